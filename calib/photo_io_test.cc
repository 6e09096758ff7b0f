// SPDX-License-Identifier: MIT
#include "calib/photo_io.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>

#include "calib/error.h"
#include "calib/hdr.h"

namespace translume::calib {
namespace {

namespace fs = std::filesystem;

// Folders copied from a camera card hold more than photos: the folder readers take the photos
// (any case of extension) and skip hidden files and everything else.
TEST(PhotoIo, PhotoFoldersSkipHiddenAndOtherFiles) {
  const fs::path dir = fs::temp_directory_path() / "translume_photo_io_folder";
  fs::remove_all(dir);
  fs::create_directories(dir);
  const cv::Mat grey(24, 32, CV_8UC1, cv::Scalar(90));
  ASSERT_TRUE(cv::imwrite((dir / "p0_board.png").string(), grey));
  ASSERT_TRUE(cv::imwrite((dir / "p0_pattern.TIF").string(), grey));
  std::ofstream(dir / "._p0_board.png") << "AppleDouble metadata, not a PNG";
  std::ofstream(dir / ".DS_Store") << "x";
  std::ofstream(dir / "notes.txt") << "plate at 40 cm";
  const auto photos = ReadPhotoFolder(dir.string());
  ASSERT_EQ(photos.size(), 2u);
  EXPECT_EQ(photos[0].name, (dir / "p0_board.png").string());
  EXPECT_EQ(photos[1].image.size(), grey.size());
  const auto planes = ReadPlaneFolder(dir.string());
  ASSERT_EQ(planes.size(), 1u);
  EXPECT_EQ(planes[0].name, (dir / "p0").string());
  EXPECT_TRUE(IsPhotoFile("IMG_0001.CR2"));
  EXPECT_FALSE(IsPhotoFile("._IMG_0001.JPG"));
  fs::remove_all(dir);
}

}  // namespace
}  // namespace translume::calib
