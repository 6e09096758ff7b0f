// SPDX-License-Identifier: MIT
// Subcommands of the inverse problem: simulate, solve, evaluate.
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fmt/format.h>
#include <fstream>
#include <nlohmann/json.hpp>
#include <optional>

#include "solver/gl_context.h"
#include "solver/atomic_file.h"
#include "solver/dataset.h"
#include "solver/evaluate.h"
#include "solver/evaluate_previews.h"
#include "solver/image_io.h"
#include "solver/light.h"
#include "solver/material_io.h"
#include "solver/memory.h"
#include "solver/recover.h"
#include "solver/simulate.h"
#include "solver/status.h"
#include "solver/threads.h"
#include "tools/commands.h"
#include "tools/recovery_flags.h"

namespace translume {
namespace {

namespace fs = std::filesystem;

}  // namespace

void AddRecoveryFlags(CLI::App& app, RecoveryFlags* f) {
  app.add_option("--optimizer", f->optimizer, "lbfgs, ncg or paper")->capture_default_str();
  app.add_option("--lambda", f->options.lambda, "Regularisation weight")->capture_default_str();
  app.add_option("--regularizer", f->regularizer, "tk1, tv or huber")->capture_default_str();
  app.add_flag("--regularize-mu", f->options.regularize_mu, "Regularise mu too");
  app.add_option("--max-iterations", f->options.max_iterations, "Iterations of the heterogeneous fit")
      ->capture_default_str();
  app.add_option("--lbfgs-rank", f->options.lbfgs_rank,
                 "L-BFGS history: pairs of vectors kept, 96 bytes per node each (lower: less memory)")
      ->capture_default_str();
  app.add_option("--level-search", f->options.level_search,
                 "Iterations per trial of the absorption level search after the homogeneous fit (0: off; "
                 "docs/inverse.md)")
      ->capture_default_str();
  app.add_option("--tolerance", f->options.tolerance,
                 "A channel's optimiser stops when an iteration lowers its objective by less than this "
                 "fraction")
      ->capture_default_str();
  AddValidationFlags(app, &f->options);
  AddSolveToleranceFlag(app, &f->options);
  app.add_option("--backend", f->backend, "cpu or gl (OpenGL compute shaders; docs/gpu.md)")
      ->capture_default_str();
}

RecoveryOptions RecoveryFlags::Options(const CLI::App& app, const char* command) const {
  RecoveryOptions o = options;
  o.optimizer = ParseOptimizer(optimizer);
  o.regularizer.kind = ParseRegularizer(regularizer);
  o.backend = ParseBackend(backend);
  if (o.backend == Backend::kGl) GlContext::Get();  // fail before any output
  if (std::string err = o.Validate(); !err.empty()) throw OptionsError(app, command, err);
  return o;
}

void CheckRecoveryFitsInMemory(const GridShape& shape, int conditions, const RecoveryOptions& o,
                               const std::string& what) {
  std::string hint;
  if (o.optimizer == OptimizerKind::kLbfgs && o.lbfgs_rank > 5) {
    RecoveryOptions smaller = o;
    smaller.lbfgs_rank = 5;
    hint = fmt::format(" (with --lbfgs-rank 5 about {}: docs/inverse.md, \"Memory\")",
                       FormatBytes(RecoveryMemoryBytes(shape, conditions, smaller)));
  }
  CheckFitsInMemory(RecoveryMemoryBytes(shape, conditions, o), what, hint);
}

std::string TimeLeft::operator()(const IterationReport& r, int max_iterations) {
  if (first_seconds_ < 0) {
    first_seconds_ = r.seconds;
    first_iteration_ = r.iteration;
  }
  if (r.iteration <= first_iteration_) return "?";
  return "<= " + FormatSeconds((r.seconds - first_seconds_) / (r.iteration - first_iteration_) *
                               std::max(0, max_iterations - r.iteration));
}

std::string FormatSeconds(double s) {
  if (s < 120) return fmt::format("{:.1f} s", s);
  if (s < 7200) return fmt::format("{:.1f} min", s / 60);
  return fmt::format("{:.1f} h", s / 3600);
}


// The first entry of `dir` that a dataset does not consist of (dataset.json, q_*.exr, L_*.exr,
// mask_*.exr and, at the top, holdout/ and validation/ of the same), or "" if there is none.
std::string ForeignEntry(const fs::path& dir, bool top) {
  for (const fs::directory_entry& e : fs::directory_iterator(dir)) {
    const std::string name = e.path().filename().string();
    if (top && (name == "holdout" || name == "validation") && e.is_directory()) {
      if (std::string f = ForeignEntry(e.path(), false); !f.empty()) return f;
      continue;
    }
    const bool image = e.is_regular_file() && name.ends_with(".exr") &&
                       (name.starts_with("q_") || name.starts_with("L_") || name.starts_with("mask_"));
    if (!image && !(name == "dataset.json" && e.is_regular_file())) return e.path().string();
  }
  return "";
}

// simulate's -o: a new or empty folder, or an earlier dataset (which the new one replaces
// whole, holdout/ and validation/ included) holding nothing else; never the folder that holds the input material.
void RequireDatasetFolder(const std::string& out, const std::string& material_path) {
  RequireNotInput("-o", out, {material_path});
  if (!fs::exists(out)) return;
  if (!fs::is_directory(out)) throw InputError(fmt::format("-o {}: is a file, not a folder", out));
  if (fs::is_empty(out)) return;
  if (!fs::exists(fs::path(out) / "dataset.json"))
    throw InputError(fmt::format("-o {}: the folder is not empty and holds no dataset.json; choose a new or empty "
                                 "folder (an earlier dataset there is replaced)", out));
  if (const std::string f = ForeignEntry(out, true); !f.empty())
    throw InputError(fmt::format("-o {}: holds {}, which is not part of a dataset and would be lost; choose a new or "
                                 "empty folder (an earlier dataset alone is replaced)", out, f));
}

int RunSimulate(int argc, char** argv) {
  CLI::App app{"Simulate a capture of a material into a node-space dataset (docs/formats.md):\n"
               "region or spot lights on the lit face, forward solves on a grid K times finer per axis\n"
               "(no inverse crime), radiance sampled back at the material's nodes, optional\n"
               "relative Gaussian noise, held-out spot lights in DATASET/holdout/ (for evaluate) and\n"
               "validation spot lights in DATASET/validation/ (for solve's early stop).",
               "translume simulate"};
  std::string material_path, lights = "4x4", setup = "back", backend = "cpu", out;
  SimulateOptions o;
  app.add_option("material", material_path, "Material file (.vdb): the truth, on the recovery grid")->required();
  app.add_option("--lights", lights, "Training lights: NxN regions of the lit face, or light specs "
                 "separated by ';' (spot:X,Y,R mm, region:I,J/N, uniform)")->capture_default_str();
  app.add_option("--setup", setup, "back (lit back face) or front")->capture_default_str();
  app.add_option("--noise", o.noise, "Relative Gaussian noise sigma per pixel (0.01 = 1 %; at most 1)")->capture_default_str();
  app.add_option("--oversample", o.oversample, "Forward solves on a grid this many times finer per axis: 1, 2, 4, 6 or 8 (the data are the finer face's box means per node)")->capture_default_str();
  app.add_option("--holdout", o.holdout, "Held-out spot conditions to write into DATASET/holdout/: 0..4096")->capture_default_str();
  app.add_option("--validation", o.validation, "Validation spot conditions to write into DATASET/validation/ "
                 "(solve stops on them): 0..4096")->capture_default_str();
  app.add_option("--seed", o.seed, "Noise, holdout and validation seed")->capture_default_str();
  app.add_option("--backend", backend, "cpu or gl (forward solves on the GPU; docs/gpu.md)")
      ->capture_default_str();
  app.add_option("-o,--output", out, "Output dataset folder")->required();
  AddCommonOptions(app);
  if (ParseOrHelp(app, argc, argv)) return 0;
  o.lights = TrainingLights(lights);
  o.setup = ParseSetup(setup);
  o.backend = ParseBackend(backend);
  if (o.backend == Backend::kGl) GlContext::Get();  // fail before any output
  if (std::string err = o.Validate(); !err.empty()) throw OptionsError(app, "simulate", err);
  RequireDatasetFolder(out, material_path);
  RequireFolderPath("-o", out);
  const Material m = ReadMaterial(material_path);
  const auto t0 = std::chrono::steady_clock::now();
  const SimulatedData data = SimulateDataset(m, o);
  WriteFolderAtomically(out, [&](const std::string& tmp) {
    WriteDataset(tmp, data.training);
    if (!data.holdout.conditions.empty()) WriteDataset((fs::path(tmp) / "holdout").string(), data.holdout);
    if (!data.validation.conditions.empty())
      WriteDataset((fs::path(tmp) / "validation").string(), data.validation);
  });
  std::printf("wrote %s: %zu conditions (%s, %s-lit), grid %s, oversampled %dx, noise %g, "
              "%zu held-out, %zu validation, %.1f s\n", (fs::path(out) / "dataset.json").c_str(),
              data.training.conditions.size(), lights.c_str(), SetupName(o.setup),
              m.shape.ToString().c_str(), o.oversample, o.noise, data.holdout.conditions.size(),
              data.validation.conditions.size(),
              std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  return 0;
}

int RunSolve(int argc, char** argv) {
  CLI::App app{"Recover per-node kappa and mu (RGB) from a node-space dataset (SPEC section 4):\n"
               "homogeneous fit first, then the heterogeneous fit in log(kappa), log(mu).\n"
               "Ctrl-C stops after the current iteration and writes the best material so far\n"
               "(exit status 130); a second Ctrl-C ends at once.\n"
               "Writes OUT.vdb, OUT.json (report) and OUT_{kappa,mu}_kNN.png slices.",
               "translume solve"};
  std::string dataset_path, out, checkpoint, init;
  RecoveryFlags flags;
  app.add_option("dataset", dataset_path, "DATASET/ or DATASET/dataset.json")->required();
  app.add_option("-o,--output", out, "Output material (.vdb)")->required();
  AddRecoveryFlags(app, &flags);
  app.add_option("--checkpoint", checkpoint, "Checkpoint file: resumed from if it exists, updated while running");
  app.add_option("--init", init, "Start from this material (.vdb) instead of the homogeneous fit");
  AddCommonOptions(app);
  if (ParseOrHelp(app, argc, argv)) return 0;
  RequireExtension(out, {".vdb"}, "-o");
  const RecoveryOptions o = flags.Options(app, "solve");
  const std::string& optimizer = flags.optimizer;
  const std::string& regularizer = flags.regularizer;
  const Dataset d = ReadDataset(dataset_path);
  const fs::path vdir = fs::path(DatasetFolder(dataset_path)) / "validation";
  const Dataset validation = o.validation_every > 0 && fs::exists(vdir / "dataset.json")
                                 ? ReadDataset(vdir.string()) : Dataset{};
  // Outputs: OUT.vdb, OUT.json and the slices next to them, the checkpoint; none may replace or
  // land in an input, and none may be a folder (found before the solve, not after it).
  const fs::path base = fs::path(out).replace_extension("");
  const std::string report = base.string() + ".json";
  const std::string dataset_dir = DatasetFolder(dataset_path);
  std::vector<std::string> outputs = {out, report};
  for (const std::string& slice : MaterialSlicePaths(base.string(), d.shape)) outputs.push_back(slice);
  for (const std::string& path : outputs) {
    RequireNotInput("-o", path, {dataset_path, dataset_dir, init});
    RequireFilePath("-o", path);
  }
  if (!checkpoint.empty()) {
    RequireNotInput("--checkpoint", checkpoint, {dataset_path, dataset_dir, init});
    RequireFilePath("--checkpoint", checkpoint);
    std::error_code ec;
    for (const std::string& path : outputs)
      if (fs::weakly_canonical(path, ec) == fs::weakly_canonical(checkpoint, ec))
        throw InputError(fmt::format("--checkpoint {}: is also an output of -o {} (its {}); choose another "
                                     "name", checkpoint, out, path == out ? "material" : path == report ?
                                     "report" : "slice " + path));
  }
  CheckRecoveryFitsInMemory(d.shape, int(d.conditions.size()), o,
                            fmt::format("{}: a recovery on the {} grid with {} conditions",
                                        (fs::path(dataset_dir) / "dataset.json").string(),
                                        d.shape.ToString(), d.conditions.size()));
  RecoveryState state;
  std::string resuming;
  if (!checkpoint.empty() && fs::exists(checkpoint)) {
    state = ReadCheckpoint(checkpoint, d);
    resuming = fmt::format("resuming from {} at iteration {} ({} solves, {}){}\n", checkpoint,
                           state.iteration, state.solves, FormatSeconds(state.seconds),
                           init.empty() ? "" : "; --init is not used when resuming");
  } else if (!init.empty()) {
    state = StateFromMaterial(d, ReadMaterial(init));
  }
  // First Ctrl-C: finish the current iteration, then write the best material so far. (Installed
  // before the first line of output, so that a script that waits for it can interrupt.)
  std::optional<SigintGuard> sigint(std::in_place);
  std::printf("solve: %s, grid %s, %zu conditions, %s-lit, optimizer %s, lambda %g (%s%s), "
              "%d threads\n%s", dataset_path.c_str(), d.shape.ToString().c_str(),
              d.conditions.size(), SetupName(d.setup), optimizer.c_str(), o.lambda,
              regularizer.c_str(), o.regularize_mu ? " on kappa and mu" : " on kappa",
              NumThreads(), resuming.c_str());
  if (!validation.conditions.empty())
    std::printf("validation: %zu conditions in %s, checked every %d iterations; the result is the best "
                "checked iterate, the fit stops after %d iterations without a better one\n",
                validation.conditions.size(), vdir.c_str(), o.validation_every, o.validation_patience);
  if (state.x.empty())
    std::printf("homogeneous fit first (6 unknowns)%s...\n",
                o.level_search > 0 ? fmt::format(", then the absorption level search (trials of {} iterations)",
                                                  o.level_search).c_str() : "");
  std::fflush(stdout);
  const bool tty = isatty(fileno(stdout));
  auto last_checkpoint = std::chrono::steady_clock::now();
  bool printed_homogeneous = !state.x.empty();
  TimeLeft time_left;
  std::string last_validation;
  auto callback = [&](const IterationReport& r, const RecoveryState& s) {
    if (!printed_homogeneous) {
      printed_homogeneous = true;
      std::printf("homogeneous fit: kappa %.4g %.4g %.4g mm, mu %.4g %.4g %.4g /mm\n",
                  s.homogeneous_kappa[0], s.homogeneous_kappa[1], s.homogeneous_kappa[2],
                  s.homogeneous_mu[0], s.homogeneous_mu[1], s.homogeneous_mu[2]);
      if (s.level_factor != std::array<double, 3>{1, 1, 1})
        std::printf("absorption level: mu x %.3g %.3g %.3g\n", s.level_factor[0], s.level_factor[1],
                    s.level_factor[2]);
    }
    const std::string left = time_left(r, o.max_iterations);
    if (r.validation_error >= 0) last_validation = fmt::format("  validation E {:.3e} (best {:.3e} at {})",
        r.validation_error, s.best_validation_error, s.best_iteration);
    std::printf("%siter %4d  objective %.4e  |grad| %.3e  solves %lld  elapsed %s  left %s%s%s",
                tty ? "\r" : "", r.iteration, r.objective, r.gradient_norm, (long long)r.solves,
                FormatSeconds(r.seconds).c_str(), left.c_str(), last_validation.c_str(), tty ? "   " : "\n");
    std::fflush(stdout);
    if (!checkpoint.empty() &&
        std::chrono::steady_clock::now() - last_checkpoint > std::chrono::seconds(10)) {
      WriteCheckpoint(checkpoint, d, s);
      last_checkpoint = std::chrono::steady_clock::now();
    }
    return !sigint->interrupted();
  };
  RecoveryOptions ro = o;
  ro.stop = [&] { return sigint->interrupted(); };  // the homogeneous fit and the level search
  const RecoverySummary sum = Recover(d, ro, &state, callback, &validation);
  const bool interrupted = sigint->interrupted();
  sigint.reset();  // writing the outputs: Ctrl-C ends at once again
  if (tty) std::printf("\n");
  // A fit that ran into NaN (data or spacing far outside what the model can reach) has no
  // material to offer: say so instead of writing the starting guess as a result.
  if (!std::isfinite(sum.final_objective) || !std::isfinite(sum.fit_error))
    throw InputError(fmt::format("{}: the fit failed (objective {:.4g} -> {:.4g}: {}); nothing written. Check the "
                                 "dataset's scale: L, q and spacing_mm", dataset_path, sum.initial_objective,
                                 sum.final_objective, sum.message));
  if (!printed_homogeneous)  // (stopped before the fit's first iteration, whose callback prints it)
    std::printf("homogeneous fit: kappa %.4g %.4g %.4g mm, mu %.4g %.4g %.4g /mm\n", sum.homogeneous_kappa[0],
                sum.homogeneous_kappa[1], sum.homogeneous_kappa[2], sum.homogeneous_mu[0], sum.homogeneous_mu[1],
                sum.homogeneous_mu[2]);
  // Stopped before the fit's first iteration: no checkpoint, so that a re-run starts over with
  // the homogeneous fit and the level search, which a resumed run skips.
  if (!checkpoint.empty() && state.iteration == 0 && interrupted)
    std::printf("checkpoint %s not written: stopped before the fit's first iteration (a re-run starts over)\n",
                checkpoint.c_str());
  else if (!checkpoint.empty())
    WriteCheckpoint(checkpoint, d, state);
  const Material m = MaterialFromState(d, state);
  WriteMaterial(out, m);
  std::printf("%s\n", sum.BriefReport().c_str());
  const auto slices = WriteMaterialSlices(base.string(), m);
  nlohmann::json j;
  j["dataset"] = dataset_path;
  j["output"] = out;
  j["grid"] = {d.shape.nx, d.shape.ny, d.shape.nz};
  j["optimizer"] = OptimizerName(o.optimizer);
  j["lambda"] = o.lambda;
  j["regularizer"] = RegularizerName(o.regularizer.kind);
  j["regularize_mu"] = o.regularize_mu;
  j["solve_tolerance"] = o.solve_tolerance;
  j["termination"] = TerminationName(sum.termination);
  j["interrupted"] = interrupted;
  j["message"] = sum.message;
  j["iterations"] = sum.iterations;
  j["solves"] = sum.solves;
  j["seconds"] = sum.seconds;
  j["homogeneous_seconds"] = sum.homogeneous_seconds;
  j["optimizer_seconds"] = sum.optimizer_seconds;
  j["homogeneous_kappa"] = sum.homogeneous_kappa;
  j["homogeneous_mu"] = sum.homogeneous_mu;
  j["level_search"] = {{"iterations_per_trial", o.level_search}, {"trials", sum.level_trials},
                       {"seconds", sum.level_seconds}, {"solves", sum.level_solves},
                       {"mu_factor", sum.level_factor}};
  j["initial_objective"] = sum.initial_objective;
  j["final_objective"] = sum.final_objective;
  j["fit_error"] = sum.fit_error;
  if (sum.validation_checks > 0)
    j["validation"] = {{"conditions", validation.conditions.size()}, {"every", o.validation_every},
                       {"patience", o.validation_patience}, {"checks", sum.validation_checks},
                       {"seconds", sum.validation_seconds}, {"error", sum.validation_error},
                       {"iteration", sum.validation_iteration}};
  nlohmann::json per = nlohmann::json::object();
  for (size_t m2 = 0; m2 < d.conditions.size(); ++m2) per[d.conditions[m2].name] = sum.condition_fit_error[m2];
  j["condition_fit_error"] = per;
  nlohmann::json hist = nlohmann::json::array();
  for (const auto& r : sum.history)
    hist.push_back({{"iteration", r.iteration}, {"objective", r.objective},
                    {"gradient_norm", r.gradient_norm}, {"solves", r.solves}, {"seconds", r.seconds},
                    {"validation_error", r.validation_error}});
  j["history"] = hist;
  j["slices"] = slices;
  WriteAtomically(report, [&](const std::string& tmp) {
    std::ofstream f(tmp);
    f << j.dump(2) << "\n";
    if (!f) throw InputError(fmt::format("{}: cannot write the report", report));
  });
  std::printf("wrote %s, %s and %zu slices (%s_*.png)%s\n", out.c_str(), report.c_str(),
              slices.size(), base.c_str(), interrupted ? "; interrupted: this is the best material so far" : "");
  return interrupted ? kInterruptedExit : 0;
}

int RunEvaluate(int argc, char** argv) {
  CLI::App app{"Evaluate a recovered material (SPEC section 5): held-out relighting error over\n"
               "DATASET/holdout, fit error on the training conditions, relative L2 error of\n"
               "kappa and mu per depth layer.", "translume evaluate"};
  std::string rec_path, truth_path, dataset_path, measured_path;
  bool json = false;
  app.add_option("recovered", rec_path, "Recovered material (.vdb)")->required();
  app.add_option("--truth", truth_path, "True material (.vdb) on the recovery grid: needed for the held-out, "
                 "training and per-layer errors (without it only the fit error)");
  app.add_option("--dataset", dataset_path, "The dataset folder (with holdout/ for held-out errors, with --truth)")
      ->required();
  app.add_option("--measured", measured_path, "A dataset built from photos (acquire's OUT_work/dataset): "
                 "also print its relative RMS error in L and q against --dataset");
  std::string previews;
  app.add_option("--previews", previews, "Write into this folder fit_NAME.png per training condition (measured | "
                 "recovered | residual) and, with --truth and holdout/, holdout_NAME.png (the truth relit | the "
                 "recovery relit | residual)");
  app.add_flag("--json", json, "Print JSON instead of a table");
  AddCommonOptions(app);
  if (ParseOrHelp(app, argc, argv)) return 0;
  const Dataset training = ReadDataset(dataset_path);
  std::optional<DatasetMismatch> mapping;
  Dataset measured;
  if (!measured_path.empty()) {
    try {
      measured = ReadDataset(measured_path);
      mapping = CompareDatasets(measured, training);
    } catch (const InputError& e) {
      throw InputError(fmt::format("--measured {} against --dataset {}: {}", measured_path, dataset_path, e.what()));
    }
    if (!json) {
      const DatasetMismatch& mm = *mapping;
      std::printf("mapping: %s vs %s: L relative RMS %.2f %%, q relative RMS %.2f %%\n",
                  measured_path.c_str(), dataset_path.c_str(), 100 * mm.L_rms, 100 * mm.q_rms);
      std::printf("mapping: L scale per channel %.4f %.4f %.4f; relative RMS after it %.2f %% %.2f %% %.2f %%\n",
                  mm.L_scale[0], mm.L_scale[1], mm.L_scale[2], 100 * mm.L_rms_after_scale[0],
                  100 * mm.L_rms_after_scale[1], 100 * mm.L_rms_after_scale[2]);
    }
  }
  const fs::path hdir = fs::path(DatasetFolder(dataset_path)) / "holdout";
  const Dataset holdout = fs::exists(hdir / "dataset.json") ? ReadDataset(hdir.string()) : Dataset{};
  const Material rec = ReadMaterial(rec_path);
  std::optional<Material> truth;
  if (!truth_path.empty()) truth = ReadMaterial(truth_path);
  if (!previews.empty()) {  // (before the work)
    RequireFolderPath("--previews", previews);
    const std::vector<std::string> inputs = {rec_path, truth_path, DatasetFolder(dataset_path), measured_path};
    for (const std::string& path : EvaluationPreviewPaths(previews, training, holdout, truth.has_value()))
      RequireNotInput("--previews", path, inputs);
  }
  MultigridOptions mg;
  mg.tolerance = 1e-9;
  mg.max_iterations = 300;
  EvaluationReport r;
  try {
    r = EvaluateRecovery(rec, truth ? &*truth : nullptr, training, holdout, mg);
  } catch (const InputError& e) {
    throw InputError(fmt::format("{} against --dataset {}: {}", rec_path, dataset_path, e.what()));
  }
  if (!previews.empty()) {
    const auto written = WriteEvaluationPreviews(previews, r, training, holdout);
    if (!json) std::printf("previews: %zu images in %s\n", written.size(), previews.c_str());
  }
  // The fit against the data the material was fitted to (acquire's), where that is not --dataset.
  double measured_fit = -1;
  if (mapping) {
    try {
      measured_fit = EvaluateRecovery(rec, nullptr, measured, Dataset{}, mg).fit_error;
    } catch (const InputError& e) {
      throw InputError(fmt::format("{} against --measured {}: {}", rec_path, measured_path, e.what()));
    }
  }
  if (!json) {
    std::printf("%s", EvaluationTable(r).c_str());
    if (mapping) std::printf("fit E (vs --measured)    %.3e   (the data it was fitted to)\n", measured_fit);
    if (!truth)
      std::printf("note: without --truth only the fit error%s\n",
                  holdout.conditions.empty() ? "" : " and the held-out error against the data");
    else if (holdout.conditions.empty())
      std::printf("note: %s has no holdout/ (translume simulate --holdout N writes one): no held-out error\n",
                  DatasetFolder(dataset_path).c_str());
    return 0;
  }
  nlohmann::json j = nlohmann::json::parse(EvaluationJson(r));
  if (mapping)
    j["mapping"] = {{"measured", measured_path},
                    {"fit_error", measured_fit},
                    {"L_rms", mapping->L_rms},
                    {"q_rms", mapping->q_rms},
                    {"L_scale", mapping->L_scale},
                    {"L_rms_after_scale", mapping->L_rms_after_scale}};
  std::printf("%s\n", j.dump(2).c_str());
  return 0;
}

}  // namespace translume
