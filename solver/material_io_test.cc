// SPDX-License-Identifier: MIT
#include "solver/material_io.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "solver/image_io.h"
#include "solver/status.h"
#include "solver/synthetic.h"

namespace translume {
namespace {

namespace fs = std::filesystem;

class MaterialIo : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("translume_mio_" + std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    SynthOptions o;
    o.preset = "inclusions";
    o.shape = {9, 7, 5};
    o.spacing_mm = 0.25;
    o.eta = 1.4;
    material_ = SynthesizeMaterial(o);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string Path(const std::string& name) const { return (dir_ / name).string(); }

  // Expects ReadMaterial to throw an InputError whose message names the file and `what`.
  void ExpectRejected(const std::string& path, const std::string& what) {
    try {
      ReadMaterial(path);
      FAIL() << "no error for " << what;
    } catch (const InputError& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find(path), std::string::npos) << msg;
      EXPECT_NE(msg.find(what), std::string::npos) << msg;
      EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
      EXPECT_LT(msg.size(), path.size() + 200) << msg;  // one short line, whatever the file holds
    }
  }

  fs::path dir_;
  Material material_;
};

TEST_F(MaterialIo, RoundTripIsExact) {
  const std::string path = Path("m.vdb");
  WriteMaterial(path, material_);
  const Material back = ReadMaterial(path);
  EXPECT_EQ(back.shape, material_.shape);
  EXPECT_DOUBLE_EQ(back.spacing_mm, material_.spacing_mm);
  EXPECT_NEAR(back.C, material_.C, 1e-6);
  EXPECT_NEAR(back.eta, 1.4, 1e-6);
  for (int c = 0; c < 3; ++c) {
    EXPECT_EQ(back.kappa[c], material_.kappa[c]);
    EXPECT_EQ(back.mu[c], material_.mu[c]);
  }
  // No temporary file left behind.
  int files = 0;
  for ([[maybe_unused]] const auto& e : fs::directory_iterator(dir_)) ++files;
  EXPECT_EQ(files, 1);
}

TEST_F(MaterialIo, RejectsEveryBrokenFile) {
  ExpectRejected(Path("absent.vdb"), "no such file");
  {
    std::ofstream(Path("text.vdb")) << "not a vdb";
    ExpectRejected(Path("text.vdb"), "too short");
    std::ofstream(Path("long.vdb")) << std::string(10000, 'x');
    ExpectRejected(Path("long.vdb"), "not a readable OpenVDB material");
    fs::create_directories(Path("folder.vdb"));
    ExpectRejected(Path("folder.vdb"), "is a folder");
  }
  // A good file cut short or with flipped bytes: one short line naming it, at any cut (inside
  // the header OpenVDB would otherwise trust garbage lengths and allocate gigabytes).
  WriteMaterial(Path("good.vdb"), material_);
  std::string bytes;
  {
    std::ifstream in(Path("good.vdb"), std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), {});
  }
  ASSERT_GT(bytes.size(), 8192u);
  for (size_t cut : {size_t(60), size_t(100), size_t(120), bytes.size() / 3, bytes.size() - 10}) {
    std::ofstream(Path("cut.vdb"), std::ios::binary) << bytes.substr(0, cut);
    try {
      ReadMaterial(Path("cut.vdb"));
      ADD_FAILURE() << "no error for a file cut at " << cut;
    } catch (const InputError& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find(Path("cut.vdb")), std::string::npos) << msg;
      EXPECT_LT(msg.size(), 300u) << cut;
      if (cut >= 4096) {
        EXPECT_TRUE(msg.find("cut short") != std::string::npos || msg.find("truncated") != std::string::npos) << msg;
      }
    }
  }
  // Flipped bytes anywhere (in the header, a grid's topology or its values: OpenVDB would read
  // some silently as other values and crash on others) fail the checksum; so does a byte
  // appended.
  for (size_t at : {size_t(80), bytes.size() / 4, bytes.size() / 2, bytes.size() - 40, bytes.size() - 5}) {
    std::string flipped = bytes;
    flipped[at] = char(~flipped[at]);
    std::ofstream(Path("flip.vdb"), std::ios::binary) << flipped;
    ExpectRejected(Path("flip.vdb"), "corrupt material file");
  }
  std::ofstream(Path("longer.vdb"), std::ios::binary) << bytes << 'x';
  // (The trailer is then not at the end: OpenVDB reads the file, which says it had one.)
  ExpectRejected(Path("longer.vdb"), "checksum trailer is missing");
  std::ofstream(Path("cut_trailer.vdb"), std::ios::binary) << bytes.substr(0, bytes.size() - 24);
  ExpectRejected(Path("cut_trailer.vdb"), "checksum trailer is missing");
  // A file from before the trailer still reads.
  WriteCorruptMaterialForTest(Path("old.vdb"), material_, MaterialCorruption::kNoChecksum);
  EXPECT_EQ(ReadMaterial(Path("old.vdb")).kappa, material_.kappa);
  // Such a file (or another tool's) has no checksum: lengths in its header that the file cannot
  // hold are refused before OpenVDB allocates them (a metadata name of 4 GB took 21 GB).
  std::string old;
  {
    std::ifstream in(Path("old.vdb"), std::ios::binary);
    old.assign(std::istreambuf_iterator<char>(in), {});
  }
  const auto patched = [&](size_t at, uint32_t value) {
    std::string b = old;
    for (int i = 0; i < 4; ++i) b[at + size_t(i)] = char((value >> (8 * i)) & 0xff);
    std::ofstream(Path("patched.vdb"), std::ios::binary) << b;
    return Path("patched.vdb");
  };
  ExpectRejected(patched(0x08, 1), "OpenVDB file format version 1, this build reads 213 to 224");
  ExpectRejected(patched(0x39, 0x7fffffff), "2147483647 metadata entries, more than the file holds");
  ExpectRejected(patched(0x3d, 0xfffffff0), "a metadata name of 4294967280 bytes, beyond the file's end");
  const size_t grid_name = old.find(std::string("\x05\0\0\0kappa", 9));
  ASSERT_NE(grid_name, std::string::npos);
  ExpectRejected(patched(grid_name, 0xfffffff0), "a grid name of 4294967280 bytes");
  ExpectRejected(patched(grid_name + 9 + 4 + 16 + 4 + 16, 0x7fffffff), "grid 0 ends at byte 2147483647, beyond");
  const std::pair<MaterialCorruption, std::string> cases[] = {
      {MaterialCorruption::kMissingMu, "missing grid 'mu'"},
      {MaterialCorruption::kMissingC, "missing file metadata 'C'"},
      {MaterialCorruption::kUnknownMetadata, "unknown file metadata 'albedo_scale'"},
      {MaterialCorruption::kShapeMismatch, "different shapes"},
      {MaterialCorruption::kNegativeKappa, "kappa = -0.2"},
      {MaterialCorruption::kNanMu, "mu = nan"},
      {MaterialCorruption::kWrongGridType, "expected Vec3f"},
      {MaterialCorruption::kMissingVoxel, "active voxels"},
      {MaterialCorruption::kWrongFormat, "translume_format"},
      {MaterialCorruption::kRotated, "axis-aligned"},
      {MaterialCorruption::kMirrored, "axis-aligned"},
      {MaterialCorruption::kHugeTiles, "4096x4096x4096 grid, held densely, needs about"},
  };
  int n = 0;
  for (const auto& [corruption, what] : cases) {
    const std::string path = Path("bad" + std::to_string(n++) + ".vdb");
    WriteCorruptMaterialForTest(path, material_, corruption);
    ExpectRejected(path, what);
  }
}

