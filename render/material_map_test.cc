// SPDX-License-Identifier: MIT
#include "render/material_map.h"

#include <gtest/gtest.h>

#include "solver/status.h"

namespace translume {
namespace {

// A block whose kappa encodes the layer (0.1 + 0.01 k) and mu the column (0.01 + 0.001 i).
Material Coded(int nx, int ny, int nz, double h) {
  Material m = Material::Constant({nx, ny, nz}, h, {0.1f, 0.1f, 0.1f}, {0.01f, 0.01f, 0.01f});
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i)
        for (int c = 0; c < 3; ++c) {
          m.kappa[c][m.shape.index(i, j, k)] = 0.1f + 0.01f * k;
          m.mu[c][m.shape.index(i, j, k)] = 0.01f + 0.001f * i;
        }
  return m;
}

TEST(MaterialMap, ShellDepthAndCoreFill) {
  const auto box = MakeBoxShape(Vec3(8, 8, 8));
  PolygridOptions o;
  o.resolution = 9;
  const Polygrid pg = BuildPolygrid(BuiltinPolycube("box"), *box, o);
  const Material m = Coded(4, 4, 3, 1.0);  // 2 mm deep block
  const NodeMaterial nm = MapShellMaterial(pg, m, {});
  for (int64_t n = 0; n < pg.size(); ++n) {
    const double k = std::min(pg.depth_mm[n] / 1.0, 2.0);  // clamped: the core repeats layer 2
    EXPECT_NEAR(nm.kappa[0][n], 0.1 + 0.01 * k, 1e-5) << n;
    if (pg.is_boundary(n)) {
      EXPECT_NEAR(nm.kappa[1][n], 0.1, 1e-6);
    }
    EXPECT_GT(nm.mu[2][n], 0);
  }
  // The centre node of the 8 mm cube lies 4 mm deep: the deepest layer.
  double deepest = 0;
  for (int64_t n = 0; n < pg.size(); ++n) deepest = std::max(deepest, pg.depth_mm[n]);
  EXPECT_GT(deepest, 3.0);
}

TEST(MaterialMap, TileAndClampAlongTheSurface) {
  const auto box = MakeBoxShape(Vec3(8, 8, 8));
  PolygridOptions o;
  o.resolution = 9;
  const Polygrid pg = BuildPolygrid(BuiltinPolycube("box"), *box, o);
  const Material m = Coded(3, 3, 2, pg.mean_boundary_spacing);  // 3 columns: period 3 nodes
  ShellMappingOptions tile, clamp;
  clamp.tile = false;
  const NodeMaterial t = MapShellMaterial(pg, m, tile), c = MapShellMaterial(pg, m, clamp);
  int checked = 0;
  for (int64_t b = pg.num_interior; b < pg.size(); ++b) {
    const auto uv = pg.SurfaceUV(b);
    if (std::abs(uv[0] - std::round(uv[0])) > 1e-9) continue;
    const int u = int(std::round(uv[0]));
    // Exactly on a lattice column the surface coordinate is u spacings: tiled column u mod 3,
    // clamped column min(u, 2).
    EXPECT_NEAR(t.mu[0][b], 0.01 + 0.001 * (u % 3), 1e-6) << u;
    EXPECT_NEAR(c.mu[0][b], 0.01 + 0.001 * std::min(u, 2), 1e-6) << u;
    ++checked;
  }
  EXPECT_GT(checked, 100);
  ShellMappingOptions bad;
  bad.scale = 0;
  EXPECT_THROW(MapShellMaterial(pg, m, bad), InputError);
}

TEST(MaterialMap, ProceduralMaterialsArePositive) {
  const auto s = MakeBuiltinShape("sphere", 10, 16);
  PolygridOptions o;
  o.resolution = 5;
  const Polygrid pg = BuildPolygrid(BuiltinPolycube("sphere"), *s, o);
  for (const std::string name : {"marble", "layers"}) {
    const NodeMaterial m = ProceduralNodeMaterial(pg, name);
    for (int c = 0; c < 3; ++c)
      for (int64_t n = 0; n < pg.size(); ++n) {
        EXPECT_GT(m.kappa[c][n], 0);
        EXPECT_GT(m.mu[c][n], 0);
      }
  }
  EXPECT_THROW(ProceduralNodeMaterial(pg, "wood"), InputError);
}

}  // namespace
}  // namespace translume
