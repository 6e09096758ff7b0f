// SPDX-License-Identifier: MIT
#pragma once

#include <array>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "calib/synthetic_rig.h"
#include "solver/forward.h"
#include "solver/grid.h"

namespace translume::acquire {

// Maps between camera/projector images and the nodes of a block sample's faces. Sample frame:
// CaptureSpec (capture.h): node (i, j, k) at (i h, j h, k h) mm, front face z = 0. Transforms
// are calib::Pose (x_to = R x_from + t, mm); camera_from_sample places the sample in the camera
// frame. Pixels use OpenCV's convention (pixel centres at integer coordinates).

// A pinhole device with OpenCV distortion (k1, k2, p1, p2, k3).
struct DeviceIntrinsics {
  cv::Size size;
  cv::Matx33d K = cv::Matx33d::eye();
  cv::Vec<double, 5> dist{0, 0, 0, 0, 0};
  std::vector<cv::Point2d> Project(const std::vector<cv::Point3d>& camera_xyz) const;
  // From a calibration's size, camera matrix and distortion (any length up to 5 used).
  static DeviceIntrinsics From(const cv::Size& size, const cv::Matx33d& K, const cv::Mat& dist);
};

// A block sample's extent along x, y, z (mm): (n - 1) h per axis.
std::array<double, 3> SampleSize(const GridShape& grid, double h);

// The four front-face corners in the sample frame, in CaptureSpec's order:
// (0, 0, 0), (X, 0, 0), (X, Y, 0), (0, Y, 0).
std::vector<cv::Point3d> FrontFaceCorners(const GridShape& grid, double h);

// The lit face's plane z (sample frame, mm): the back face Z back-lit, the front face 0 front-lit.
double LitFaceZ(const GridShape& grid, double h, Setup setup);

// "" when four image points enclose a convex quadrilateral (every turn the same way) of at
// least 16 px^2, else "the 4 corners must enclose a convex quadrilateral of at least 16 px^2
// (area A)": four points on a line let a pose fit them with a small error.
std::string QuadrilateralProblem(const std::vector<cv::Point2d>& corners);

// camera_from_sample from the front face's four image corners (planar PnP, IPPE, refined by
// Levenberg-Marquardt). *rms_px receives the corners' reprojection RMS. Throws InputError
// naming `what` when a corner lies outside the image, the pose puts the sample behind the
// camera or shows the face from behind (corners counter-clockwise), or the pose misses the
// corners by more than max(3 px, 2 % of the face's side in the image) RMS (corners listed from
// another corner of a non-square face, or a wrong sample size).
// fit_bound false leaves out the last check (corners found on a block's outline, which
// FitBlockOutline then fits).
calib::Pose EstimateSamplePose(const DeviceIntrinsics& camera, const std::vector<cv::Point2d>& corners,
                               const std::array<double, 3>& size_mm, const std::string& what,
                               double* rms_px = nullptr, bool fit_bound = true);
calib::Pose EstimateSamplePose(const DeviceIntrinsics& camera, const std::vector<cv::Point2d>& corners,
                               const GridShape& grid, double h, const std::string& what,
                               double* rms_px = nullptr, bool fit_bound = true);

// For corners that a face of size_mm fits badly: the front face's width (x extent, mm, its
// height kept) whose pose fits them best (0.67 to 1.5 times size_mm[0]) and that pose's RMS
// (px). Only the face's aspect ratio shows in one view; a wrong sample_mm shows as a better fit.
struct FaceWidthFit {
  double width_mm = 0, rms_px = INFINITY;
};
FaceWidthFit FaceWidthFittingCorners(const DeviceIntrinsics& camera, const std::vector<cv::Point2d>& corners,
                                     const std::array<double, 3>& size_mm);

// "" or, where the corners miss a face of size_mm by more than 1 px RMS (rms_px) and a face of
// another width fits them in half that: "the corners found fit a face of W x Y mm (pose RMS r
// px) better than X x Y mm (rms_px)", for the error that stops at those corners. *width_fit
// (optional) receives FaceWidthFittingCorners' result where the hint is given.
std::string SampleSizeHint(const DeviceIntrinsics& camera, const std::vector<cv::Point2d>& corners,
                           const std::array<double, 3>& size_mm, double rms_px, FaceWidthFit* width_fit = nullptr);

// Finds the front face's four corners in a linear image of the lit sample on a dark background
// (e.g. the sum of every condition's HDR, or a photo whose background is clipped at 0): a
// log-domain Otsu threshold after a 5x5 median, the largest blob, its four-sided outline, each
// side refined by a line fit to sub-pixel edge points (where the profile across the side falls
// half-way from the inside's level, extrapolated to the edge, to the outside's). The log scale spans 6 decades below the
// brightest pixel, then 4, 2 and 1 until the blob is solid (97 % of its outline's inside) and an
// edge shows along most of each side. Corners are returned in image order top-left, top-right,
// bottom-right, bottom-left (the sample seen upright: node (0, 0) top-left). Empty when no
// convex quadrilateral is found. With the `camera` that took the image, the sides are fitted
// as straight lines after undistortion (the corners of a face seen through the simulated rig's
// barrel distortion were found 0.33 px outside without it: docs/benchmarks.md, "Corners of a
// distorted face").
// *outline (optional) receives the first quadrilateral outline found, whole pixels, in the same
// order, also where its sides do not refine (a block whose side faces show: FitBlockOutline).
std::vector<cv::Point2d> DetectFaceCorners(const cv::Mat& linear_rgb, const DeviceIntrinsics* camera = nullptr,
                                           std::vector<cv::Point2d>* outline = nullptr);

// Corners (four image points, side s from corner s to s + 1, e.g. DetectFaceCorners') refined
// on photos of the lit sample through a lens of Gaussian blur near `blur_px` (sigma, pixels;
// EstimateOutlineBlur's): `images` linear CV_32FC3 of camera.size, +inf where saturated, less
// `black` (CV_32FC3, empty: none) where sampled. Across the middle 70 % of each side, every ~2
// px, each image's profile (the channels' mean along the outward normal every 0.25 px, from
// max(6, 4 sigma_e) px inside to max(5, 3 sigma_e + 1.5) px outside; profiles with a
// non-finite sample or without an edge, inside below 4x the surround, left out) is fitted by
// least squares as
//     a E(s) + b (s E(s) - sigma_e^2 G(s)) + c ((s^2 + sigma_e^2) E(s) - sigma_e^2 s G(s)) + d,
// s = t - t0, E(s) = erfc(s / (sqrt(2) sigma_e)) / 2 and G the Gaussian of sigma_e, sigma_e^2 =
// blur^2 + 1/4 (the pixel's area and the bilinear sampling, 1/12 + 1/6): the blurred image of a
// radiance a + b s + c s^2 inside the edge (s < 0) over a constant surround d, for the edge's
// offset t0 within max(1.5, sigma_e) px (0.05 px steps, parabola-refined). The blur is the one
// whose fits cost least in sum over ~2000 profiles (0 to 2 blur_px + 1 px, to 0.05 px; a blur
// 13 % off moves the edge ~0.6 px at 2 px): *blur_found (optional) receives it. The points p +
// t0 n, undistorted, are fitted by a line per side (Huber); the corners are where consecutive
// lines meet. DetectFaceCorners' half-way crossing on a summed image is biased where the sum
// saturates and where the blur spreads a radiance that falls towards the edge; this is not,
// but for curvature that a quadratic over the window does not follow (a 60 % fall over 4 px
// through a 2.5 px lens: 0.6 px; docs/capture.md, "Automatic corners"). Empty when a side keeps fewer than 8 points;
// *edge_points (optional) receives the points used. `reach_px` above max(1.5, sigma_e) lets the
// edge lie that far off the given outline (corners clicked by hand), the window widened to
// match; a second call from the result then fits in the usual window.
std::vector<cv::Point2d> RefineFaceCorners(const std::vector<cv::Mat>& images, const DeviceIntrinsics& camera,
                                           const std::vector<cv::Point2d>& corners, double blur_px,
                                           const cv::Mat& black = cv::Mat(), int* edge_points = nullptr,
                                           double* blur_found = nullptr, double reach_px = 0);

// How far off a corner clicked by hand may be (px): capture.json's {"near": [...]} and
// `translume patterns --corners` with `--photo`.
constexpr double kNearCornerReachPx = 5;

// RefineFaceCorners from corners within reach_px of the outline: with reach_px > 0 a first pass
// that lets the edges lie that far off, then the usual pass from its result through the blur it
// found; with reach_px = 0 the usual pass alone. Empty where a pass fails; *edge_points and
// *blur_found (optional) are the last pass's.
std::vector<cv::Point2d> RefineFaceCornersWithin(const std::vector<cv::Mat>& images, const DeviceIntrinsics& camera,
                                                 const std::vector<cv::Point2d>& corners, double blur_px,
                                                 double reach_px, const cv::Mat& black = cv::Mat(),
                                                 int* edge_points = nullptr, double* blur_found = nullptr);

// The side faces a camera sees of a block of `size_mm` at camera_from_sample, besides the front
// face: per side face (0: x = 0, 1: x = X, 2: y = 0, 3: y = Y), how wide it shows (px: the
// largest image distance of a back corner from the front edge's line through its front corner),
// 0 where it is turned away. A camera whose centre lies outside the slab of a side face's plane
// sees it (the paper's front-lit rig puts the camera beside the projector).
constexpr double kSideFaceShowsPx = 0.5;  // wider than this, a side face is taken as seen
std::array<double, 4> SideFaceWidthsPx(const DeviceIntrinsics& camera, const calib::Pose& camera_from_sample,
                                       const std::array<double, 3>& size_mm);
// The same distances signed: negative where the side face is turned away (its back corners
// project inside the front face, by that much at most), so that a pose a little off tells how
// near a side face is to showing.
std::array<double, 4> SideFaceSignedWidthsPx(const DeviceIntrinsics& camera, const calib::Pose& camera_from_sample,
                                             const std::array<double, 3>& size_mm);

// Whether the pose from four corners gives way to FitBlockOutline's (acquire and `translume
// patterns` alike). `required`: a side face wider than kSideFaceShowsPx shows at
// camera_from_sample, or corners found in the photos fit no face (pose RMS above 1 px, or an
// outline whose sides did not refine); the four corners cannot stand in where the fit does not
// settle. `needed`: that, or corners found or given near the face with a side face within
// kSideFaceNearPx of showing: a strip up to ~2 px wide hides in the outline found (its outer
// edge taken for the face's, the pose from those corners showing no side face, or one
// narrower than kSideFaceShowsPx); the fit is then kept only where it shows a side face.
// reach_px: FitBlockOutline's first round's, 0 for corners given as exact, else
// kNearCornerReachPx + 2 pose RMS (at most 15 px).
constexpr double kSideFaceNearPx = 1.0;
enum class CornerSource { kExact, kNear, kFound };
struct OutlineFitNeed {
  bool needed = false;
  bool required = false;
  double reach_px = 0;
  CornerSource source = CornerSource::kFound;
  double pose_rms_px = 0;  // the corners' pose RMS (px)
};
OutlineFitNeed NeedsBlockOutlineFit(const DeviceIntrinsics& camera, const calib::Pose& camera_from_sample,
                                    const std::array<double, 3>& size_mm, CornerSource source,
                                    double pose_rms_px, bool outline_unrefined);

// The sample's pose from the outline of the whole block in photos of it lit on a dark surround,
// for a camera that sees side faces too: the outline is then the convex hull of up to six of
// the block's eight corners (in the ideal pinhole image), and the front face's edges next to a
// side face do not show. From `camera_from_sample`, up to sixteen rounds of: the hull's sides
// refined as RefineFaceCorners refines the face's (OutlineEdgePoints: the same profiles and
// model; the edges let lie up to reach_px off in the first round, through blur_px, and up to
// 3 px off later, so that a side the pose misplaces can move; the blur searched in the second
// round and again once the pose nearly settles, on the hull's sides that are front-face edges
// only: a narrow side face's crease misleads the search), then the pose whose hull sides (lines through
// the projected box corners) pass closest to the edge points (Ceres, Huber loss of 1 px on the
// distances in the ideal image); settled when a round moves the front corners by less than
// 0.02 px. Sides with fewer than 8 points are left out; a round with fewer than 4 such sides
// ends the fit (ok false). A nearly parallel view fits two poses nearly as well (the side face
// seen taken for its neighbour, the block turned the other way), so the fit runs from the pose
// given and from it turned both ways about the front face's x and y axes through its centre
// (by the angle at which a side face starts to show, plus 5 degrees), and keeps, among the fits
// with at least 80 % of the most edge points, a settled one before any other, then the least RMS.
struct BlockOutlineFit {
  bool ok = false;
  calib::Pose camera_from_sample;
  std::vector<cv::Point2d> corners;  // the front face's corners (FrontFaceCorners' order), image px
  double rms_px = 0;                 // the edge points' RMS distance from the fitted outline
  int edge_points = 0, sides = 0;    // points and hull sides used in the last round
  double blur_px = 0;                // the lens's blur the last round found
  // The smallest share, over the hull's sides at least 20 px long, of a side's profiles that
  // found its edge (last round).
  double least_side_support = 0;
  // The last round moved the front corners by less than 0.02 px, and every side of the outline
  // is explained: least_side_support at least 25 % (a wrong sample_mm leaves one near 5 %).
  bool converged = false;
};
BlockOutlineFit FitBlockOutline(const std::vector<cv::Mat>& images, const DeviceIntrinsics& camera,
                                const std::array<double, 3>& size_mm, const calib::Pose& camera_from_sample,
                                double blur_px, double reach_px, const cv::Mat& black = cv::Mat());

// What the block's outline says where NeedsBlockOutlineFit asks for it (acquire and `translume
// patterns` alike): FitBlockOutline of the declared block from camera_from_sample (the pose
// from `corners`) through blur_px, and whether it places the corners (use_fit: required, or
// settled with a side face showing). Where the fit is required for corners found or given near
// and SampleSizeHint names another width, the block of that width is fitted too; where that one
// settles and the declared one does not, or fits with more than 1.5 times its RMS, sample_mm is
// taken as off (a wider block turned to show a side face that is not there can fit a face's
// outline too): size_hint holds SampleSizeHint's text and use_fit is false, the face's four
// corners to be refined instead.
struct OutlineChoice {
  BlockOutlineFit fit;
  bool settled = false;              // fit.ok && fit.converged
  std::array<double, 4> side_px{};   // SideFaceWidthsPx at the fit's pose (settled) or the start's
  bool use_fit = false;
  std::string size_hint;
};
OutlineChoice ChooseBlockOutline(const std::vector<cv::Mat>& images, const DeviceIntrinsics& camera,
                                 const std::array<double, 3>& size_mm, const calib::Pose& camera_from_sample,
                                 const std::vector<cv::Point2d>& corners, double blur_px,
                                 const OutlineFitNeed& need, const cv::Mat& black = cv::Mat());

// Node-space front-face radiance from a linear RGB image (CV_32FC3; +inf = saturated): every
// front-face node's value is the mean of the image over the node's dual box on the face (the
// face area the node owns, SPEC section 3), sampled at n x n points per box through the camera
// model with bilinear interpolation, n = max(`samples`, pixels across a node + 1): at least one
// sample per pixel, an area-weighted resampling.
struct FaceSamples {
  FacePattern value;                // RGB, nx * ny (i + nx j); NaN where not measured
  std::vector<float> saturated;     // fraction of the node's samples on saturated pixels
};
// With `coverage` (FaceCoverage's image), each node's sum of samples is divided by the sum of
// the coverage's at the same points instead of by their count (a normalised convolution): the
// pixels across the face's outline see the dark surround too, and a border node's half box
// would lose that light (docs/capture.md, "Mapping").
FaceSamples ResampleFrontFace(const cv::Mat& linear_rgb, const DeviceIntrinsics& camera,
                              const calib::Pose& camera_from_sample, const GridShape& grid,
                              double h, int samples = 6, const cv::Mat* coverage = nullptr);

// The fraction of each camera pixel that sees the front face [0, X] x [0, Y] (z = 0): the image
// of a uniformly bright face of radiance 1 on a black surround (CV_32FC1, camera.size). Each
// pixel's rays are interpolated bilinearly between the rays of its corners (through the
// distortion model), s x s per pixel where its corners do not all agree (inside or outside).
// With blur_px > 0 the image is then blurred by a Gaussian of that sigma (pixels): the lens's
// blur, which spreads the face's outline further into the dark surround.
cv::Mat FaceCoverage(const DeviceIntrinsics& camera, const calib::Pose& camera_from_sample,
                     const GridShape& grid, double h, double blur_px = 0, int s = 8);

// The lens's blur on photos of the sample, read off the front face's outline in `images`
// (linear, CV_32FC3, camera.size: photos of the lit sample through the same lens). Profiles
// cross the four sides along their image normals (every ~1.5 px of a side, away from the
// corners, t from -(3 max + 3) to 3 max + 3 px in steps of 0.5, t > 0 outside); each image's
// channel mean along them, scaled to the largest value of that image's brightest profile (dim
// profiles weigh less; profiles with a non-finite sample, e.g. saturated, are left out), is
// fitted per profile by least squares as
//     a c_sigma(t) + b (t c_sigma(t) + v c_sigma'(t)) + d,   v = sigma^2 + 1/4,
// c_sigma the coverage image (FaceCoverage) blurred by a Gaussian of sigma px and sampled at
// the same points, c_sigma' its slope along the profile (central differences): the blurred
// images of a radiance a + b t linear up to the outline (for a kernel of variance v,
// K * (t f) = t (K * f) + v (K * f)'; the pixel's area and the bilinear sampling add 1/4 px^2)
// over a constant surround d. sigma is the
// one of 0, 0.05, ..., max_sigma_px whose summed squared residual is least (tried every 0.25
// px, then every 0.05 px within 0.25 px of the best), refined by a parabola through its
// neighbours. The pixels' own area and the bilinear sampling are in both
// the images and c_sigma, so sigma is the lens's alone. Below ~0.3 px a Gaussian is not told
// from none on the pixel grid (a sharp lens reads as 0-0.3 px).
struct OutlineBlur {
  double sigma_px = 0;    // the estimate; 0 when no profile could be fitted
  int positions = 0;      // places on the outline that a profile fits in the image (per image)
  int profiles = 0;       // profiles fitted, over all images (0 with positions > 0: saturated)
  double rms = 0;         // RMS residual at sigma_px, relative to each image's scale
  double rms_sharp = 0;   // the same with sigma 0 (no blur)
};
// `black` (CV_32FC3, camera.size; empty: none) is subtracted from every image where sampled, so
// that a capture's images need not be copied to remove their black level.
OutlineBlur EstimateOutlineBlur(const std::vector<cv::Mat>& images, const DeviceIntrinsics& camera,
                                const calib::Pose& camera_from_sample, const GridShape& grid, double h,
                                double max_sigma_px = 3.0, const cv::Mat& black = cv::Mat());

// Incoming light q on the lit face (z = Z back-lit, z = 0 front-lit) from a projector image
// (CV_32FC1, linear, 1 = full white): each lit-face node gets the mean of the pattern over its
// dual box, sampled at `samples` x `samples` points mapped through camera_from_sample,
// projector_from_camera and the projector's intrinsics; each projector pixel is a sharp square
// (a DLP), so the pattern is read at the nearest pixel. Points outside the projector image or
// on a face turned away from the projector get 0. q = the pattern value (the white calibration
// fixes q = 1 for full white); acquire multiplies it by the projector's fall-off where the white
// reference gives one (white.flat_field).
std::vector<float> ProjectPatternOnFace(const cv::Mat& pattern, const DeviceIntrinsics& projector,
                                        const calib::Pose& projector_from_camera,
                                        const calib::Pose& camera_from_sample, const GridShape& grid,
                                        double h, Setup setup, int samples = 8);

// The projector image (CV_8UC1, 255 inside) that lights the rectangle [x0, x1] x [y0, y1] (mm,
// sample frame) of the lit face: pixels whose centre ray meets the lit face inside it.
// The projector images (CV_8UC1, 255 inside) that light each of n x n equal regions of the lit
// face of a block of `size_mm` (back face z = Z back-lit, front face z = 0 front-lit): region
// m = I + n J covers [I X / n, (I + 1) X / n] x [J Y / n, (J + 1) Y / n] (mm, sample frame; a pixel
// whose ray meets an edge exactly lights both regions). Throws InputError when the lit face is
// turned away from the projector (the setup is the other one) or a region gets no projector pixel.
std::vector<cv::Mat> RegionPatterns(const DeviceIntrinsics& projector, const calib::Pose& projector_from_camera,
                                    const calib::Pose& camera_from_sample, const std::array<double, 3>& size_mm,
                                    Setup setup, int n);

// `count` validation spots on a lit face of X x Y mm (size_mm's first two): discs of radius
// min(X, Y) / 16 centred on the points of Halton's sequence (bases 2 and 3), inset by the
// radius: evenly spread, the same for the same block. Each is {x, y, radius} in mm.
std::vector<std::array<double, 3>> ValidationSpots(const std::array<double, 3>& size_mm, int count);

// The projector images (CV_8UC1, 255 inside) that light each disc {x, y, r} (mm, sample frame) of
// the lit face: pixels whose centre ray meets the face inside it. Throws InputError as
// RegionPatterns does.
std::vector<cv::Mat> SpotPatterns(const DeviceIntrinsics& projector, const calib::Pose& projector_from_camera,
                                  const calib::Pose& camera_from_sample, const std::array<double, 3>& size_mm,
                                  Setup setup, const std::vector<std::array<double, 3>>& spots);

// Whether the lit face's four corners (and so, the face being flat and the projector's distortion
// mild, the whole face) fall inside the projector's image.
bool LitFaceInsideProjector(const DeviceIntrinsics& projector, const calib::Pose& projector_from_camera,
                            const calib::Pose& camera_from_sample, const std::array<double, 3>& size_mm,
                            Setup setup);

cv::Mat PatternForFaceRect(const DeviceIntrinsics& projector, const calib::Pose& projector_from_camera,
                           const calib::Pose& camera_from_sample, const GridShape& grid, double h,
                           Setup setup, const std::array<double, 4>& rect);

}  // namespace translume::acquire