// Damaged grid data in a file without a checksum trailer (another tool's): OpenVDB's reader
// trusts it and, in-process, corrupted the heap or failed an assertion on almost every byte
// changed here. The file is read in a child process: one line naming the file, and this process
// lives on. (The offsets are in the kappa grid's first leaf of this material as Debian 12's
// OpenVDB 10 writes it: 62 of these 64 changes crash the reader, 2 make it ask for gigabytes.)
TEST_F(MaterialIo, DamagedGridDataWithoutChecksumIsAnErrorNotACrash) {
  WriteCorruptMaterialForTest(Path("old.vdb"), material_, MaterialCorruption::kNoChecksum);
  std::string old;
  {
    std::ifstream in(Path("old.vdb"), std::ios::binary);
    old.assign(std::istreambuf_iterator<char>(in), {});
  }
  ASSERT_GT(old.size(), 9000u);
  int damaged = 0;
  for (size_t at = 8930; at < 8994; ++at) {
    std::string b = old;
    b[at] = '1';
    if (b[at] == old[at]) continue;
    std::ofstream(Path("damaged.vdb"), std::ios::binary) << b;
    try {
      ReadMaterial(Path("damaged.vdb"));
    } catch (const InputError& e) {
      const std::string msg = e.what();
      EXPECT_EQ(msg.rfind(Path("damaged.vdb") + ": ", 0), 0u) << msg;
      EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
      EXPECT_LT(msg.size(), 300u) << msg;
      if (msg.find("damaged grid data") != std::string::npos) ++damaged;
    }
  }
  EXPECT_GE(damaged, 32);
  // The undamaged file reads through the same child process, exactly.
  const Material back = ReadMaterial(Path("old.vdb"));
  EXPECT_EQ(back.shape, material_.shape);
  EXPECT_EQ(back.kappa, material_.kappa);
  EXPECT_EQ(back.mu, material_.mu);
  EXPECT_DOUBLE_EQ(back.spacing_mm, material_.spacing_mm);
}

