// SPDX-License-Identifier: MIT
// Subcommands over the solver library: synth, forward, info, demo.
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fmt/format.h>
#include <fmt/ranges.h>

#include "solver/forward.h"
#include "solver/dataset.h"
#include "solver/evaluate.h"
#include "solver/recover.h"
#include "solver/simulate.h"
#include "solver/gl_context.h"
#include "solver/gl_solver.h"
#include "solver/image_io.h"
#include "solver/light.h"
#include "solver/material_io.h"
#include "solver/memory.h"
#include "solver/status.h"
#include "solver/synthetic.h"
#include "solver/threads.h"
#include "tools/commands.h"

namespace translume {
namespace {

void PrintSummaries(const ForwardResult& r) {
  const char* names[3] = {"R", "G", "B"};
  for (int c = 0; c < 3; ++c)
    std::printf("  channel %s: %s\n", names[c], r.summaries[c].BriefReport().c_str());
}

void WriteRadiance(const std::string& path, const GridShape& s, const FacePattern& L) {
  WriteImage(path, ImageFromPlanes(int(s.nx), int(s.ny), {L[0].data(), L[1].data(), L[2].data()}));
}

}  // namespace

int RunSynth(int argc, char** argv) {
  CLI::App app{"Write a synthetic material volume with physically plausible kappa and mu.\n"
               "Presets: homogeneous, layered, inclusions, wax (default grid 64x48x16), and the\n"
               "paper's samples at their grids: wax1 (130x53x37), wax2 (140x75x48), marble\n"
               "(256x256x20), stone (128x128x41). --grid sets any preset's grid.",
               "translume synth"};
  SynthOptions o;
  std::string grid, out;
  app.add_option("--preset", o.preset, "Preset name")->required();
  app.add_option("--grid", grid, "Grid size NXxNYxNZ (default: the preset's)");
  app.add_option("--spacing", o.spacing_mm, "Node spacing h in mm")->capture_default_str();
  app.add_option("--seed", o.seed, "Random seed")->capture_default_str();
  app.add_option("--eta", o.eta, "Refractive index (sets C)")->capture_default_str();
  app.add_option("-o,--output", out, "Output material file (.vdb)")->required();
  AddCommonOptions(app);
  if (ParseOrHelp(app, argc, argv)) return 0;
  RequireExtension(out, {".vdb"}, "-o");
  RequireFilePath("-o", out);
  if (!grid.empty()) o.shape = ParseGridShape(grid, "--grid");
  const GridShape shape = o.shape.size() > 0 ? o.shape : DefaultSynthShape(o.preset);
  // The material (RGB kappa, mu) plus OpenVDB's copy while writing.
  CheckFitsInMemory(shape.size() * 3 * 4 * 4, fmt::format("a {} material", shape.ToString()));
  const Material m = SynthesizeMaterial(o);
  WriteMaterial(out, m);
  std::printf("wrote %s: preset %s, grid %s, spacing %g mm, C %.4f\n", out.c_str(),
              o.preset.c_str(), m.shape.ToString().c_str(), m.spacing_mm, m.C);
  return 0;
}

int RunForward(int argc, char** argv) {
  CLI::App app{"Solve the diffusion forward model (SPEC section 3) and write the front-face\n"
               "radiance L = (phi - q) / (2 pi) as an RGB float EXR, pixel (i, j) = node (i, j, 0).\n"
               "Lights: uniform | region:I,J/N | spot:X,Y,R (mm) | image:FILE\n"
               "Exit status 3: a channel's solve did not reach --tolerance (the image is written).",
               "translume forward"};
  std::string material_path, light = "uniform", setup = "back", backend = "cpu", precision, out;
  double tolerance = 1e-6;
  app.add_option("material", material_path, "Material file (.vdb)")->required();
  app.add_option("--light", light, "Light specification")->capture_default_str();
  app.add_option("--setup", setup, "back (lit back face) or front")->capture_default_str();
  app.add_option("--backend", backend, "cpu or gl (OpenGL compute shaders, float; docs/gpu.md)")->capture_default_str();
  app.add_option("--precision", precision, "float or double (default: double on cpu; gl computes in float)");
  app.add_option("--tolerance", tolerance, "Relative residual to reach")->capture_default_str();
  app.add_option("-o,--output", out, "Output radiance image (.exr)")->required();
  AddCommonOptions(app);
  if (ParseOrHelp(app, argc, argv)) return 0;
  RequireExtension(out, {".exr"}, "-o");
  ForwardOptions fo;
  fo.setup = ParseSetup(setup);
  fo.backend = ParseBackend(backend);
  if (fo.backend == Backend::kGl && precision == "double")
    throw InputError("--precision double: the gl backend computes in float (use --backend cpu for double)");
  fo.precision = ParsePrecision(precision.empty() ? (fo.backend == Backend::kGl ? "float" : "double") : precision);
  fo.multigrid.tolerance = tolerance;
  if (std::string err = fo.multigrid.Validate(); !err.empty())
    throw InputError("--tolerance: " + err);
  const LightSpec spec = LightSpec::Parse(light);
  RequireNotInput("-o", out, {material_path, spec.image_path});
  RequireFilePath("-o", out);
  if (fo.backend == Backend::kGl) GlContext::Get();  // fail before any output
  const Material m = ReadMaterial(material_path);
  CheckFitsInMemory(EstimateMemory(m.shape, 1, fo.precision).forward_bytes,
                    fmt::format("{}: a forward solve on the {} grid", material_path, m.shape.ToString()));
  const FacePattern q = GreyPattern(RasterizeLightFile(spec, m.shape, m.spacing_mm));
  if (std::all_of(q[0].begin(), q[0].end(), [](float v) { return v == 0.0f; }))
    throw InputError(fmt::format("--light {}: lights no node of the {} x {} mm lit face", light,
                                 double(m.shape.nx - 1) * m.spacing_mm, double(m.shape.ny - 1) * m.spacing_mm));
  std::printf("forward: %s, grid %s, h %g mm, light %s, setup %s, %d threads\n",
              material_path.c_str(), m.shape.ToString().c_str(), m.spacing_mm, light.c_str(),
              SetupName(fo.setup), NumThreads());
  const ForwardResult r = SolveForward(m, q, fo);
  PrintSummaries(r);
  WriteRadiance(out, m.shape, r.radiance);
  std::printf("wrote %s (%lld x %lld, RGB float)\n", out.c_str(), (long long)m.shape.nx,
              (long long)m.shape.ny);
  bool ok = true;
  for (const auto& s : r.summaries) ok &= s.converged;
  return ok ? 0 : 3;
}

namespace {

// `info MATERIAL.vdb`: the grid, the block's size, eta, and per channel the spread of kappa and
// mu, with the quantiles between which the previews stretch each channel (WriteMaterialSlices).
void PrintMaterialSummary(const std::string& path, const Material& m) {
  const GridShape& s = m.shape;
  const double h = m.spacing_mm;
  std::printf("material %s: %s nodes, spacing %g mm (a block of %g x %g x %g mm), eta %g (C %.4f)\n",
              path.c_str(), s.ToString().c_str(), h, h * double(s.nx - 1), h * double(s.ny - 1),
              h * double(s.nz - 1), m.eta, m.C);
  const double p = 100 * kPreviewQuantile;
  std::printf("  %-12s %11s %11s %11s %11s %11s\n", "", "min", fmt::format("{:g} %", p).c_str(), "median",
              fmt::format("{:g} %", 100 - p).c_str(), "max");
  const char* channels[3] = {"red", "green", "blue"};
  for (const auto& [name, field] : {std::pair{"kappa", &m.kappa}, std::pair{"mu", &m.mu}})
    for (int c = 0; c < 3; ++c) {
      const std::vector<float> v = Quantiles((*field)[c], {0, kPreviewQuantile, 0.5, 1 - kPreviewQuantile, 1});
      std::printf("  %-12s %11.4g %11.4g %11.4g %11.4g %11.4g\n", fmt::format("{} {}", name, channels[c]).c_str(),
                  v[0], v[1], v[2], v[3], v[4]);
    }
  std::printf("  (kappa in mm, mu in 1/mm; the slices that `solve` and `acquire` write show each channel on a "
              "log scale from its %g %% to its %g %% value, a range of at least a factor %g)\n", p, 100 - p,
              kPreviewMinRatio);
}

}  // namespace

int RunInfo(int argc, char** argv) {
  CLI::App app{"Version, build options, backends, threads, and the memory a forward solve and a\n"
               "recovery need for a material or grid; for a material also its size and the spread\n"
               "of kappa and mu per channel.", "translume info"};
  std::string material_path, grid, precision = "double";
  int conditions = 16;
  bool gl = false;
  app.add_flag("--gl", gl, "Create a headless OpenGL context and print platform, vendor, "
                           "renderer, version and limits (TRANSLUME_GL=device|surfaceless|osmesa "
                           "forces a platform)");
  app.add_option("material", material_path, "Material file (.vdb) to size");
  app.add_option("--grid", grid, "Grid NXxNYxNZ to size");
  app.add_option("--conditions", conditions, "Illumination conditions of a recovery")
      ->capture_default_str()->check(PositiveFinite());
  app.add_option("--precision", precision, "float or double")->capture_default_str();
  AddCommonOptions(app);
  if (ParseOrHelp(app, argc, argv)) return 0;
  const Precision sized_precision = ParsePrecision(precision);  // checked even without a grid
  if (!material_path.empty() && !grid.empty())
    throw InputError("info: give a material or --grid, not both");
  // Inputs first: bad input is one line, not a report cut short.
  GridShape shape;
  Material material;
  if (!material_path.empty()) {
    material = ReadMaterial(material_path);
    shape = material.shape;
  }
  if (!grid.empty()) shape = ParseGridShape(grid, "--grid");
  std::printf("translume %s (%s build)\n", TRANSLUME_VERSION, TRANSLUME_BUILD_TYPE);
  std::printf("backends: cpu (multigrid-preconditioned CG, float and double), gl (OpenGL compute, "
              "float)\n");
  if (gl) {
    try {
      std::printf("gl backend:\n  %s\n", [] {
        std::string s = GlContext::Get().info().ToString();
        for (size_t p = s.find('\n'); p != std::string::npos; p = s.find('\n', p + 3)) s.replace(p, 1, "\n  ");
        return s;
      }().c_str());
      std::printf("  shaders: %s\n", GlShaderTuning().c_str());
    } catch (const InputError& e) {
      std::printf("gl backend: unavailable: %s\n", e.what());
    }
  } else {
    std::printf("gl backend: not probed (translume info --gl creates a context and prints it)\n");
  }
  std::printf("threads: %d in use (of %d hardware threads); change with --threads N or "
              "TRANSLUME_THREADS=N\n", NumThreads(), omp_get_num_procs());
  std::printf("indices: 64-bit\n");
  const AvailableMemory memory = ReadAvailableMemory();
  const int64_t avail = memory.bytes;
  if (avail > 0)
    std::printf("memory available: %s%s\n", FormatBytes(avail).c_str(),
                memory.cgroup_bytes >= 0 && memory.cgroup_bytes < memory.meminfo_bytes
                    ? fmt::format(" (the cgroup's memory limit; the machine has {} available)",
                                  FormatBytes(memory.meminfo_bytes)).c_str()
                    : "");
  if (!material_path.empty()) PrintMaterialSummary(material_path, material);
  if (shape.size() > 0) {
    const MemoryEstimate e = EstimateMemory(shape, conditions, sized_precision);
    std::printf("grid %s (%lld nodes), %s:\n", shape.ToString().c_str(), (long long)shape.size(),
                precision.c_str());
    std::printf("  forward solve: %s%s\n", FormatBytes(e.forward_bytes).c_str(),
                avail > 0 && e.forward_bytes > avail ? "  (does NOT fit in available memory)" : "");
    // A recovery runs in double whatever --precision says; the L-BFGS rank sets most of it.
    RecoveryOptions ro;
    const int64_t recovery = RecoveryMemoryBytes(shape, conditions, ro);
    ro.lbfgs_rank = 5;
    const int64_t recovery5 = RecoveryMemoryBytes(shape, conditions, ro);
    std::printf("  recovery with %d conditions, RGB: %s%s; with --lbfgs-rank 5: %s%s\n", conditions,
                FormatBytes(recovery).c_str(),
                avail > 0 && recovery > avail ? "  (does NOT fit in available memory)" : "",
                FormatBytes(recovery5).c_str(),
                avail > 0 && recovery5 > avail ? "  (does NOT fit either)" : "");
  }
  return 0;
}

namespace {

void AddBenchmarks(CLI::App& bench) {
  AddBenchForward(bench);
  AddBenchRecovery(bench);
  AddBenchExposureTimes(bench);
  AddBenchPatterns(bench);
}

}  // namespace

std::vector<std::string> BenchSubcommands() {
  CLI::App app;
  AddBenchmarks(app);
  std::vector<std::string> names;
  for (const CLI::App* sub : app.get_subcommands([](const CLI::App*) { return true; }))
    names.push_back(sub->get_name());
  return names;
}

int RunBench(int argc, char** argv) {
  CLI::App app{"Benchmarks. Results are medians; ratios compare solvers run side by side in\n"
               "the same process on the same problem.", "translume bench"};
  app.require_subcommand(1);
  AddBenchmarks(app);
  AddCommonOptions(app);
  const std::vector<std::string> names = BenchSubcommands();
  if (argc >= 2 && argv[1][0] != '-' && std::find(names.begin(), names.end(), argv[1]) == names.end())
    throw InputError(fmt::format("unknown benchmark '{}' ({})", argv[1], fmt::join(names, ", ")));
  ParseOrHelp(app, argc, argv);
  return 0;
}


}  // namespace translume
