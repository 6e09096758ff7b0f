// SPDX-License-Identifier: MIT
// translume render / translume edit: the polygrid preview renderer and material editing
// (Wang et al. 2008, Section 5; docs/render.md).
#include <algorithm>
#include <chrono>
#include <climits>
#include <cmath>
#include <filesystem>
#include <cstdio>
#include <fmt/format.h>
#include <fstream>
#include <memory>
#include <optional>

#include "render/edit.h"
#include "render/material_map.h"
#include "render/mesh_io.h"
#include "render/polygrid.h"
#include "render/renderer.h"
#include "render/shape.h"
#include "solver/atomic_file.h"
#include "solver/image_io.h"
#include "solver/material_io.h"
#include "solver/parse.h"
#include "solver/status.h"
#include "tools/commands.h"

namespace translume {
namespace {

// OUT.png -> OUT_007.png for turntable frames.
std::string FramePath(const std::string& path, int frame, int frames) {
  if (frames <= 1) return path;
  const auto dot = path.rfind('.');
  return path.substr(0, dot) + fmt::format("_{:03d}", frame) + path.substr(dot);
}

// MATERIAL: a .vdb file, procedural:NAME, or homogeneous:KAPPA,MU (mm, 1/mm, grey).
std::vector<NodeMaterial> LoadNodeMaterials(const std::string& spec, const std::vector<Polygrid>& levels,
                                            const ShellMappingOptions& mapping, double* C) {
  *C = ReflectionParameterC(1.3);
  const Polygrid& finest = levels[0];
  NodeMaterial m;
  if (IsNamedNodeMaterial(spec)) {
    m = NamedNodeMaterial(finest, spec);
  } else {
    const Material mat = ReadMaterial(spec);
    *C = mat.C;
    m = MapShellMaterial(finest, mat, mapping);
  }
  // Coarser levels average their children (Section 5.3).
  const std::vector<NodeMaterial> out = RestrictMaterialHierarchy(levels, std::move(m));
  return out;
}

std::vector<int> ParseIntList(const std::string& text, const char* flag) {
  std::vector<int> v;
  size_t pos = 0;
  while (pos <= text.size()) {
    const size_t comma = std::min(text.find(',', pos), text.size());
    try {
      size_t used = 0;
      const std::string tok = text.substr(pos, comma - pos);
      v.push_back(std::stoi(tok, &used));
      if (used != tok.size()) throw std::invalid_argument("trailing");
    } catch (const std::exception&) {
      throw InputError(std::string(flag) + " " + text + ": expected comma-separated integers");
    }
    pos = comma + 1;
  }
  return v;
}

}  // namespace

int RunRender(int argc, char** argv) {
  CLI::App app{"Render a material on a shape with the polygrid diffusion renderer (Wang et al.\n"
               "2008, Section 5). MATERIAL: a .vdb file (mapped as a shell), procedural:marble,\n"
               "procedural:layers, or homogeneous:KAPPA,MU. Shapes: slab, sphere, torus, blob, bunny\n"
               "(253 cubes), or"
               " a closed mesh (.obj, .ply) with an optional --polycube (a file, or auto).",
               "translume render"};
  std::string material, shape_name = "sphere", polycube_path, save_polycube, light = "dir:1,0.3,0.6", out,
              camera, image = "256x256", iterations = "60,30,30", depth, backend = "cpu", placement = "winslow",
              relaxation = "chebyshev";
  double size_mm = 20, map_scale = 1, first_layer = 0.1;
  int resolution = 17, levels = 3, turntable = 1, variance_steps = PolygridOptions().variance_iterations, stencil = 18;
  bool coherence = false, clamp = false, check_error = false;
  std::optional<double> exposure;  // stops; none: auto exposure
  RenderOptions ro;
  app.add_option("material", material, "Material")->required();
  app.add_option("--shape", shape_name, "slab|sphere|torus|blob|bunny|MESH.obj|MESH.ply")->capture_default_str();
  app.add_option("--polycube", polycube_path,
                 "Polycube file (docs/render.md); auto:N: the cells of an N-cell grid along the shape's longest "
                 "axis whose centres lie inside it, in the frame the mesh's faces follow; auto: the first N of "
                 "1..12 whose polycube has the mesh's genus, a grid that does not fold and cubes at most 2:1; "
                 "default: the shape's own (meshes: auto)");
  app.add_option("--save-polycube", save_polycube, "Write the polycube used (e.g. auto's) to this file");
  app.add_option("--size", size_mm, "Largest extent of the object, mm (0.001 .. 1e6)")->capture_default_str();
  app.add_option("--resolution", resolution, "Polygrid nodes per cube edge")->capture_default_str();
  app.add_option("--levels", levels, "Hierarchy levels (Section 5.3)")->capture_default_str();
  app.add_option("--first-layer", first_layer, "First interior nodes at this fraction of the boundary spacing: (0, 0.5)")
      ->capture_default_str();
  app.add_option("--placement", placement,
                 "Interior nodes: winslow (elliptic grid generation: nearer-orthogonal cells, more accurate on "
                 "curved shapes) or variance (the paper's edge-length variance steps); docs/render.md")
      ->capture_default_str();
  app.add_option("--stencil", stencil,
                 "Interior rows' Laplacian: 18 (the face and edge-diagonal neighbours where the grid is "
                 "sheared: second order there too) or 6 (the paper's Appendix B: less work per step on "
                 "sheared grids); docs/render.md")
      ->check(CLI::IsMember({6, 18}))
      ->capture_default_str();
  app.add_option("--variance-steps", variance_steps,
                 "With --placement variance: gradient steps on the interior nodes' edge-length variance (0: "
                 "smoothing only)")
      ->capture_default_str();
  app.add_option("--iterations", iterations,
                 "Relaxation steps per level (0..1000000), coarsest first (a longer list than the levels drops "
                 "its first entries, a shorter one repeats its last)")->capture_default_str();
  app.add_option("--depth", depth, "Adaptive depth per level in node layers, coarsest first (-1: all; the coarsest level, with no coarser solution to keep, always updates all)");
  app.add_option("--relaxation", relaxation,
                 "Diffusion steps: jacobi (the paper's) or chebyshev (the same steps accelerated by Chebyshev's "
                 "semi-iteration)")->capture_default_str();
  app.add_option("--backend", backend, "All three passes on cpu or gl (compute shaders)")->capture_default_str();
  app.add_option("--light", light, "dir:X,Y,Z | point:X,Y,Z (mm; shadows in every direction: a cube shadow map when near or inside the object's bounding sphere) | env:FILE.exr (lat-long)")->capture_default_str();
  app.add_option("--camera", camera,
                 "AZIMUTH,ELEVATION in degrees (default 30,25), and optionally ,DISTANCE of the eye from the "
                 "object's centre in mm (default: the whole object in view; nearer for a close-up)");
  app.add_option("--image", image, "Output size WxH")->capture_default_str();
  app.add_option("--supersample", ro.supersample, "Samples per pixel per axis")->capture_default_str();
  app.add_option("--turntable", turntable, "Frames of a turntable (object rotating under fixed light): 1..3600")->capture_default_str();
  app.add_flag("--coherence", coherence, "Frame coherence: start each frame from the last solution");
  app.add_flag("--check-error", check_error,
               "After each frame, its diffusion's error E against the converged solution of the same equations "
               "(the paper's Figure 15 metric, which it keeps below 5e-3; one sparse solve per frame: seconds, ~50 s "
               "on a million nodes), to choose --iterations and --depth");
  app.add_option("--model", ro.model, "polygrid or dipole (homogeneous baseline)")->capture_default_str();
  app.add_option("--specular", ro.specular, "Ward rho_s")->capture_default_str();
  app.add_option("--roughness", ro.roughness, "Ward alpha")->capture_default_str();
  app.add_option("--reflectance", ro.surface_reflectance, "Lambertian surface reflectance")->capture_default_str();
  app.add_flag("--clamp", clamp, "Clamp the material in u, v instead of tiling");
  app.add_option("--map-scale", map_scale, "Surface mm per material mm")->capture_default_str();
  app.add_option("--exposure", exposure, "PNG exposure in stops (default: auto, from the first frame; printed)");
  app.add_option("-o,--output", out, "Output image (.png or .exr)")->required();
  AddCommonOptions(app);
  if (ParseOrHelp(app, argc, argv)) return 0;
  const std::string ext = Extension(out);
  RequireExtension(out, {".png", ".exr"}, "-o");
  const auto wh = WholeNumbers(image, "x");
  if (!wh || (*wh)[0] < 1 || (*wh)[1] < 1 || (*wh)[0] > INT_MAX || (*wh)[1] > INT_MAX)
    throw InputError("--image " + image + ": expected WxH, whole numbers of pixels");
  ro.width = int((*wh)[0]);
  ro.height = int((*wh)[1]);
  if (!camera.empty()) {
    const std::vector<double> v = ParseNumbers(camera, "--camera", 2, 3);
    ro.azimuth_deg = v[0];
    ro.elevation_deg = v[1];
    if (v.size() == 3 && !((ro.camera_distance_mm = v[2]) > 0))
      throw InputError("--camera " + camera + ": the distance (mm, from the object's centre) must be > 0");
  }
  if (exposure && !std::isfinite(*exposure)) throw InputError("--exposure: must be a finite number of stops");
  if (turntable < 1 || turntable > 3600)
    throw InputError(fmt::format("--turntable: must be within 1..3600 frames (0.1 degree steps), got {}", turntable));
  if (levels < 1) throw InputError("--levels: must be >= 1");
  if (variance_steps < 0) throw InputError("--variance-steps: must be >= 0");
  if (!(first_layer > 0 && first_layer < 0.5))
    throw InputError(fmt::format("--first-layer: must be within (0, 0.5) of the boundary spacing, got {}", first_layer));
  if (app.count("--variance-steps") && placement != "variance")
    throw InputError("--variance-steps: applies to --placement variance only (placement is " + placement + ")");
  if (std::string err = ro.Validate(); !err.empty()) throw OptionsError(app, "render", err);
  RenderLight L = RenderLight::Parse(light);
  const bool mesh = Extension(shape_name) == ".obj" || Extension(shape_name) == ".ply";
  for (int f = 0; f < turntable; ++f) {
    const std::string frame = FramePath(out, f, turntable);
    RequireNotInput("-o", frame, {material, L.kind == RenderLight::Kind::kEnvironment ? L.path : "",
                                  mesh ? shape_name : "", polycube_path});
    RequireFilePath("-o", frame);
  }
  if (!save_polycube.empty()) {
    RequireNotInput("--save-polycube", save_polycube,
                    {material, L.kind == RenderLight::Kind::kEnvironment ? L.path : "", mesh ? shape_name : "",
                     polycube_path});
    RequireFilePath("--save-polycube", save_polycube);
    std::error_code ec;
    for (int f = 0; f < turntable; ++f)
      if (std::filesystem::weakly_canonical(FramePath(out, f, turntable), ec) ==
          std::filesystem::weakly_canonical(save_polycube, ec))
        throw InputError(fmt::format("--save-polycube {}: is also frame {} of -o {}; choose another name",
                                     save_polycube, f, out));
  }
  if (check_error && ro.model != "polygrid")
    throw InputError("--check-error: --model " + ro.model + " has no diffusion steps to check");
  if (L.kind == RenderLight::Kind::kEnvironment) {
    L.environment = std::make_shared<Image>(ReadImage(L.path));
    if (const std::string problem = EnvironmentMapProblem(*L.environment); !problem.empty())
      throw InputError("--light env:" + L.path + ": " + problem);
  }

  std::vector<std::string> repairs;
  std::unique_ptr<Shape> shape = mesh ? MakeMeshShape(ReadMesh(shape_name, &repairs), shape_name, size_mm)
                                      : MakeBuiltinShape(shape_name, size_mm);
  for (const std::string& repair : repairs) std::printf("render: %s: %s\n", shape_name.c_str(), repair.c_str());
  const bool auto_polycube = polycube_path.rfind("auto", 0) == 0 || (mesh && polycube_path.empty());
  if (polycube_path == "auto" || (mesh && polycube_path.empty())) {
    std::printf("render: choosing a polycube for %s (--polycube auto) ...\n", shape->name().c_str());
    std::fflush(stdout);
  }
  std::string polycube_label;
  const Polycube pc = ResolvePolycube(polycube_path, *shape, mesh ? "" : shape_name, &polycube_label,
                                      [](const std::string& line) {
                                        std::printf("%s", line.c_str());
                                        std::fflush(stdout);
                                      });
  if (auto_polycube)
    std::printf("render: polycube %s from the cells inside %s\n", polycube_label.c_str(), shape->name().c_str());
  if (!save_polycube.empty()) {
    WriteAtomically(save_polycube, [&](const std::string& tmp) {
      std::ofstream f(tmp);
      f << "# " << pc.cubes.size() << " cubes for " << shape->name() << " (translume render --polycube "
        << (auto_polycube ? polycube_label : polycube_path.empty() ? "default" : polycube_path) << ")\n"
        << FormatPolycube(pc);
      if (!f.flush()) throw InputError(save_polycube + ": cannot write");
    });
    std::printf("render: wrote the polycube to %s\n", save_polycube.c_str());
  }
  for (const std::string& note : PolycubeNotes(*shape, pc, polycube_label))
    std::printf("render: note: %s\n", note.c_str());
  PolygridOptions po;
  po.resolution = resolution;
  po.first_layer_fraction = first_layer;
  po.variance_iterations = variance_steps;
  po.placement = ParseInteriorPlacement(placement);
  po.diagonal_stencil = stencil == 18;
  // The build takes seconds on large polycubes (the bunny: ~10 s on two cores): say so first.
  if (pc.cubes.size() > 16) {
    std::printf("render: building the polygrid of %s (%zu cubes x %d^3, up to %d level%s) ...\n",
                shape->name().c_str(), pc.cubes.size(), resolution, levels, levels == 1 ? "" : "s");
    std::fflush(stdout);
  }
  auto t0 = std::chrono::steady_clock::now();
  const std::vector<Polygrid> grids = BuildPolygridHierarchy(pc, *shape, po, levels);
  const double build_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  ShellMappingOptions mo;
  mo.tile = !clamp;
  mo.scale = map_scale;
  double C = 0;
  std::vector<NodeMaterial> mats = LoadNodeMaterials(material, grids, mo, &C);
  DiffusionOptions dopt;
  dopt.backend = ParseDiffusionBackend(backend);
  dopt.iterations = ParseIntList(iterations, "--iterations");
  dopt.relaxation = ParseRelaxation(relaxation);
  if (!depth.empty()) dopt.depth = ParseIntList(depth, "--depth");
  dopt.frame_coherence = coherence;
  // Measured on the torus at 9^3 (the converged frames against the coherent ones) with Jacobi's
  // steps: mean 1.5 %, at most 7 % off at 10-degree steps; 4-5 %, at most 15 % at 30 degrees.
  // Chebyshev's 50 steps: 0.01 % mean, 0.03 % at most at 30 degrees (docs/benchmarks.md).
  if (coherence && turntable == 1) std::printf("render: note: --coherence does nothing for a single frame\n");
  if (coherence && turntable > 1 && turntable < 36 && dopt.relaxation == Relaxation::kJacobi)
    std::printf("render: note: --coherence starts each frame from the last and relaxes it %d steps, so at "
                "%.0f-degree steps frames lag the converged image (on a torus up to ~15 %% at 30 degrees, ~7 %% at "
                "10); use 36 or more frames, or leave --coherence off\n", dopt.coherent_iterations, 360.0 / turntable);
  if (std::string err = dopt.Validate(); !err.empty()) throw InputError("--iterations/--depth: " + err);
  std::printf("render: %s on %s, polygrid %zu cubes x %d^3 (%lld nodes, %lld boundary, %lld with fallback "
              "Laplacian weights, %lld of them per-axis, %lld on the 18-point stencil), %zu levels, built in %.2f s\n",
              material.c_str(), shape->name().c_str(), pc.cubes.size(), resolution, (long long)grids[0].size(),
              (long long)grids[0].num_boundary(), (long long)grids[0].fallback_weights,
              (long long)grids[0].axis_weights, (long long)grids[0].diagonal_stencil_nodes, grids.size(), build_s);
  for (const std::string& note : PolygridNotes(grids, levels, polycube_label, shape->name()))
    std::printf("render: note: %s\n", note.c_str());
  if (ro.model == "dipole") {
    bool homogeneous = true;
    for (int ch = 0; ch < 3; ++ch)
      for (size_t n = 1; n < mats[0].kappa[ch].size(); ++n)
        homogeneous &= mats[0].kappa[ch][n] == mats[0].kappa[ch][0] && mats[0].mu[ch][n] == mats[0].mu[ch][0];
    if (!homogeneous)
      std::printf("render: note: --model dipole is for homogeneous materials; using the mean kappa and mu\n");
    // Every boundary node sums the light from the others (near ones per source, far ones per
    // cell): on the bunny at the default resolution, ~50x the polygrid diffusion's time (40 s).
    std::printf("render: the dipole sums the light over the surface at each of the %lld boundary nodes%s ...\n",
                (long long)grids[0].num_boundary(),
                grids[0].num_boundary() > 20000 ? " (slow here: a lower --resolution renders faster)" : "");
    std::fflush(stdout);
  }
  Renderer renderer(shape.get(), &grids, std::move(mats), C, dopt, ro);
  for (const std::string& note : renderer.Notes()) std::printf("render: note: %s\n", note.c_str());
  // Frames pipelined after the first (Renderer::Submit): frame f + 1 is issued before frame f
  // is taken and written, so on the gl backend the GPU renders it meanwhile. Frame 0 alone, so
  // that its boundary radiance is at hand below; --check-error measures each frame alone.
  // Each frame prints its passes' times and 1 / their sum as its fps (gl: GPU timestamps,
  // which pipelining leaves alone); a turntable also prints its throughput at the end.
  int submitted = 0;
  const auto start = std::chrono::steady_clock::now();
  for (int f = 0; f < turntable; ++f) {
    const int ahead = f > 0 && !check_error ? 1 : 0;
    for (; submitted < turntable && submitted <= f + ahead; ++submitted)
      renderer.Submit(L, 360.0 * submitted / turntable);
    Image img = renderer.Collect();
    if (ext == ".png") {
      // Auto exposure from the first frame only: a turntable's frames share it (no flicker).
      const double scale = ToneMap(&img, exposure);
      if (!exposure) {
        exposure = std::log2(scale);
        std::printf("render: exposure %+.2f stops (auto%s; --exposure %.2f renders others alike)\n", *exposure,
                    turntable > 1 ? ", from the first frame, for every frame" : "", *exposure);
      }
    }
    const std::string path = FramePath(out, f, turntable);
    WriteImage(path, img);
    const FrameTimes& t = renderer.times();
    if (f == 0) {
      const auto& R = renderer.boundary_radiance()[0];
      const auto [lo, hi] = std::minmax_element(R.begin(), R.end());
      double sum = 0;
      for (float v : R) sum += v;
      std::printf("boundary radiance (red): min %.3g, mean %.3g, max %.3g\n", *lo, sum / R.size(), *hi);
      float brightest = 0;
      for (const auto& channel : renderer.boundary_radiance())
        for (float v : channel) brightest = std::max(brightest, v);
      const bool blank = std::all_of(img.data.begin(), img.data.end(), [](float v) { return v == 0; });
      if (blank && brightest > 0)
        std::printf("render: note: the image is black: the object is not in the camera's view (is --camera's "
                    "eye inside the object, or too far away?)\n");
      if (brightest == 0)
        std::printf("render: note: no light reaches the surface, so the object renders black%s\n",
                    L.kind == RenderLight::Kind::kPoint         ? " (is the point light inside the object?)"
                    : L.kind == RenderLight::Kind::kEnvironment ? " (is the environment map black?)"
                                                                : "");
    }
    std::printf("frame %d: incident %.1f ms, diffusion %.1f ms, shading %.1f ms (%.2f fps) -> %s\n", f,
                1e3 * t.incident, 1e3 * t.diffusion, 1e3 * t.shading, 1 / (t.incident + t.diffusion + t.shading),
                path.c_str());
    if (check_error) {
      const double E = renderer.ErrorAgainstConverged();
      // Coherent frames after the first run DiffusionOptions::coherent_iterations finest steps.
      const char* hint = !(E > 5e-3)                     ? ""
                         : dopt.frame_coherence && f > 0 ? " (above the paper's 5e-3: a coherent frame's steps start "
                                                           "from the last frame; use more --turntable frames or "
                                                           "leave --coherence off)"
                                                         : " (above the paper's 5e-3: raise --iterations, or --depth)";
      std::printf("frame %d: diffusion E %.2e against the converged solution%s\n", f, E, hint);
    }
  }
  if (turntable > 1) {
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    std::printf("render: %d frames in %.2f s (%.2f fps, writing the files included%s)\n", turntable, s,
                turntable / s, check_error ? " and --check-error's solves" : "");
  }
  return 0;
}

int RunEdit(int argc, char** argv) {
  CLI::App app{"Edit a material (Wang et al. 2008, Section 5.4): multiply or add constants to\n"
               "kappa and mu, within a pattern mask (image stretched over x-y) and a depth range.",
               "translume edit"};
  std::string material, mask, depth, channels, out;
  std::vector<std::string> scales, adds;
  app.add_option("material", material, "Material file (.vdb)")->required();
  app.add_option("--scale", scales, "kappa=S or mu=S (multiply; repeated ones multiply)");
  app.add_option("--add", adds, "kappa=A or mu=A (add, mm or 1/mm; repeated ones add up)");
  app.add_option("--mask", mask, "Pattern mask image (luminance 0..1 weights the edit)");
  app.add_option("--depth", depth, "Node layers A:B (inclusive) to edit");
  app.add_option("--channels", channels, "Channels to edit: letters of r, g, b (default: rgb)");
  app.add_option("-o,--output", out, "Output material (.vdb)")->required();
  AddCommonOptions(app);
  if (ParseOrHelp(app, argc, argv)) return 0;
  RequireExtension(out, {".vdb"}, "-o");
  EditOptions eo;
  for (const auto& s : scales) eo.ParseTerm(s, false);
  for (const auto& a : adds) eo.ParseTerm(a, true);
  if (!depth.empty()) eo.ParseDepth(depth);
  if (!channels.empty()) eo.ParseChannels(channels);
  RequireNotInput("-o", out, {material, mask});
  RequireFilePath("-o", out);
  const Material m = ReadMaterial(material);
  Image mask_image;
  if (!mask.empty()) {
    mask_image = ReadImage(mask);
    RequireFinitePixels(mask_image, "--mask " + mask);
  }
  const Material edited = EditMaterial(m, eo, mask.empty() ? nullptr : &mask_image);
  WriteMaterial(out, edited);
  std::printf("wrote %s: kappa x%g %+g mm, mu x%g %+g /mm%s%s%s\n", out.c_str(), eo.scale_kappa,
              eo.add_kappa, eo.scale_mu, eo.add_mu, mask.empty() ? "" : (", mask " + mask).c_str(),
              depth.empty() ? "" : (", layers " + depth).c_str(),
              channels.empty() ? "" : (", channels " + channels).c_str());
  return 0;
}

}  // namespace translume
