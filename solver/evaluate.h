// SPDX-License-Identifier: MIT
#pragma once

#include <array>
#include <string>
#include <vector>

#include "solver/dataset.h"
#include "solver/material.h"
#include "solver/multigrid.h"

namespace translume {

// Relighting error of SPEC section 5 over conditions m, channels and front-face nodes p:
//   E = sum w_mp (a_mp - b_mp)^2 / sum w_mp b_mp^2
// (b: the reference; w: masks, one per condition, nx*ny values; empty masks mean all 1).
// A reference without light (sum w b^2 = 0) gives 0 if a is dark there too, else infinity.
double RelightingError(const std::vector<FacePattern>& a, const std::vector<FacePattern>& b,
                       const std::vector<std::vector<float>>& masks = {});

// Relative L2 error per depth layer k (RGB together):
//   e_k = sqrt(sum_{i,j,c} (v_rec - v_true)^2 / sum_{i,j,c} v_true^2), for v = kappa and mu.
void LayerErrors(const Material& recovered, const Material& truth, std::vector<double>* kappa,
                 std::vector<double>* mu);

struct EvaluationReport {
  // Recovered vs true material, both rendered on the recovery grid, under the held-out
  // conditions (holdout_error) and the training conditions (training_error).
  double holdout_error = -1, training_error = -1;
  std::vector<double> holdout_condition_error;
  // Recovered material vs the dataset's measured L (what the fit minimised).
  double fit_error = -1;
  // The truth rendered on the recovery grid vs the held-out data (the discretisation floor
  // when the data was oversampled; noise adds to it).
  double truth_holdout_error = -1;
  // The recovery rendered vs the held-out data (no truth needed): what the truth's own error is
  // to the truth. Where that floor exceeds holdout_error (front-lit captures on coarse grids),
  // this one, not holdout_error, tells which of two recoveries predicts the data better.
  double holdout_data_error = -1;
  std::vector<double> kappa_layer_error, mu_layer_error;
  // The front-face radiance (nx*ny per channel) behind those errors, one per condition in the
  // datasets' order: the recovered material under the training lights and, with a holdout/,
  // the held-out lights; with a truth and a holdout/ the true material under the held-out lights.
  std::vector<FacePattern> training_recovered, holdout_recovered, holdout_truth;
};

// Evaluates a recovery. `holdout` may have no conditions (its errors stay -1); `truth` may be
// null (only the fit error and, with a holdout, holdout_data_error are computed). `backend`: where the forward solves run. Throws
// InputError on a grid mismatch.
EvaluationReport EvaluateRecovery(const Material& recovered, const Material* truth,
                                  const Dataset& training, const Dataset& holdout,
                                  const MultigridOptions& multigrid,
                                  Backend backend = Backend::kCpu);

std::string EvaluationTable(const EvaluationReport& report);
std::string EvaluationJson(const EvaluationReport& report);

// How far a dataset built from photos is from a reference one (e.g. the simulator's own
// node-space data): relative RMS errors sqrt(sum w (a - b)^2 / sum w b^2) of L (w: the product
// of both masks) and of q (w = 1), over the conditions of `reference`, matched by name. Throws
// InputError naming the missing condition or a grid mismatch.
struct DatasetMismatch {
  double L_rms = 0, q_rms = 0;
  std::vector<double> condition_L_rms, condition_q_rms;
  // Per channel, the least-squares scale of measured L against the reference (1: no gain
  // error; a white-balance or exposure error shows here) and the relative RMS left after it.
  std::array<double, 3> L_scale{}, L_rms_after_scale{};
};
DatasetMismatch CompareDatasets(const Dataset& measured, const Dataset& reference);

}  // namespace translume