// A volume where an image is read (a light pattern, a mask, a dataset image): one line, no
// crash (OpenImageIO reads the .vdb as a 3-D image, whatever its file name).
TEST_F(MaterialIo, AVolumeIsNoImage) {
  WriteMaterial(Path("m.vdb"), material_);
  fs::copy_file(Path("m.vdb"), Path("m.exr"));
  for (const std::string& path : {Path("m.vdb"), Path("m.exr")}) {
    try {
      ReadImage(path);
      ADD_FAILURE() << "no error for " << path;
    } catch (const InputError& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find(path), std::string::npos) << msg;
      EXPECT_NE(msg.find("not a 2-D image"), std::string::npos) << msg;
    }
  }
}

// An image header's size is checked before it is allocated: a 54-byte BMP that claims 20000 x
// 20000 pixels (a 661-byte PNG that did took 4.8 GB before decoding failed).
TEST_F(MaterialIo, AHugeImageHeaderIsRefusedBeforeAllocating) {
  std::string bmp = "BM";
  const auto put = [&](uint32_t v, int bytes) {
    for (int b = 0; b < bytes; ++b) bmp.push_back(char((v >> (8 * b)) & 0xff));
  };
  put(54, 4), put(0, 4), put(54, 4);                  // file size, reserved, pixel data offset
  put(40, 4), put(20000, 4), put(20000, 4);           // BITMAPINFOHEADER, width, height
  put(1, 2), put(24, 2), put(0, 4), put(0, 4);        // planes, bits per pixel, BI_RGB, image size
  put(2835, 4), put(2835, 4), put(0, 4), put(0, 4);  // resolution, palette
  std::ofstream(Path("huge.bmp"), std::ios::binary) << bmp;
  try {
    ReadImage(Path("huge.bmp"));
    ADD_FAILURE() << "no error";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), Path("huge.bmp") + ": a 20000x20000 image of 3 channels is larger than "
                                     "translume reads (at most 268435456 pixels of at most 64 channels)");
  }
}

TEST_F(MaterialIo, RefusesToWriteInvalidMaterialAndLeavesNothing) {
  Material bad = material_;
  bad.mu[1][3] = 0;
  const std::string path = Path("bad.vdb");
  EXPECT_THROW(WriteMaterial(path, bad), InputError);
  EXPECT_FALSE(fs::exists(path));
}

