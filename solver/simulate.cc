// SPDX-License-Identifier: MIT
#include "solver/simulate.h"

#include <algorithm>
#include <cmath>
#include <fmt/format.h>
#include <random>
#include <thread>
#include <atomic>
#include <exception>
#include <omp.h>

#include "solver/face_measurement.h"
#include "solver/status.h"
#include "solver/threads.h"

namespace translume {

GridShape RefineShape(const GridShape& s, int K) {
  return {(s.nx - 1) * K + 1, (s.ny - 1) * K + 1, (s.nz - 1) * K + 1};
}

Material RefineMaterial(const Material& m, int K) {
  TL_CHECK(K >= 1);
  if (K == 1) return m;
  const GridShape& s = m.shape;
  Material f = m;
  f.shape = RefineShape(s, K);
  f.spacing_mm = m.spacing_mm / K;
  // Per fine index along an axis: the lower coarse node and the weight of the upper one.
  auto axis = [K](int64_t n_fine, int64_t n_coarse, std::vector<int64_t>* lo, std::vector<double>* w) {
    lo->resize(n_fine);
    w->resize(n_fine);
    for (int64_t i = 0; i < n_fine; ++i) {
      (*lo)[i] = std::min(i / K, n_coarse - 2);
      (*w)[i] = double(i - (*lo)[i] * K) / K;
    }
  };
  std::array<std::vector<int64_t>, 3> lo;
  std::array<std::vector<double>, 3> w;
  for (int a = 0; a < 3; ++a) axis(f.shape.n(a), s.n(a), &lo[a], &w[a]);
  for (int c = 0; c < 3; ++c) {
    for (auto* field : {&f.kappa, &f.mu}) {
      const std::vector<float>& src = (field == &f.kappa ? m.kappa : m.mu)[c];
      std::vector<float>& dst = (*field)[c];
      dst.assign(f.shape.size(), 0.0f);
#pragma omp parallel for schedule(static)
      for (int64_t k = 0; k < f.shape.nz; ++k)
        for (int64_t j = 0; j < f.shape.ny; ++j)
          for (int64_t i = 0; i < f.shape.nx; ++i) {
            double v = 0;
            for (int corner = 0; corner < 8; ++corner) {
              const int dx = corner & 1, dy = (corner >> 1) & 1, dz = (corner >> 2) & 1;
              const double wt = (dx ? w[0][i] : 1 - w[0][i]) * (dy ? w[1][j] : 1 - w[1][j]) *
                                (dz ? w[2][k] : 1 - w[2][k]);
              if (wt != 0) v += wt * src[s.index(lo[0][i] + dx, lo[1][j] + dy, lo[2][k] + dz)];
            }
            dst[f.shape.index(i, j, k)] = float(v);
          }
    }
  }
  return f;
}

std::vector<FacePattern> RenderFrontFace(const Material& material, Setup setup,
                                         const std::vector<FacePattern>& lights,
                                         const MultigridOptions& multigrid, Backend backend,
                                         int max_at_once, std::vector<SideFaces>* sides) {
  ForwardOptions fo;
  fo.setup = setup;
  fo.multigrid = multigrid;
  fo.backend = backend;
  fo.side_faces = sides != nullptr;
  if (sides) sides->assign(lights.size(), SideFaces());
  std::vector<FacePattern> out(lights.size());
  auto check = [](const ForwardResult& r) {
    for (const auto& sum : r.summaries)
      if (!sum.converged) throw InputError("forward solve did not converge: " + sum.BriefReport());
  };
  if (backend == Backend::kGl) {
    // Batches of kGlBatch lights per channel solve (one dispatch per step for all of them);
    // larger batches would add GPU memory (about 40 bytes per node and light) for little gain.
    const size_t kGlBatch = max_at_once > 0 ? std::min(16, max_at_once) : 16;
    for (size_t first = 0; first < lights.size(); first += kGlBatch) {
      const std::vector<FacePattern> some(lights.begin() + first,
                                          lights.begin() + std::min(lights.size(), first + kGlBatch));
      std::vector<ForwardResult> rs = SolveForwardBatch(material, some, fo);
      for (size_t l = 0; l < rs.size(); ++l) {
        check(rs[l]);
        out[first + l] = std::move(rs[l].radiance);
        if (sides) (*sides)[first + l] = std::move(rs[l].sides);
      }
    }
    return out;
  }
  // Conditions in parallel, one OpenMP thread each: independent solves scale better than
  // threads inside one solve, and small grids do not suffer from OpenMP barriers.
  std::atomic<size_t> next{0};
  std::vector<std::exception_ptr> errors(lights.size());
  auto worker = [&] {
    omp_set_num_threads(1);
    for (size_t l = next++; l < lights.size(); l = next++) {
      try {
        ForwardResult r = SolveForward(material, lights[l], fo);
        check(r);
        out[l] = std::move(r.radiance);
        if (sides) (*sides)[l] = std::move(r.sides);
      } catch (...) {
        errors[l] = std::current_exception();
      }
    }
  };
  const int workers = std::max(1, std::min({NumThreads(), int(lights.size()), max_at_once > 0 ? max_at_once : NumThreads()}));
  std::vector<std::thread> pool;
  for (int t = 1; t < workers; ++t) pool.emplace_back(worker);
  worker();
  for (auto& t : pool) t.join();
  for (auto& e : errors)
    if (e) std::rethrow_exception(e);
  return out;
}

std::vector<FacePattern> RenderMeasured(const Material& material, Setup setup,
                                        const std::vector<FacePattern>& lights,
                                        const MultigridOptions& multigrid, Backend backend,
                                        int max_at_once) {
  std::vector<FacePattern> out = RenderFrontFace(material, setup, lights, multigrid, backend, max_at_once);
  for (FacePattern& L : out)
    for (auto& channel : L) channel = MeasureFace(material.shape, channel);
  return out;
}

std::vector<float> MeasurementMask(const GridShape& s, Setup setup, const FacePattern& q,
                                   int margin) {
  std::vector<float> mask(s.face_size(), 1.0f);
  if (setup == Setup::kBack) return mask;
  for (int64_t j = 0; j < s.ny; ++j)
    for (int64_t i = 0; i < s.nx; ++i) {
      const int64_t p = i + s.nx * j;
      if (q[0][p] <= 0 && q[1][p] <= 0 && q[2][p] <= 0) continue;
      for (int64_t jj = std::max<int64_t>(0, j - margin); jj <= std::min(s.ny - 1, j + margin); ++jj)
        for (int64_t ii = std::max<int64_t>(0, i - margin); ii <= std::min(s.nx - 1, i + margin); ++ii)
          mask[ii + s.nx * jj] = 0.0f;
    }
  return mask;
}

std::string SimulateOptions::Validate() const {
  if (lights.empty() && holdout == 0 && validation == 0)
    return "at least one light (or held-out or validation condition) is needed";
  // Above a relative sigma of 1 the noise outweighs the signal (1e300 overflowed the data to inf).
  if (!(noise >= 0 && noise <= 1))
    return fmt::format("noise must be within 0..1 (a relative sigma: 0.01 = 1 %), got {}", noise);
  if (oversample < 1 || oversample > 8 || (oversample > 1 && oversample % 2))
    return fmt::format("oversample must be 1, 2, 4, 6 or 8 (a node's face box then ends on fine nodes), got {}",
                       oversample);
  if (holdout < 0 || holdout > kMaxHoldout)
    return fmt::format("holdout must be within 0..{}, got {}", kMaxHoldout, holdout);
  if (validation < 0 || validation > kMaxHoldout)
    return fmt::format("validation must be within 0..{}, got {}", kMaxHoldout, validation);
  if (!(tolerance > 0 && tolerance < 1)) return "tolerance must be in (0, 1)";
  if (mask_margin < 0) return "mask_margin must be >= 0";
  return "";
}

namespace {

// Simulates `lights` into a dataset with conditions named prefix + index.
Dataset Simulate(const Material& m, const Material& fine, const SimulateOptions& o,
                 const std::vector<LightSpec>& lights, const std::string& prefix,
                 std::mt19937_64* rng) {
  Dataset d;
  d.shape = m.shape;
  d.spacing_mm = m.spacing_mm;
  d.C = m.C;
  d.setup = o.setup;
  // Front-lit data leave out the lit region: lights that cover the whole face leave nothing.
  bool measured = false;
  for (const auto& l : lights) {
    const std::vector<float> mask =
        MeasurementMask(m.shape, o.setup, GreyPattern(RasterizeLight(l, m.shape, m.spacing_mm)), o.mask_margin);
    measured |= std::any_of(mask.begin(), mask.end(), [](float v) { return v > 0; });
  }
  if (!measured)
    throw InputError(fmt::format("simulate: front-lit, every {} light covers the whole face, and the lit region is "
                                 "left out of the data: nothing would be measured (use smaller regions, e.g. "
                                 "--lights 2x2)", prefix == "h" ? "held-out" : "training"));
  std::vector<FacePattern> fine_q;
  for (const auto& l : lights) fine_q.push_back(GreyPattern(RasterizeLight(l, fine.shape, fine.spacing_mm)));
  MultigridOptions mg;
  mg.tolerance = o.tolerance;
  mg.max_iterations = 200;
  const std::vector<FacePattern> fine_L = RenderFrontFace(fine, o.setup, fine_q, mg, o.backend);
  std::normal_distribution<double> gauss(0.0, 1.0);
  const int K = o.oversample;
  for (size_t l = 0; l < lights.size(); ++l) {
    DatasetCondition c;
    c.name = fmt::format("{}{:02d}", prefix, l);
    c.q = GreyPattern(RasterizeLight(lights[l], m.shape, m.spacing_mm));
    for (int ch = 0; ch < 3; ++ch) {
      c.L[ch] = BoxMeansOfFineFace(m.shape, K, fine_L[l][ch]);
      if (o.noise > 0)
        for (float& v : c.L[ch]) v = float(v * (1.0 + o.noise * gauss(*rng)));
    }
    c.mask = MeasurementMask(m.shape, o.setup, c.q, o.mask_margin);
    d.conditions.push_back(std::move(c));
  }
  return d;
}

}  // namespace

SimulatedData SimulateDataset(const Material& material, const SimulateOptions& o) {
  if (std::string err = o.Validate(); !err.empty()) throw InputError("simulate: " + err);
  if (std::string err = material.Validate(); !err.empty()) throw InputError("material: " + err);
  const Material fine = RefineMaterial(material, o.oversample);
  std::mt19937_64 rng(o.seed);
  SimulatedData out;
  if (!o.lights.empty()) out.training = Simulate(material, fine, o, o.lights, "c", &rng);
  const auto spots = [&](int count, const char* prefix, std::vector<LightSpec>* lights, Dataset* data) {
    if (count == 0) return;
    const double h = material.spacing_mm;
    const double w = (material.shape.nx - 1) * h, ht = (material.shape.ny - 1) * h;
    std::uniform_real_distribution<double> ux(0.0, w), uy(0.0, ht);
    for (int i = 0; i < count; ++i) {
      const double x = ux(rng), y = uy(rng);
      lights->push_back(LightSpec::Parse(fmt::format("spot:{:.4f},{:.4f},{:.4f}", x, y, 3 * h)));
    }
    *data = Simulate(material, fine, o, *lights, prefix, &rng);
  };
  spots(o.holdout, "h", &out.holdout_lights, &out.holdout);
  spots(o.validation, "v", &out.validation_lights, &out.validation);
  return out;
}

}  // namespace translume
