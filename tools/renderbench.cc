// SPDX-License-Identifier: MIT
// translume-renderbench: frames per second of the polygrid renderer per shape and polygrid size
// (the yardstick: Wang et al. 2008, Table III; SPEC section 6). Built-in shapes and named
// materials only (`--material`, the procedural marble by default), so the binary needs no file
// IO libraries and can be bundled for a GPU machine (tools/gpu_bundle.sh translume-renderbench).
// The paper's Bunny size, 253 cubes x 16^3 cells: `--shapes bunny --resolutions 17` (17 nodes per cube edge, 16 intervals).
#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <exception>
#include <fmt/format.h>
#include <string>
#include <vector>

#include "render/diffusion.h"
#include "render/material_map.h"
#include "render/renderer.h"
#include "solver/evaluate.h"
#include "solver/gl_context.h"
#include "solver/memory.h"
#include "solver/status.h"
#include "solver/threads.h"

namespace translume {
namespace {

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

}  // namespace
}  // namespace translume

int main(int argc, char** argv) {
  using namespace translume;
  UsePassiveOpenMpByDefault(argv);
  KeepFreedMemoryForReuse();
  CLI::App app{"Polygrid renderer frame rates: three passes per frame, with and without frame "
               "coherence, for each shape and resolution.", "translume-renderbench"};
  std::vector<std::string> shapes = {"sphere", "torus"};
  std::vector<int> resolutions = {9, 17};
  std::string backend = "gl", relaxation = "chebyshev", material = "procedural:marble";
  // Chebyshev steps that keep E below 1e-3 on the bunny at 9^3 and 17^3 (the paper's Figure 15
  // allows 5e-3; docs/benchmarks.md, 2026-12-01 and "Jacobi tails in a frame's calls").
  std::vector<int> iterations = {30, 15, 15};
  std::vector<int> depth;
  int frames = 10, size = 256, coherent_iterations = 20, stencil = 18;
  bool skip_coherent = false, skip_error = false;
  app.add_option("--shapes", shapes, "Built-in shapes")->delimiter(',');
  app.add_option("--resolutions", resolutions, "Nodes per cube edge")->delimiter(',');
  app.add_option("--backend", backend, "cpu or gl")->capture_default_str();
  app.add_option("--material", material, "procedural:NAME or homogeneous:KAPPA,MU (mm, 1/mm, grey)")
      ->capture_default_str();
  app.add_option("--iterations", iterations, "Relaxation steps per level, coarsest first")
      ->delimiter(',')
      ->capture_default_str();
  app.add_option("--relaxation", relaxation, "jacobi (the paper's) or chebyshev (accelerated)")
      ->capture_default_str();
  app.add_option("--depth", depth,
                 "Adaptive depth per level in node layers, coarsest first (-1: all nodes; the "
                 "default: all nodes on every level)")
      ->delimiter(',');
  app.add_option("--stencil", stencil, "Interior rows' Laplacian: 18 (face and edge-diagonal neighbours) or 6")
      ->check(CLI::IsMember({6, 18}))
      ->capture_default_str();
  app.add_flag("--no-error", skip_error, "Skip the error against the converged solution (a sparse "
                                         "solve in double on the host)");
  app.add_option("--frames", frames, "Timed frames per configuration")->capture_default_str();
  app.add_option("--image", size, "Square image size")->capture_default_str();
  app.add_option("--coherent-iterations", coherent_iterations, "Finest-level steps per coherent frame")
      ->capture_default_str();
  app.add_flag("--skip-coherent", skip_coherent, "Time only frames without frame coherence");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  try {
    DiffusionOptions d;
    d.backend = ParseDiffusionBackend(backend);
    d.iterations = iterations;
    d.depth = depth;
    d.relaxation = ParseRelaxation(relaxation);
    if (const std::string err = d.Validate(); !err.empty())
      throw InputError("--iterations/--depth: " + err);
    d.coherent_iterations = coherent_iterations;
    if (d.backend == DiffusionBackend::kGl) std::printf("%s\n", GlContext::Get().info().ToString().c_str());
    // Medians over the timed frames: t1 incident light, t2 diffusion, t3 shading (ms; gl: GPU
    // timestamps between the passes, Renderer::times); t2 host: the host's time to issue the
    // diffusion's commands (gl; near t2, the GPU waited for them); fps = 1 / median frame time
    // (host); fps pipe: the same frames again pipelined (Renderer::Submit one frame ahead of
    // Collect, as `translume render --turntable` does), 1 / the median time from one frame's
    // image to the next's; diff fps = 1 / median t2 (diffusion only); coh: with frame
    // coherence (skipped: -). build s: the polygrid hierarchy's construction (once). setup s: the
    // Renderer's without coherence (the relaxation rows, Chebyshev's radii and their guard,
    // PolygridDiffusion; on gl the upload too). t2 range:
    // the fastest and slowest frame's diffusion without coherence (a run's spread, to tell it
    // from differences between runs). E: the last frame without coherence against the
    // converged solution (Renderer::ErrorAgainstConverged; the paper's Figure 15 keeps it below 0.5 %).
    std::printf("interior rows: %s\n", stencil == 18 ? "the wide stencil where the grid is sheared (--stencil 18)"
                                                     : "Appendix B's six weights (--stencil 6)");
    std::printf("%-7s %-14s %8s %8s %8s %9s %9s %13s %10s %9s %8s %8s %9s %9s %8s %8s\n", "shape", "polygrid", "nodes",
                "build s", "setup s", "t1 ms", "t2 ms", "t2 range ms", "t2 host ms", "t3 ms", "fps", "fps pipe", "diff fps",
                "t2coh ms", "fps coh", "E");
    for (const std::string& name : shapes)
      for (int res : resolutions) {
        const auto shape = MakeBuiltinShape(name, 20);
        const Polycube pc = BuiltinPolycube(name);
        PolygridOptions po;
        po.resolution = res;
        po.diagonal_stencil = stencil == 18;
        const auto tb = std::chrono::steady_clock::now();
        const auto levels = BuildPolygridHierarchy(pc, *shape, po, 3);
        const double build_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - tb).count();
        const std::vector<NodeMaterial> mats =
            RestrictMaterialHierarchy(levels, NamedNodeMaterial(levels[0], material));
        const double C = ReflectionParameterC(1.3);
        RenderOptions ro;
        ro.width = ro.height = size;
        ro.supersample = 1;
        double fps[2] = {0, 0}, fps_pipe = 0, t1 = 0, t2[2] = {0, 0}, t3 = 0, t2_min = 0, t2_max = 0, error = -1, setup_s = 0,
               t2_issue = 0;
        for (int coh = 0; coh < (skip_coherent ? 1 : 2); ++coh) {
          d.frame_coherence = coh;
          const auto ts = std::chrono::steady_clock::now();
          Renderer r(shape.get(), &levels, mats, C, d, ro);
          if (!coh) setup_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - ts).count();
          const RenderLight light = RenderLight::Parse("dir:1,0.3,0.6");
          r.Render(light, 0);  // warm-up (shader compile, first solve)
          std::vector<double> frame, a, b, c, issue;
          for (int f = 1; f <= frames; ++f) {
            const auto t0 = std::chrono::steady_clock::now();
            r.Render(light, 2.0 * f);  // the light moves 2 deg/frame
            frame.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
            a.push_back(r.times().incident);
            b.push_back(r.times().diffusion);
            c.push_back(r.times().shading);
            issue.push_back(r.times().diffusion_issue);
          }
          fps[coh] = 1 / Median(frame);
          if (!coh) {
            std::vector<double> gaps;
            auto last = std::chrono::steady_clock::now();
            r.Submit(light, 2.0);
            for (int f = 1; f <= frames; ++f) {
              if (f < frames) r.Submit(light, 2.0 * (f + 1));
              r.Collect();
              const auto now = std::chrono::steady_clock::now();
              gaps.push_back(std::chrono::duration<double>(now - last).count());
              last = now;
            }
            fps_pipe = 1 / Median(gaps);
          }
          t2[coh] = Median(b);
          if (!coh) {
            if (!skip_error) error = r.ErrorAgainstConverged();
            t1 = Median(a), t3 = Median(c), t2_issue = Median(issue);
            t2_min = *std::min_element(b.begin(), b.end());
            t2_max = *std::max_element(b.begin(), b.end());
          }
        }
        const std::string coh_ms = skip_coherent ? "-" : std::to_string(1e3 * t2[1]).substr(0, 7);
        const std::string coh_fps = skip_coherent ? "-" : std::to_string(fps[1]).substr(0, 7);
        const std::string range = fmt::format("{:.1f}-{:.1f}", 1e3 * t2_min, 1e3 * t2_max);
        const std::string e = error < 0 ? "-" : fmt::format("{:.1e}", error);
        std::printf("%-7s %-14s %8lld %8.1f %8.2f %9.1f %9.1f %13s %10.2f %9.1f %8.2f %8.2f %9.2f %9s %8s %8s\n",
                    name.c_str(), (std::to_string(pc.cubes.size()) + "x" + std::to_string(res) + "^3").c_str(),
                    (long long)levels[0].size(), build_s, setup_s, 1e3 * t1, 1e3 * t2[0], range.c_str(),
                    1e3 * t2_issue, 1e3 * t3, fps[0], fps_pipe, 1 / t2[0], coh_ms.c_str(), coh_fps.c_str(), e.c_str());
        std::fflush(stdout);
      }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "translume-renderbench: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