// The slices that `solve` and `acquire` preview a material with: blocks of nodes at least 256
// pixels wide; each channel on a log scale over its own spread, so that a kappa inclusion shows at
// full contrast though the channel's level is small, a single extreme node is clamped instead of
// flattening the rest, a 20 % variation stays faint (the range spans at least a factor 2) and a
// constant channel is mid-grey.
TEST_F(MaterialIo, SlicePreviewsAreLargeAndStretchEachChannel) {
  EXPECT_EQ(PreviewPixelsPerNode(32), 8);
  EXPECT_EQ(PreviewPixelsPerNode(130), 2);
  EXPECT_EQ(PreviewPixelsPerNode(256), 1);
  EXPECT_EQ(PreviewPixelsPerNode(300), 1);
  EXPECT_EQ(Quantiles({3, 1, 2, 5, 4}, {0, 0.5, 1, 0.26}), (std::vector<float>{1, 3, 5, 2}));

  const GridShape shape{20, 10, 4};
  Material m = Material::Constant(shape, 0.5, {0.01f, 0.5f, 0.5f}, {0.02f, 0.02f, 0.02f});
  for (int64_t j = 2; j < 5; ++j)
    for (int64_t i = 3; i < 8; ++i) {
      m.kappa[0][size_t(shape.index(i, j, 0))] = 0.04f;  // red: 4x in a box
      m.kappa[1][size_t(shape.index(i, j, 0))] = 0.6f;   // green: 20 % above
    }
  for (int64_t n = 0; n < shape.size(); ++n) m.mu[2][size_t(n)] = 0.01f * std::pow(4.0f, float(n % shape.nx) / 19);
  m.mu[2][size_t(shape.index(19, 9, 3))] = 1000;  // one extreme node
  const std::vector<std::string> paths = WriteMaterialSlices(Path("m"), m);
  ASSERT_EQ(paths, MaterialSlicePaths(Path("m"), shape));
  ASSERT_EQ(paths.size(), 8u);  // depths 0, 1, 2, 3 of each quantity
  EXPECT_EQ(paths[0], Path("m_kappa_k00.png"));
  const Image kappa0 = ReadImage(paths[0]);
  const int z = 13;  // ceil(256 / 20)
  ASSERT_EQ(kappa0.width, 20 * z);
  ASSERT_EQ(kappa0.height, 10 * z);
  ASSERT_EQ(kappa0.channels, 3);
  const auto at = [&](const Image& img, int64_t i, int64_t j, int c, int dx = 0, int dy = 0) {
    return img.data[size_t(((j * z + dy) * img.width + i * z + dx) * 3 + c)];
  };
  const float step = 1 / 255.0f;
  EXPECT_FLOAT_EQ(at(kappa0, 5, 3, 0), 1.0f);  // the red box: the channel's top
  EXPECT_FLOAT_EQ(at(kappa0, 7, 4, 0, z - 1, z - 1), 1.0f);
  EXPECT_FLOAT_EQ(at(kappa0, 8, 4, 0), 0.0f);  // beside it: the channel's bottom
  EXPECT_FLOAT_EQ(at(kappa0, 0, 0, 0), 0.0f);
  // Green's 20 %: log 1.2 / log 2 = 0.26 of the scale, about the centre of 0.5 and 0.6.
  const float faint = float(std::log(1.2) / std::log(2.0));
  EXPECT_NEAR(at(kappa0, 5, 3, 1), 0.5f + faint / 2, step);
  EXPECT_NEAR(at(kappa0, 0, 0, 1), 0.5f - faint / 2, step);
  EXPECT_NEAR(at(kappa0, 0, 0, 2), 0.5f, step);  // constant blue
  const Image mu3 = ReadImage(paths[7]);
  EXPECT_NEAR(at(mu3, 0, 0, 0), 0.5f, step);  // constant red
  EXPECT_FLOAT_EQ(at(mu3, 0, 5, 2), 0.0f);    // blue rises by 4x along x, evenly on the log scale ...
  EXPECT_NEAR(at(mu3, 10, 5, 2), 10.0f / 19, step);
  EXPECT_FLOAT_EQ(at(mu3, 19, 5, 2), 1.0f);
  EXPECT_FLOAT_EQ(at(mu3, 19, 9, 2), 1.0f);  // ... and its extreme node is clamped
}

