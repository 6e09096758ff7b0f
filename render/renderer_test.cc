// SPDX-License-Identifier: MIT
#include "render/renderer.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>

#include "render/material_map.h"
#include "render/test_metrics.h"
#include "solver/image_io.h"
#include "solver/status.h"

namespace translume {
namespace {

constexpr double kPi = 3.14159265358979323846;

// A small, fast scene: the marble sphere, 2 levels, cpu diffusion.
Image RenderSmallSphere(int width, int height) {
  const auto shape = MakeBuiltinShape("sphere", 20, 24);
  PolygridOptions po;
  po.resolution = 9;
  const auto levels = BuildPolygridHierarchy(BuiltinPolycube("sphere"), *shape, po, 2);
  std::vector<NodeMaterial> mats;
  for (const Polygrid& pg : levels) mats.push_back(ProceduralNodeMaterial(pg, "marble"));
  DiffusionOptions d;
  d.iterations = {200, 200};
  RenderOptions ro;
  ro.width = width;
  ro.height = height;
  Renderer r(shape.get(), &levels, mats, ReflectionParameterC(1.3), d, ro);
  return r.Render(RenderLight::Parse("dir:1,0.3,0.6"));
}

TEST(Render, ImageHasRequestedSizeAndIsNotEmpty) {
  const Image img = RenderSmallSphere(48, 40);
  ASSERT_EQ(img.width, 48);
  ASSERT_EQ(img.height, 40);
  ASSERT_EQ(img.channels, 3);
  int lit = 0;
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) {
      for (int c = 0; c < 3; ++c) ASSERT_TRUE(std::isfinite(img.at(x, y, c)));
      lit += img.at(x, y, 0) > 1e-4f;
    }
  EXPECT_GT(lit, 48 * 40 / 5);   // the sphere covers a good part of the frame
  EXPECT_LT(lit, 48 * 40);       // and the background stays black
  EXPECT_EQ(img.at(0, 0, 0), 0.f);
}

// The gl passes (compute shaders: shadow maps, incident light, rasterisation, shading) against
// the cpu passes, the same scene and light: q at the boundary nodes and the image agree to
// float rounding (a pixel whose sample centre lies on a triangle edge may pick the other
// triangle, so the image is compared in L2 and by the share of pixels that differ).
TEST(Render, GlPassesMatchCpu) {
  auto sky = std::make_shared<Image>();
  sky->width = 32;
  sky->height = 16;
  sky->channels = 3;
  for (int y = 0; y < 16; ++y)
    for (int x = 0; x < 32; ++x)
      for (int c = 0; c < 3; ++c) sky->data.push_back(y < 6 ? 1.f + 0.5f * c : 0.2f);
  RenderLight env = RenderLight::Parse("env:sky.exr");
  env.environment = sky;
  struct Case {
    std::string shape, light;
  };
  for (const Case& k : {Case{"sphere", "dir:1,0.3,0.6"}, Case{"torus", "point:30,10,20"},
                        Case{"torus", "env"}}) {
    SCOPED_TRACE(k.shape + " " + k.light);
    const auto shape = MakeBuiltinShape(k.shape, 20, 24);
    PolygridOptions po;
    po.resolution = 5;
    const auto levels = BuildPolygridHierarchy(BuiltinPolycube(k.shape), *shape, po, 2);
    std::vector<NodeMaterial> mats;
    for (const Polygrid& pg : levels) mats.push_back(ProceduralNodeMaterial(pg, "marble"));
    RenderOptions ro;
    ro.width = 40;
    ro.height = 32;
    ro.surface_reflectance = 0.1;
    ro.environment_directions = 16;
    DiffusionOptions d;
    d.iterations = {50, 50};
    const RenderLight light = k.light == "env" ? env : RenderLight::Parse(k.light);
    Renderer cpu(shape.get(), &levels, mats, ReflectionParameterC(1.3), d, ro);
    const Image a = cpu.Render(light, 15);
    d.backend = DiffusionBackend::kGl;
    Renderer gl(shape.get(), &levels, mats, ReflectionParameterC(1.3), d, ro);
    const Image b = gl.Render(light, 15);
    double eq = 0;
    for (int c = 0; c < 3; ++c)
      eq = std::max(eq, RelativeL2(gl.boundary_light()[c], cpu.boundary_light()[c]));
    int differ = 0, lit = 0;
    for (size_t i = 0; i < a.data.size(); ++i) {
      differ += std::abs(a.data[i] - b.data[i]) > 1e-4 * (std::abs(a.data[i]) + 1e-3);
      lit += a.data[i] > 0;
    }
    const double ei = RelativeL2(b.data, a.data);
    std::printf("[gl passes] %s %s: q relative L2 %.2e, image relative L2 %.2e, %d of %d values "
                "differ by > 1e-4\n", k.shape.c_str(), k.light.c_str(), eq, ei, differ, lit);
    EXPECT_GT(lit, int(a.data.size()) / 5);
    EXPECT_LT(eq, 1e-5);
    EXPECT_LT(ei, 1e-3);
    EXPECT_LT(differ, int(a.data.size()) / 100);
  }
}

// The stored reference: tests/data/render_sphere_marble.exr (linear RGB). After an intentional
// change, regenerate it with
//   TRANSLUME_UPDATE_REFERENCE=1 build/render/render_test --gtest_filter=Render.MatchesStoredReference
TEST(Render, MatchesStoredReference) {
  const std::string path = std::string(TRANSLUME_SOURCE_DIR) + "/tests/data/render_sphere_marble.exr";
  const Image img = RenderSmallSphere(64, 64);
  if (std::getenv("TRANSLUME_UPDATE_REFERENCE")) {
    WriteImage(path, img);
    GTEST_SKIP() << "wrote " << path;
  }
  const Image ref = ReadImage(path);
  ASSERT_EQ(ref.width, img.width);
  ASSERT_EQ(ref.height, img.height);
  double num = 0, den = 0;
  for (size_t i = 0; i < img.data.size(); ++i) {
    num += (img.data[i] - ref.data[i]) * double(img.data[i] - ref.data[i]);
    den += double(ref.data[i]) * ref.data[i];
  }
  const double err = std::sqrt(num / den);
  std::printf("[render] relative L2 difference to the stored reference: %.2e\n", err);
  EXPECT_LT(err, 1e-3);
}

// Fitted exponential decay rate of ln L against the distance along the surface from the
// terminator, over boundary nodes in the dark half with s in [s0, s1] mm.
double DecayRate(const Polygrid& pg, const std::vector<float>& L, const Vec3& light, double R,
                 double s0, double s1) {
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  int n = 0;
  for (int64_t b = 0; b < pg.num_boundary(); ++b) {
    const double theta = std::acos(std::clamp(pg.normal[b].dot(light), -1.0, 1.0));
    const double s = R * (theta - kPi / 2);
    if (s < s0 || s > s1 || !(L[b] > 0)) continue;
    const double y = std::log(L[b]);
    sx += s, sy += y, sxx += s * s, sxy += s * y;
    ++n;
  }
  EXPECT_GT(n, 20);
  return -(n * sxy - sx * sy) / (n * sxx - sx * sx);
}

TEST(Render, DipoleAndPolygridAgreeOnTransmittedFalloff) {
  const double R = 10;
  const auto shape = MakeBuiltinShape("sphere", 2 * R);
  PolygridOptions po;
  po.resolution = 17;
  const Polygrid pg = BuildPolygrid(BuiltinPolycube("sphere"), *shape, po);
  const float kappa = 0.2f, mu = 0.05f;  // sigma_tr = sqrt(mu / kappa) = 0.5 / mm
  const NodeMaterial m = ConstantNodeMaterial(pg, {kappa, kappa, kappa}, {mu, mu, mu});
  const double C = ReflectionParameterC(1.3);
  const Vec3 light(1, 0, 0);
  BoundaryLight q;
  for (int c = 0; c < 3; ++c) {
    q[c].resize(pg.num_boundary());
    for (int64_t b = 0; b < pg.num_boundary(); ++b) {
      const double ci = std::max(0.0, pg.normal[b].dot(light));
      q[c][b] = float(ci * FresnelTransmittance(ci, 1.3));
    }
  }
  BoundaryLight zero;
  for (int c = 0; c < 3; ++c) zero[c].assign(pg.num_boundary(), 0.f);
  const BoundaryLight Lpg = BoundaryRadiance(pg, m, zero, SolveReference(BuildJacobiSystem(pg, m, C, q), 1));
  const BoundaryLight Ldp = DipoleRadiance(pg, {kappa, kappa, kappa}, {mu, mu, mu}, C, q);
  const double rate_pg = DecayRate(pg, Lpg[0], light, R, 2, 10);
  const double rate_dp = DecayRate(pg, Ldp[0], light, R, 2, 10);
  std::printf("[falloff] homogeneous sphere R 10 mm, kappa 0.2 mm, mu 0.05/mm (sigma_tr 0.5/mm): "
              "fitted decay along the surface beyond the terminator (2-10 mm): polygrid %.4f/mm, "
              "dipole %.4f/mm, ratio %.3f\n", rate_pg, rate_dp, rate_pg / rate_dp);
  EXPECT_NEAR(rate_pg / rate_dp, 1.0, 0.10);
}

TEST(Render, MeshShapeRendersAndBadLightsAreRefused) {
  const auto dir = std::filesystem::temp_directory_path();
  const std::string obj = (dir / "tl_blob.obj").string();
  WriteObj(obj, MakeBuiltinShape("blob", 20, 12)->mesh());
  const auto shape = MakeMeshShape(ReadMesh(obj), obj, 20);
  PolygridOptions po;
  po.resolution = 7;
  const auto levels = BuildPolygridHierarchy(BuiltinPolycube("box"), *shape, po, 2);
  std::vector<NodeMaterial> mats;
  for (const Polygrid& pg : levels) mats.push_back(ConstantNodeMaterial(pg, {0.2f, 0.2f, 0.2f}, {0.02f, 0.03f, 0.05f}));
  RenderOptions ro;
  ro.width = ro.height = 32;
  Renderer r(shape.get(), &levels, mats, ReflectionParameterC(1.3), DiffusionOptions{}, ro);
  const Image img = r.Render(RenderLight::Parse("point:30,10,20"));
  double sum = 0;
  for (float v : img.data) sum += v;
  EXPECT_GT(sum, 0);
  EXPECT_EQ(RenderLight::Parse("env:sky.exr").path, "sky.exr");
  EXPECT_THROW(RenderLight::Parse("env:"), InputError);
  EXPECT_THROW(RenderLight::Parse("dir:1,2"), InputError);
  EXPECT_THROW(RenderLight::Parse("spot:1,2,3"), InputError);
  EXPECT_THROW(RenderLight::Parse("dir:0,0,0"), InputError);
}

// A white environment: every node of a convex sphere gets the same irradiance (the hemisphere's
// integral of cos F_t); on the torus the nodes facing into the hole see less sky (occlusion).
TEST(Render, EnvironmentLightingWithOcclusion) {
  auto white = std::make_shared<Image>();
  white->width = 64;
  white->height = 32;
  white->channels = 3;
  white->data.assign(64 * 32 * 3, 1.f);
  const auto samples = EnvironmentSamples(*white, 64);
  double total = 0;
  for (const auto& s : samples) total += s.second[0];
  EXPECT_NEAR(total, 4 * kPi, 1e-2);  // midpoint rule over 32 rows
  RenderLight env = RenderLight::Parse("env:white.exr");
  env.environment = white;
  RenderOptions ro;
  ro.width = ro.height = 16;
  for (const std::string name : {"sphere", "torus"}) {
    const auto shape = MakeBuiltinShape(name, 20, 24);
    PolygridOptions po;
    po.resolution = 5;
    const auto levels = BuildPolygridHierarchy(BuiltinPolycube(name), *shape, po, 1);
    std::vector<NodeMaterial> mats = {ConstantNodeMaterial(levels[0], {0.2f, 0.2f, 0.2f}, {0.02f, 0.02f, 0.02f})};
    Renderer r(shape.get(), &levels, mats, ReflectionParameterC(1.3), DiffusionOptions{}, ro);
    r.Render(env);
    const auto& q = r.boundary_light()[0];
    const Polygrid& pg = levels[0];
    double inner = 0, outer = 0, lo = 1e9, hi = 0;
    int ni = 0, no = 0;
    for (int64_t b = 0; b < pg.num_boundary(); ++b) {
      lo = std::min(lo, double(q[b]));
      hi = std::max(hi, double(q[b]));
      const Vec3& p = pg.position[pg.num_interior + b];
      const Vec3 radial(p.x(), p.y(), 0);
      if (std::abs(pg.normal[b].z()) > 0.5 || radial.norm() == 0) continue;
      (pg.normal[b].dot(radial.normalized()) < 0 ? (++ni, inner) : (++no, outer)) += q[b];
    }
    if (name == "sphere") {
      std::printf("[env] white sky on a sphere: q in [%.3f, %.3f]\n", lo, hi);
      EXPECT_GT(lo, 0.85 * hi);
      EXPECT_GT(lo, 2.0);  // pi * (1 - diffuse Fresnel reflectance) ~ 2.9
    } else {
      std::printf("[env] white sky on a torus: mean q facing the hole %.3f, facing out %.3f\n",
                  inner / ni, outer / no);
      EXPECT_LT(inner / ni, 0.8 * outer / no);
    }
  }
}

}  // namespace
}  // namespace translume
