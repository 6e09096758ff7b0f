// SPDX-License-Identifier: MIT
#include "acquire/patterns.h"

#include <fmt/format.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>

#include "acquire/face_mapping.h"
#include "calib/hdr.h"
#include "solver/atomic_file.h"
#include "solver/status.h"

namespace translume::acquire {

namespace fs = std::filesystem;

PatternSet MakeRegionPatterns(const PatternJob& job) {
  if (std::string why = calib::CameraMismatch(job.camera, job.projector_file); !why.empty())
    throw InputError(why + "; use the camera calibration it was made with");
  const DeviceIntrinsics cam = DeviceIntrinsics::From(job.camera.image_size, job.camera.K, job.camera.dist);
  const DeviceIntrinsics proj =
      DeviceIntrinsics::From(job.projector.projector_size, job.projector.K, job.projector.dist);
  calib::Pose projector_from_camera;
  projector_from_camera.R = job.projector.R;
  projector_from_camera.t = job.projector.T;
  PatternSet set;
  set.corners = job.corners;
  if (!job.photo.empty()) {
    if (job.photo.size() != job.camera.image_size)
      throw InputError(fmt::format("{}: the image is {}x{} but the camera calibration is {}x{}", job.corners_source,
                                   job.photo.cols, job.photo.rows, job.camera.image_size.width,
                                   job.camera.image_size.height));
    std::vector<cv::Point2d> outline;
    if (set.corners.empty()) set.corners = DetectFaceCorners(job.photo, &cam, &outline);
    const bool outline_unrefined = job.corners.empty() && set.corners.empty() && !outline.empty();
    if (outline_unrefined) set.corners = outline;
    if (set.corners.empty())
      throw InputError(job.corners_source + ": no four-sided sample found on a dark background; give the corners");
    // A camera that sees side faces of the block: the outline is the block's (acquire does the same).
    double rms = 0;
    const calib::Pose start = EstimateSamplePose(cam, set.corners, job.size_mm, job.corners_source, &rms, false);
    const CornerSource source = job.corners.empty() ? CornerSource::kFound : CornerSource::kNear;
    if (const OutlineFitNeed need = NeedsBlockOutlineFit(cam, start, job.size_mm, source, rms, outline_unrefined);
        need.needed) {
      const OutlineChoice choice = ChooseBlockOutline({job.photo}, cam, job.size_mm, start, set.corners, 1.0, need);
      if (choice.use_fit && choice.settled) {
        const BlockOutlineFit& fit = choice.fit;
        set.unrefined_corners = set.corners;
        for (size_t k = 0; k < 4; ++k)
          set.refine_moved_px = std::max(set.refine_moved_px, cv::norm(fit.corners[k] - set.corners[k]));
        set.corners = fit.corners;
        set.refined = true;
        set.refine_blur_px = fit.blur_px;
        set.outline_fit = true;
        set.side_faces = *std::max_element(choice.side_px.begin(), choice.side_px.end()) > kSideFaceShowsPx;
      } else if (!choice.size_hint.empty()) {
        set.warnings.push_back(fmt::format("{}: --sample-mm may be off: {}, and a block of that width fits the "
                                           "outline in the photo better; the face's four corners are refined",
                                           job.corners_source, choice.size_hint));
      } else if (choice.use_fit) {
        throw InputError(fmt::format("{}: the camera sees side faces of the block, and the block's outline fit did "
                                     "not settle (docs/capture.md, \"Side faces\"); give --corners alone, as "
                                     "measured", job.corners_source));
      }
    }
  }
  if (!job.photo.empty() && !set.outline_fit) {
    set.unrefined_corners = set.corners;
    constexpr double kBlurStartPx = 1;  // the refinement's search spans 0..3 px, then follows what it finds
    const std::vector<cv::Point2d> refined =
        RefineFaceCornersWithin({job.photo}, cam, set.corners, kBlurStartPx,
                                job.corners.empty() ? 0 : kNearCornerReachPx, cv::Mat(), nullptr, &set.refine_blur_px);
    if (refined.empty()) {
      set.warnings.push_back(fmt::format("{}: the corners were not refined (too few profiles across a side show an "
                                         "unsaturated edge); keeping the {} ones", job.corners_source,
                                         job.corners.empty() ? "found" : "given"));
    } else {
      set.refined = true;
      for (size_t k = 0; k < refined.size(); ++k)
        set.refine_moved_px = std::max(set.refine_moved_px, cv::norm(refined[k] - set.corners[k]));
      set.corners = refined;
    }
  }
  const calib::Pose camera_from_sample =
      EstimateSamplePose(cam, set.corners, job.size_mm, job.corners_source, &set.pose_rms_px);
  if (set.pose_rms_px > 1.0)
    set.warnings.push_back(fmt::format("the sample's pose misses the corners by {:.2f} px RMS: check the sample's size "
                                       "and the corners (hand-picked corners give 0.1-0.5 px{})", set.pose_rms_px,
                                       job.photo.empty() ? "; with --photo they are refined in it" : ""));
  try {
    set.images = RegionPatterns(proj, projector_from_camera, camera_from_sample, job.size_mm, job.setup, job.lights);
    if (job.validation > 0)
      for (cv::Mat& p : SpotPatterns(proj, projector_from_camera, camera_from_sample, job.size_mm, job.setup,
                                     ValidationSpots(job.size_mm, job.validation)))
        set.images.push_back(std::move(p));
  } catch (const InputError& e) {
    throw InputError(fmt::format("{} and {}: {}", job.projector_file, job.corners_source, e.what()));
  }
  set.face_inside_projector = LitFaceInsideProjector(proj, projector_from_camera, camera_from_sample, job.size_mm,
                                                     job.setup);
  if (!set.face_inside_projector)
    set.warnings.push_back(fmt::format("the {} face reaches outside the projector's image: the regions at its edge are "
                                       "lit only in part", SetupName(job.setup)));
  // Names of one width that sort in order: 00..15, 000..999, 0000..4095; validation spots v00...
  const size_t regions = set.images.size() - size_t(job.validation);
  const int width = std::max<int>(2, int(std::to_string(regions - 1).size()));
  set.validation = job.validation;
  set.fewest_pixels = std::numeric_limits<int64_t>::max();
  for (size_t m = 0; m < set.images.size(); ++m) {
    set.names.push_back(m < regions ? fmt::format("{:0{}d}", m, width) : fmt::format("v{:02d}", m - regions));
    const int64_t lit = cv::countNonZero(set.images[m]);
    set.fewest_pixels = std::min(set.fewest_pixels, lit);
    set.most_pixels = std::max(set.most_pixels, lit);
  }
  return set;
}

std::string PatternFolderProblem(const std::string& dir) {
  if (!fs::exists(dir) || (fs::is_directory(dir) && fs::is_empty(dir))) return "";
  return fmt::format("{}: {} (a new folder of patterns is written)", dir,
                     fs::is_directory(dir) ? "exists and is not empty" : "is a file");
}

void WritePatternFolder(const PatternSet& set, const std::string& dir) {
  TL_CHECK(set.images.size() == set.names.size());
  if (std::string why = PatternFolderProblem(dir); !why.empty()) throw InputError(why);
  // The folder's own name, also for "DIR/" and "DIR/.".
  fs::path path = fs::absolute(dir).lexically_normal();
  if (path.filename().empty()) path = path.parent_path();
  const std::string folder = path.filename().string();
  nlohmann::json conditions = nlohmann::json::array();
  for (size_t m = 0; m < set.names.size(); ++m) {
    const std::string& name = set.names[m];
    nlohmann::json c = {{"name", name}, {"stack", "lighting/" + name}, {"pattern", folder + "/" + name + ".png"}};
    if (m + size_t(set.validation) >= set.names.size()) c["validation"] = true;
    conditions.push_back(c);
  }
  WriteFolderAtomically(dir, [&](const std::string& tmp) {
    for (size_t m = 0; m < set.images.size(); ++m)
      calib::WriteImage8((fs::path(tmp) / (set.names[m] + ".png")).string(), set.images[m]);
    std::ofstream(fs::path(tmp) / "conditions.json") << conditions.dump(2) << "\n";
  });
}

}  // namespace translume::acquire