// acquire's fit previews: measured | fitted | residual, one brightness scale for the first two
// (the largest unmasked measured value), the residual signed in colour at kResidualPreviewRange
// of that scale, masked nodes black in the measured panel and grey in the residual.
TEST_F(MaterialIo, FitComparisonShowsMeasuredFittedAndSignedResidual) {
  const GridShape shape{10, 4, 3};
  const size_t face = 40;
  FacePattern measured, fitted;
  for (int c = 0; c < 3; ++c) {
    measured[size_t(c)].assign(face, 0.5f);
    fitted[size_t(c)].assign(face, 0.5f);
  }
  std::vector<float> mask(face, 1.0f);
  measured[1][size_t(shape.index(0, 0, 0))] = 2.0f;  // the top
  mask[size_t(shape.index(9, 3, 0))] = 0;           // masked: not the top though brighter
  for (int c = 0; c < 3; ++c) measured[size_t(c)][size_t(shape.index(9, 3, 0))] = 8.0f;
  for (int c = 0; c < 3; ++c) fitted[size_t(c)][size_t(shape.index(2, 1, 0))] = 0.5f + 0.05f;    // +2.5 % of top
  fitted[0][size_t(shape.index(3, 1, 0))] = 0.5f - 3 * 0.2f;                                     // -30 %: clamped
  fitted[0][size_t(shape.index(4, 1, 0))] = 0.5f + 0.1f;   // red +5 % and blue -3 %: red shows,
  fitted[2][size_t(shape.index(4, 1, 0))] = 0.5f - 0.06f;  // not their mean (+0.7 %)
  const std::string path = Path("fit.png");
  WriteFitComparison(path, shape, measured, fitted, mask);
  const Image img = ReadImage(path);
  const int z = 26;  // ceil(256 / 10)
  ASSERT_EQ(img.width, (3 * 10 + 4) * z);
  ASSERT_EQ(img.height, 4 * z);
  ASSERT_EQ(img.channels, 3);
  // Node (i, j) of panel p (0 measured, 1 fitted, 2 residual), a pixel inside its block.
  const auto at = [&](int p, int64_t i, int64_t j, int c) {
    return img.data[size_t(((j * z + z / 2) * img.width + (p * 12 + i) * z + z / 3) * 3 + c)];
  };
  const float step = 1 / 255.0f;
  const float half = std::pow(0.25f, 1 / 2.2f);  // 0.5 of the top 2
  EXPECT_NEAR(at(0, 5, 2, 0), half, step);
  EXPECT_NEAR(at(1, 5, 2, 0), half, step);
  EXPECT_FLOAT_EQ(at(0, 0, 0, 1), 1.0f);
  EXPECT_FLOAT_EQ(at(0, 9, 3, 0), 0.0f);  // masked: black in the measured panel ...
  EXPECT_NEAR(at(1, 9, 3, 0), half, step);  // ... the fit shown as everywhere ...
  EXPECT_NEAR(at(2, 9, 3, 0), 0.35f, step);  // ... and grey in the residual
  EXPECT_NEAR(at(2, 9, 3, 2), 0.35f, step);
  for (int c = 0; c < 3; ++c) EXPECT_FLOAT_EQ(at(2, 5, 2, c), 0.0f);  // a perfect fit: black
  EXPECT_NEAR(at(2, 0, 0, 0), 0.15f, step);  // the top: fitted 1.5 below in green only, -75 %
  EXPECT_NEAR(at(2, 0, 0, 2), 1.0f, step);   // of the top, beyond the range: full blue
  EXPECT_NEAR(at(2, 2, 1, 0), 0.5f, step);  // +2.5 %: half red
  EXPECT_NEAR(at(2, 2, 1, 2), 0.05f, step);
  EXPECT_NEAR(at(2, 3, 1, 2), 1.0f, step);  // -0.6 / 2 = -30 %: full blue
  EXPECT_NEAR(at(2, 3, 1, 0), 0.15f, step);
  EXPECT_NEAR(at(2, 4, 1, 0), 1.0f, step);  // +5 % in red: full red
  EXPECT_NEAR(at(2, 4, 1, 2), 0.1f, step);
  for (int c = 0; c < 3; ++c)  // the gap between the panels
    EXPECT_FLOAT_EQ(img.data[size_t(((z / 2) * img.width + 10 * z + 1) * 3 + c)], 0.0f);
}

}  // namespace
}  // namespace translume
