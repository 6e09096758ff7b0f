// SPDX-License-Identifier: MIT
#include "solver/evaluate.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "solver/simulate.h"
#include "solver/status.h"

namespace translume {
namespace {

std::vector<FacePattern> Lights(const Dataset& d) {
  std::vector<FacePattern> q;
  for (const auto& c : d.conditions) q.push_back(c.q);
  return q;
}

std::vector<FacePattern> Measured(const Dataset& d) {
  std::vector<FacePattern> L;
  for (const auto& c : d.conditions) L.push_back(c.L);
  return L;
}

std::vector<std::vector<float>> Masks(const Dataset& d) {
  std::vector<std::vector<float>> w;
  for (const auto& c : d.conditions) w.push_back(c.mask);
  return w;
}

// A material is rendered under a dataset's lights on the dataset's terms: the same grid,
// spacing and boundary parameter C (a material of another spacing or C would be compared with
// data it cannot reproduce, and its error would say nothing).
void CheckMatches(const Material& m, const Dataset& d, const char* what) {
  if (!(m.shape == d.shape))
    throw InputError(fmt::format("{}: material grid {} differs from the dataset grid {}", what,
                                 m.shape.ToString(), d.shape.ToString()));
  if (!NearlyEqual(m.spacing_mm, d.spacing_mm))
    throw InputError(fmt::format("{}: material spacing {:g} mm differs from the dataset's {:g} mm", what,
                                 m.spacing_mm, d.spacing_mm));
  if (!NearlyEqual(m.C, d.C))
    throw InputError(fmt::format("{}: material C = {:g} (eta {:g}) differs from the dataset's C = {:g}", what,
                                 m.C, m.eta, d.C));
}

}  // namespace

double RelightingError(const std::vector<FacePattern>& a, const std::vector<FacePattern>& b,
                       const std::vector<std::vector<float>>& masks) {
  TL_CHECK(a.size() == b.size());
  double num = 0, den = 0;
  for (size_t m = 0; m < a.size(); ++m)
    for (int c = 0; c < 3; ++c) {
      TL_CHECK(a[m][c].size() == b[m][c].size());
      for (size_t p = 0; p < a[m][c].size(); ++p) {
        const double w = masks.empty() ? 1.0 : masks[m][p];
        num += w * std::pow(double(a[m][c][p]) - double(b[m][c][p]), 2);
        den += w * std::pow(double(b[m][c][p]), 2);
      }
    }
  if (den > 0) return num / den;
  return num > 0 ? std::numeric_limits<double>::infinity() : 0.0;
}

void LayerErrors(const Material& rec, const Material& truth, std::vector<double>* kappa,
                 std::vector<double>* mu) {
  TL_CHECK(rec.shape == truth.shape);
  const GridShape& s = truth.shape;
  for (auto [out, r, t] : {std::tuple{kappa, &rec.kappa, &truth.kappa}, std::tuple{mu, &rec.mu, &truth.mu}}) {
    out->assign(s.nz, 0.0);
    for (int64_t k = 0; k < s.nz; ++k) {
      double num = 0, den = 0;
      for (int c = 0; c < 3; ++c)
        for (int64_t f = 0; f < s.face_size(); ++f) {
          const int64_t p = f + s.face_size() * k;
          num += std::pow(double((*r)[c][p]) - double((*t)[c][p]), 2);
          den += std::pow(double((*t)[c][p]), 2);
        }
      (*out)[k] = std::sqrt(num / den);
    }
  }
}

EvaluationReport EvaluateRecovery(const Material& rec, const Material* truth,
                                  const Dataset& training, const Dataset& holdout,
                                  const MultigridOptions& mg, Backend backend) {
  CheckMatches(rec, training, "recovered");
  if (!holdout.conditions.empty())
    if (std::string err = DifferentProblem(holdout, training, /*same_setup=*/false); !err.empty())
      throw InputError("holdout/: " + err);
  EvaluationReport r;
  const std::vector<FacePattern> rec_train =
      RenderMeasured(rec, training.setup, Lights(training), mg, backend);
  r.fit_error = RelightingError(rec_train, Measured(training), Masks(training));
  r.training_recovered = rec_train;
  const auto q = Lights(holdout);
  const auto w = Masks(holdout);
  if (!holdout.conditions.empty()) {
    r.holdout_recovered = RenderMeasured(rec, holdout.setup, q, mg, backend);
    r.holdout_data_error = RelightingError(r.holdout_recovered, Measured(holdout), w);
  }
  if (!truth) return r;
  CheckMatches(*truth, training, "--truth");
  LayerErrors(rec, *truth, &r.kappa_layer_error, &r.mu_layer_error);
  r.training_error = RelightingError(
      rec_train, RenderMeasured(*truth, training.setup, Lights(training), mg, backend),
      Masks(training));
  if (holdout.conditions.empty()) return r;
  const auto& a = r.holdout_recovered;
  r.holdout_truth = RenderMeasured(*truth, holdout.setup, q, mg, backend);
  const auto& b = r.holdout_truth;
  r.holdout_error = RelightingError(a, b, w);
  for (size_t m = 0; m < q.size(); ++m)
    r.holdout_condition_error.push_back(RelightingError({a[m]}, {b[m]}, {w[m]}));
  r.truth_holdout_error = RelightingError(b, Measured(holdout), w);
  return r;
}

std::string EvaluationTable(const EvaluationReport& r) {
  auto num = [](double v) { return v < 0 ? std::string("-") : fmt::format("{:.3e}", v); };
  std::string s;
  s += fmt::format("held-out relighting E   {}\n", num(r.holdout_error));
  s += fmt::format("training relighting E   {}\n", num(r.training_error));
  s += fmt::format("fit E (vs data)         {}\n", num(r.fit_error));
  s += fmt::format("truth's own held-out E  {}   (discretisation + noise floor)\n", num(r.truth_holdout_error));
  s += fmt::format("held-out E (vs data)    {}   (the recovery against the held-out data, as the truth's own)\n",
                   num(r.holdout_data_error));
  if (!r.kappa_layer_error.empty()) {
    s += "depth k   kappa rel. L2   mu rel. L2\n";
    for (size_t k = 0; k < r.kappa_layer_error.size(); ++k)
      s += fmt::format("{:7d}   {:13.3e}   {:10.3e}\n", k, r.kappa_layer_error[k], r.mu_layer_error[k]);
  }
  return s;
}

std::string EvaluationJson(const EvaluationReport& r) {
  nlohmann::json j;
  auto opt = [](double v) { return v < 0 ? nlohmann::json(nullptr) : nlohmann::json(v); };
  j["holdout_error"] = opt(r.holdout_error);
  j["holdout_condition_error"] = r.holdout_condition_error;
  j["training_error"] = opt(r.training_error);
  j["fit_error"] = opt(r.fit_error);
  j["truth_holdout_error"] = opt(r.truth_holdout_error);
  j["holdout_data_error"] = opt(r.holdout_data_error);
  j["kappa_layer_error"] = r.kappa_layer_error;
  j["mu_layer_error"] = r.mu_layer_error;
  return j.dump(2);
}

DatasetMismatch CompareDatasets(const Dataset& a, const Dataset& b) {
  if (a.shape.nx != b.shape.nx || a.shape.ny != b.shape.ny)
    throw InputError(fmt::format("datasets differ in grid: {} vs {}", a.shape.ToString(), b.shape.ToString()));
  if (a.setup != b.setup)
    throw InputError(fmt::format("datasets differ in setup: {}-lit vs {}-lit", SetupName(a.setup), SetupName(b.setup)));
  DatasetMismatch r;
  std::vector<FacePattern> La, Lb, qa, qb;
  std::vector<std::vector<float>> w;
  for (const DatasetCondition& cb : b.conditions) {
    const auto it = std::find_if(a.conditions.begin(), a.conditions.end(),
                                 [&](const DatasetCondition& c) { return c.name == cb.name; });
    if (it == a.conditions.end()) throw InputError("condition " + cb.name + " is missing from the measured dataset");
    std::vector<float> mask(size_t(b.shape.face_size()), 1.0f);
    for (size_t f = 0; f < mask.size(); ++f) {
      if (!it->mask.empty()) mask[f] *= it->mask[f];
      if (!cb.mask.empty()) mask[f] *= cb.mask[f];
    }
    r.condition_L_rms.push_back(std::sqrt(RelightingError({it->L}, {cb.L}, {mask})));
    r.condition_q_rms.push_back(std::sqrt(RelightingError({it->q}, {cb.q})));
    La.push_back(it->L);
    Lb.push_back(cb.L);
    qa.push_back(it->q);
    qb.push_back(cb.q);
    w.push_back(mask);
  }
  r.L_rms = std::sqrt(RelightingError(La, Lb, w));
  r.q_rms = std::sqrt(RelightingError(qa, qb));
  for (size_t c = 0; c < 3; ++c) {
    double ab = 0, bb = 0, aa = 0;
    for (size_t m = 0; m < La.size(); ++m)
      for (size_t f = 0; f < w[m].size(); ++f) {
        ab += w[m][f] * double(La[m][c][f]) * Lb[m][c][f];
        bb += w[m][f] * double(Lb[m][c][f]) * Lb[m][c][f];
        aa += w[m][f] * double(La[m][c][f]) * La[m][c][f];
      }
    r.L_scale[c] = bb > 0 ? ab / bb : 0;
    r.L_rms_after_scale[c] = bb > 0 ? std::sqrt(std::max(0.0, aa - ab * ab / bb) / bb) : 0;
  }
  return r;
}

}  // namespace translume
