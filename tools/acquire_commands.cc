// SPDX-License-Identifier: MIT
// Subcommands of the capture pipeline: simulate-capture, patterns and acquire.
#include <unistd.h>

#include <array>
#include <chrono>
#include <cmath>
#include <algorithm>
#include <cstdio>
#include <optional>
#include <filesystem>
#include <fmt/format.h>

#include "acquire/acquire.h"
#include "acquire/capture.h"
#include "acquire/patterns.h"
#include "acquire/simulate_capture.h"
#include "calib/error.h"
#include "calib/hdr.h"
#include "render/renderer.h"
#include "solver/dataset.h"
#include "solver/evaluate.h"
#include "solver/image_io.h"
#include "solver/light.h"
#include "solver/synthetic.h"
#include "solver/material_io.h"
#include "solver/memory.h"
#include "solver/simulate.h"
#include "solver/status.h"
#include "solver/threads.h"
#include "tools/commands.h"
#include "tools/recovery_flags.h"

namespace translume {

namespace fs = std::filesystem;

int RunSimulateCapture(int argc, char** argv) {
  CLI::App app{"Write a complete simulated capture folder of a material (docs/capture.md):\n"
               "calibration photos (camera boards, projector planes, response stacks, white and\n"
               "black references), projector patterns for NxN regions of the lit face, and one\n"
               "exposure stack per condition rendered from forward solves on a finer grid through\n"
               "the camera model, with the camera response, clipping and noise; plus the truth\n"
               "(truth/material.vdb, truth/dataset with held-out spots).",
               "translume simulate-capture"};
  std::string material_path, rig_path = "default", setup = "back", lights = "4x4", out;
  acquire::SimulateCaptureOptions o;
  app.add_option("material", material_path, "Material file (.vdb) on the recovery grid")->required();
  app.add_option("--rig", rig_path, "default, or a rig file (.json, docs/capture.md)")->capture_default_str();
  app.add_option("--setup", setup, "back (projector behind the sample) or front")->capture_default_str();
  app.add_option("--lights", lights, "NxN regions of the lit face, one condition each")->capture_default_str();
  app.add_option("--oversample", o.oversample, "Forward solves on a grid this many times finer: 2, 4, 6 or 8")->capture_default_str();
  app.add_option("--holdout", o.holdout, "Held-out spot conditions in truth/dataset/holdout: 0..4096")->capture_default_str();
  app.add_option("--validation", o.validation, "Validation spot conditions, photographed (lighting/vNN): the "
                 "solve stops on them; 0..64")->capture_default_str();
  app.add_option("--exposures", o.exposures, "Photos per exposure stack, one stop apart: 2..16")->capture_default_str();
  app.add_flag("--auto-corners", o.auto_corners, "Leave the face corners to acquire's detection");
  app.add_option("--seed", o.seed, "Noise and pose seed")->capture_default_str();
  app.add_option("-o,--output", out, "New capture folder")->required();
  AddCommonOptions(app);
  if (ParseOrHelp(app, argc, argv)) return 0;
  o.setup = ParseSetup(setup);
  const auto regions = RegionLights(lights);  // validates NxN
  o.lights = regions.front().region_n;
  RequireFolderPath("-o", out);
  if (fs::exists(out) && !(fs::is_directory(out) && fs::is_empty(out)))
    throw InputError(fmt::format("-o {}: exists and is not empty (a new capture folder is written)", out));
  if (std::string why = o.Validate(); !why.empty()) throw OptionsError(app, "simulate-capture", why);
  const Material m = ReadMaterial(material_path);
  const acquire::CaptureRig rig = rig_path == "default"
                                      ? acquire::DefaultCaptureRig(m.shape, m.spacing_mm, o.setup)
                                      : acquire::ReadCaptureRig(rig_path, m.shape, m.spacing_mm, o.setup);
  std::printf("simulate-capture: %s, grid %s, %s-lit, %s regions, %d threads\n", material_path.c_str(),
              m.shape.ToString().c_str(), SetupName(o.setup), lights.c_str(), NumThreads());
  SigintGuard sigint;  // Ctrl-C: stop at the next stage, the temporary folder removed
  o.stop = [&] { return sigint.interrupted(); };
  const auto sum = acquire::SimulateCapture(m, rig, o, out, [](const std::string& line) {
    std::printf("  %s\n", line.c_str());
    std::fflush(stdout);
  });
  std::printf("wrote %s: %s\n", sum.capture_json.c_str(), sum.BriefReport().c_str());
  return 0;
}

int RunPatterns(int argc, char** argv) {
  CLI::App app{"Write the projector images that light NxN regions of the sample's lit face, one\n"
               "condition each (docs/capture.md, step 6), from the camera and projector\n"
               "calibrations and the sample's place: its front face's corners in the camera image,\n"
               "given, or found (or given near them and refined) in a photo of the sample on a\n"
               "dark background, through the lens's blur; where the camera sees side faces of\n"
               "the block, from the block's outline in the photo. Also the images of a few\n"
               "validation spots (acquire's solve stops on them), and conditions.json, the\n"
               "conditions list for capture.json.",
               "translume patterns"};
  std::string camera_path, projector_path, size_text, setup = "back", corners_text, photo, response_path,
      lights = "4x4", out;
  app.add_option("--camera", camera_path, "Camera calibration (translume calibrate camera)")->required();
  app.add_option("--projector", projector_path, "Projector calibration (translume calibrate projector)")->required();
  app.add_option("--sample-mm", size_text, "The block's extent X,Y,Z (mm), as sample_mm in capture.json")->required();
  app.add_option("--setup", setup, "back (projector behind the sample) or front")->capture_default_str();
  app.add_option("--corners", corners_text,
                 "Front face corners in the camera image X1,Y1,..,X4,Y4 (node (0,0) first, clockwise as the camera "
                 "sees the face); used as given, or with --photo refined in it (then up to 5 px off will do)");
  app.add_option("--photo", photo,
                 "A camera photo (or exposure stack folder, or .exr) of the sample, lit, on a dark background, in "
                 "which the corners are found (or, with --corners, refined) through the lens's blur");
  app.add_option("--response", response_path, "Response curve for an 8-bit --photo stack");
  app.add_option("--lights", lights, "NxN regions of the lit face, one condition each")->capture_default_str();
  int validation = 4;
  app.add_option("--validation", validation, "Validation spots besides (vNN.png, \"validation\": true in "
                 "conditions.json): acquire's solve stops on them; 0..64")->capture_default_str();
  app.add_option("-o,--output", out, "New folder for NN.png and conditions.json (e.g. CAPTURE/patterns)")->required();
  AddCommonOptions(app);
  if (ParseOrHelp(app, argc, argv)) return 0;
  if (corners_text.empty() && photo.empty()) throw InputError("give --corners or --photo (or both)");
  if (!response_path.empty() && photo.empty()) throw InputError("--response is for an 8-bit --photo stack");
  const Setup s = ParseSetup(setup);
  const int n = RegionLights(lights).front().region_n;  // validates NxN
  const std::vector<double> size = ParseNumbers(size_text, "--sample-mm", 3, 3);
  for (double v : size)
    if (!(v > 0) || !std::isfinite(v)) throw InputError(fmt::format("--sample-mm {}: every extent must be positive", size_text));
  std::vector<cv::Point2d> corners;
  if (!corners_text.empty()) {
    const std::vector<double> c = ParseNumbers(corners_text, "--corners", 8, 8);
    for (int k = 0; k < 4; ++k) corners.emplace_back(c[size_t(2 * k)], c[size_t(2 * k + 1)]);
  }
  if (std::string why = acquire::PatternFolderProblem(out); !why.empty()) throw InputError("-o " + why);
  RequireFolderPath("-o", out);
  auto flagged = [](const char* flag, const auto& read) {
    try {
      return read();
    } catch (const calib::CalibError& e) {
      throw InputError(fmt::format("{}: {}", flag, e.what()));
    }
  };
  acquire::PatternJob job;
  job.camera = flagged("--camera", [&] { return calib::ReadCameraCalibration(camera_path); });
  job.projector = flagged("--projector", [&] { return calib::ReadProjectorCalibration(projector_path); });
  job.projector_file = projector_path;
  job.size_mm = {size[0], size[1], size[2]};
  job.setup = s;
  job.lights = n;
  if (validation < 0 || validation > 64) throw InputError("--validation: must be within 0..64");
  job.validation = validation;
  job.corners = corners;
  job.corners_source = "--corners";
  if (!photo.empty()) {
    calib::ResponseCurve curve;
    if (!response_path.empty()) curve = calib::ReadResponse(response_path);
    calib::HdrReadInfo info;
    job.photo = calib::ReadHdrOrStack(photo, response_path.empty() ? nullptr : &curve, {}, &info);
    if (!info.time_warning.empty()) std::printf("patterns: warning: %s\n", info.time_warning.c_str());
    job.corners_source = corners.empty() ? "--photo " + photo : "--corners in --photo " + photo;
  }
  const acquire::PatternSet set = acquire::MakeRegionPatterns(job);
  for (const std::string& w : set.warnings) std::printf("patterns: warning: %s\n", w.c_str());
  acquire::WritePatternFolder(set, out);
  const auto& c = set.corners;
  const std::string how =
      !set.refined ? (corners.empty() ? "found in the photo" : "as given")
                   : fmt::format("{} in the photo through a lens blur of {:.2f} px (moved up to {:.2f} px)",
                                 set.side_faces    ? "from the block's outline (the camera sees side faces)"
                                 : set.outline_fit ? "from the block's outline (no side face shows)"
                                 : corners.empty() ? "found and refined" : "refined",
                                 set.refine_blur_px, set.refine_moved_px);
  std::printf("patterns: front face corners (%.2f, %.2f) (%.2f, %.2f) (%.2f, %.2f) (%.2f, %.2f), %s; pose RMS %.2f "
              "px\n", c[0].x, c[0].y, c[1].x, c[1].y, c[2].x, c[2].y, c[3].x, c[3].y, how.c_str(), set.pose_rms_px);
  std::printf("wrote %s: %zu pattern%s (%dx%d regions of the %s face and %d validation spots, %lld to %lld "
              "projector pixels each) and conditions.json for capture.json\n", out.c_str(), set.images.size(),
              set.images.size() == 1 ? "" : "s", n, n, SetupName(s), set.validation, (long long)set.fewest_pixels,
              (long long)set.most_pixels);
  return 0;
}

int RunAcquire(int argc, char** argv) {
  CLI::App app{"From a capture folder (docs/capture.md) to a material: calibration, HDR, sample\n"
               "pose (corners given, or found and refined in the photos; the block's outline where\n"
               "the camera sees side faces; a warning naming the face width the corners fit where\n"
               "sample_mm looks off), mapping of the photos onto the grid nodes, the node-space\n"
               "dataset, the solve, a report (its warnings too) and previews. Intermediate results go\n"
               "to OUT_work/ and are reused on a re-run unless their inputs changed (--force\n"
               "recomputes).\n"
               "Ctrl-C stops at the next stage, or during the solve writes the best material so\n"
               "far (exit status 130); a second Ctrl-C ends at once.",
               "translume acquire"};
  std::string capture_path, out;
  RecoveryFlags flags;
  acquire::AcquireOptions o;
  bool no_solve = false;
  app.add_option("capture", capture_path, "CAPTURE/ or CAPTURE/capture.json")->required();
  app.add_option("-o,--output", out, "Output material (.vdb)")->required();
  AddRecoveryFlags(app, &flags);
  app.add_flag("--force", o.force, "Recompute calibration and HDR even if OUT_work/ has them");
  app.add_flag("--no-solve", no_solve, "Stop after writing the node-space dataset");
  AddCommonOptions(app);
  if (ParseOrHelp(app, argc, argv)) return 0;
  RequireExtension(out, {".vdb"}, "-o");
  RequireFilePath("-o", out);  // else found only when the material is written, after the solve
  o.recovery = flags.Options(app, "acquire");
  o.solve = !no_solve;
  const acquire::CaptureSpec cap = acquire::ReadCapture(capture_path);
  const std::string work = acquire::WorkDir(out);
  const fs::path out_abs = fs::weakly_canonical(fs::absolute(out)), cap_abs = fs::weakly_canonical(fs::absolute(cap.dir)),
                 work_abs = fs::weakly_canonical(fs::absolute(work));
  auto within = [](const fs::path& a, const fs::path& folder) {  // a is folder or lies inside it
    return std::mismatch(folder.begin(), folder.end(), a.begin(), a.end()).first == folder.end();
  };
  if (within(out_abs, cap_abs))
    throw InputError(fmt::format("-o {}: write outside the capture folder (inputs are never touched)", out));
  // So must the work folder: a capture folder named OUT_work would receive its files.
  if (within(work_abs, cap_abs) || within(cap_abs, work_abs))
    throw InputError(fmt::format("-o {}: its work folder {} {} the capture folder {}; choose another -o", out, work,
                                 within(work_abs, cap_abs) ? "is or lies inside" : "holds", cap.dir));
  CheckRecoveryFitsInMemory(cap.grid, int(cap.conditions.size()), o.recovery,
                            fmt::format("{}: a recovery on the {} grid with {} conditions", cap.file,
                                        cap.grid.ToString(), cap.conditions.size()));
  std::printf("acquire: %s, grid %s (h %g mm), %s-lit, %zu conditions, %d threads\n", cap.file.c_str(),
              cap.grid.ToString().c_str(), cap.spacing_mm, SetupName(cap.setup), cap.conditions.size(),
              NumThreads());
  std::fflush(stdout);
  const bool tty = isatty(fileno(stdout));
  const int every = std::max(1, o.recovery.max_iterations / 10);
  // First Ctrl-C: stop at the next stage before the solve, or after the current iteration of
  // the solve and write the best material so far (as `solve` does).
  std::optional<SigintGuard> sigint(std::in_place);
  o.stop = [&] { return sigint->interrupted(); };
  TimeLeft time_left;
  const acquire::AcquireReport rep = acquire::Acquire(
      cap, out, o,
      [](const std::string& line) {
        std::printf("  %s\n", line.c_str());
        std::fflush(stdout);
      },
      [&](const IterationReport& r, const RecoveryState&) {
        const std::string left = time_left(r, o.recovery.max_iterations);
        if (tty || r.iteration % every == 0)
          std::printf("%s  iteration %4d  objective %.4e  solves %lld  elapsed %s  left %s%s", tty ? "\r" : "",
                      r.iteration, r.objective, (long long)r.solves, FormatSeconds(r.seconds).c_str(), left.c_str(),
                      tty ? "   " : "\n");
        std::fflush(stdout);
        return !sigint->interrupted();
      });
  const bool interrupted = o.solve && sigint->interrupted();  // (without a solve, the work is done)
  sigint.reset();
  if (tty) std::printf("\n");
  if (o.solve) std::printf("%s\n", rep.solve.BriefReport().c_str());
  std::printf("%s", rep.Table().c_str());
  std::printf("wrote %s%s, %s/dataset.json%s%s\n", o.solve ? (out + ", ").c_str() : "", rep.report_json.c_str(),
              rep.dataset_dir.c_str(),
              o.solve ? fmt::format(" and {} previews (open {}/previews/index.html)", rep.previews.size() - 1,
                                    rep.work_dir).c_str() : "",
              o.solve ? "" : " (--no-solve: no material)");
  if (interrupted) std::printf("interrupted: %s is the best material so far\n", out.c_str());
  return interrupted ? kInterruptedExit : 0;
}

int RunDemo(int argc, char** argv) {
  CLI::App app{"The main job on the embedded default: synthesise a marble sample, simulate a\n"
               "complete capture of it (calibration photos, 16 back-lit regions and 4 validation\n"
               "spots as 8-bit exposure stacks rendered from forward solves on a 2x finer grid),\n"
               "acquire it (calibrate, merge HDR, find the face's corners in the photos and\n"
               "refine them through the lens's blur, find the pose, map the photos onto the\n"
               "grid, solve, stopping on the validation spots), report the held-out\n"
               "relighting error against the truth, and render the recovered and the true\n"
               "material on a sphere lit from behind with the polygrid renderer.", "translume demo"};
  std::string out = "out/demo", grid = "32x24x8", setup = "back", lights = "4x4";
  int iterations = 150;
  app.add_option("-o,--output", out, "Output folder")->capture_default_str();
  app.add_option("--grid", grid, "Recovery grid NXxNYxNZ")->capture_default_str();
  app.add_option("--setup", setup, "back or front")->capture_default_str();
  app.add_option("--lights", lights, "NxN regions of the lit face")->capture_default_str();
  app.add_option("--max-iterations", iterations, "Optimiser iterations")->capture_default_str();
  AddCommonOptions(app);
  if (ParseOrHelp(app, argc, argv)) return 0;
  const auto t0 = std::chrono::steady_clock::now();
  auto elapsed = [&] { return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(); };
  auto print = [](const std::string& line) {
    std::printf("    %s\n", line.c_str());
    std::fflush(stdout);
  };
  // Every flag and the output folder checked before the minutes of work.
  if (iterations < 0) throw InputError("--max-iterations: must be >= 0");
  if (fs::exists(out) && !fs::is_directory(out))
    throw InputError(fmt::format("-o {}: is a file; the demo writes a folder", out));
  RequireFolderPath("-o", (fs::path(out) / "capture").string());
  SynthOptions so;
  so.preset = "marble";
  so.shape = ParseGridShape(grid, "--grid");
  acquire::SimulateCaptureOptions sc;
  sc.setup = ParseSetup(setup);
  sc.lights = RegionLights(lights).front().region_n;
  sc.auto_corners = true;  // as with real photos: acquire finds the face's corners
  if (std::string why = sc.Validate(); !why.empty()) throw OptionsError(app, "demo", why);
  CheckFitsInMemory(EstimateMemory(RefineShape(so.shape, sc.oversample), 1, Precision::kDouble).forward_bytes +
                        EstimateMemory(so.shape, sc.lights * sc.lights, Precision::kDouble).recovery_bytes,
                    fmt::format("the demo on the {} grid", so.shape.ToString()));
  const Material truth = SynthesizeMaterial(so);
  const fs::path capture = fs::path(out) / "capture";
  // A capture folder from an earlier demo run is replaced once the new one is complete; anything
  // else is left alone.
  if (fs::exists(capture) && !fs::exists(capture / "truth/material.vdb"))
    throw InputError(fmt::format("{}: exists and is not a simulated capture; choose another -o", capture.string()));
  sc.replace_simulated = true;
  // Ctrl-C: the capture stops at its next stage (nothing replaced), acquire at its next stage or
  // iteration (finished stages kept for a re-run), and the demo ends there.
  std::optional<SigintGuard> sigint(std::in_place);
  sc.stop = [&] { return sigint->interrupted(); };
  std::printf("demo: 1/4 simulating a capture of a %s marble sample (h %g mm, %s-lit, %s regions)\n",
              truth.shape.ToString().c_str(), truth.spacing_mm, setup.c_str(), lights.c_str());
  std::fflush(stdout);
  const auto sim = acquire::SimulateCapture(
      truth, acquire::DefaultCaptureRig(truth.shape, truth.spacing_mm, sc.setup), sc, capture.string(), print);
  std::printf("demo: 1/4 wrote %s (%s)\n", sim.capture_json.c_str(), sim.BriefReport().c_str());

  acquire::AcquireOptions ao;
  ao.recovery.max_iterations = iterations;
  ao.stop = sc.stop;
  TimeLeft time_left;
  const std::string rec_path = (fs::path(out) / "recovered.vdb").string();
  std::printf("demo: 2/4 acquiring it: translume acquire %s -o %s\n", capture.c_str(), rec_path.c_str());
  std::fflush(stdout);
  const auto progress = [&](const IterationReport& r, const RecoveryState&) {
    const std::string left = time_left(r, iterations);
    if (r.iteration % 25 == 0)
      print(fmt::format("iteration {:4d}  objective {:.3e}  solves {}  {:.1f} s into the demo, left {}", r.iteration,
                        r.objective, r.solves, elapsed(), left));
    return !sigint->interrupted();
  };
  acquire::AcquireReport rep;
  try {
    rep = acquire::Acquire(acquire::ReadCapture(capture.string()), rec_path, ao, print, progress);
  } catch (const acquire::StageInterrupted& e) {
    // Stopped before the solve: a demo re-run simulates the capture again and reuses no stage,
    // but acquire on this capture goes on from the finished ones.
    throw Interrupted(fmt::format("{}; translume acquire {} -o {} goes on from there", e.where, capture.string(),
                                  rec_path));
  }
  std::printf("%s", rep.Table().c_str());
  if (sigint->interrupted())
    throw Interrupted(fmt::format("stopped during the solve; {} is the best material so far (re-run the demo, or "
                                  "translume acquire {} -o {})", rec_path, capture.string(), rec_path));
  sigint.reset();  // the rest takes seconds: Ctrl-C ends at once again

  const Dataset training = ReadDataset((capture / "truth/dataset").string());
  const Dataset holdout = ReadDataset((capture / "truth/dataset/holdout").string());
  const Dataset measured = ReadDataset(rep.dataset_dir);
  const DatasetMismatch mm = CompareDatasets(measured, training);
  MultigridOptions mg;
  mg.tolerance = 1e-9;
  const Material recovered = ReadMaterial(rec_path);
  const EvaluationReport e = EvaluateRecovery(recovered, &truth, training, holdout, mg);
  std::printf("demo: 3/4 mapping from photos: L within %.2f %% RMS and q within %.2f %% RMS of the "
              "simulator's node-space values\n", 100 * mm.L_rms, 100 * mm.q_rms);
  std::printf("demo: 3/4 held-out relighting error E = %.2e against the truth (%zu spots not used in "
              "the fit; the truth's own floor %.2e)\n", e.holdout_error, holdout.conditions.size(),
              e.truth_holdout_error);
  // Lit from behind and above, so that the light carried through the sample shows; the true
  // material under the same light beside it. Both rendered linear (.exr), then tone mapped with
  // the truth's auto exposure, so that the two PNGs compare.
  const fs::path truth_path = capture / "truth/material.vdb";
  std::array<Image, 2> linear;  // recovered, truth
  const std::array<std::string, 2> stems = {(fs::path(out) / "recovered_sphere").string(),
                                            (fs::path(out) / "truth_sphere").string()};
  for (int k = 0; k < 2; ++k) {
    std::vector<std::string> args = {"render", k ? truth_path.string() : rec_path, "--shape", "sphere", "--light",
                                     "point:-12,8,-12", "--image", "256x256", "-o", stems[k] + ".exr"};
    std::vector<char*> av;
    for (std::string& a : args) av.push_back(a.data());
    if (RunRender(int(av.size()), av.data()) != 0) return 1;
    linear[k] = ReadImage(stems[k] + ".exr");
  }
  const double apart = RelativeL2(linear[0].data, linear[1].data);
  const double stops = std::log2(ToneMap(&linear[1], std::nullopt));
  ToneMap(&linear[0], stops);
  for (int k = 0; k < 2; ++k) WriteImage(stems[k] + ".png", linear[k]);
  std::printf("demo: 4/4 rendered the recovered and the true material on a sphere lit from behind (one exposure, "
              "%+.2f stops): the recovered image is within %.1f %% (relative L2, linear) of the truth's; %.1f s in all\n",
              stops, 100 * apart, elapsed());
  std::printf("demo outputs:\n  capture     %s (photos, calibration, truth/)\n  recovered   %s\n"
              "  work        %s (calibration, HDR, dataset, report.json, previews/index.html)\n  rendering   %s.png "
              "(the truth: %s.png; linear: .exr)\n",
              capture.c_str(), rec_path.c_str(), rep.work_dir.c_str(), stems[0].c_str(), stems[1].c_str());
  return 0;
}

}  // namespace translume
