// SPDX-License-Identifier: MIT
#include "solver/evaluate_previews.h"

#include <filesystem>

#include "solver/image_io.h"
#include "solver/status.h"

namespace translume {
namespace fs = std::filesystem;

std::vector<std::string> EvaluationPreviewPaths(const std::string& folder, const Dataset& training,
                                                const Dataset& holdout, bool with_holdout) {
  std::vector<std::string> paths;
  for (const auto& c : training.conditions) paths.push_back((fs::path(folder) / ("fit_" + c.name + ".png")).string());
  if (with_holdout)
    for (const auto& c : holdout.conditions)
      paths.push_back((fs::path(folder) / ("holdout_" + c.name + ".png")).string());
  return paths;
}

std::vector<std::string> WriteEvaluationPreviews(const std::string& folder, const EvaluationReport& r,
                                                 const Dataset& training, const Dataset& holdout) {
  TL_CHECK(r.training_recovered.size() == training.conditions.size());
  const bool with_holdout = !r.holdout_truth.empty();
  TL_CHECK(!with_holdout || (r.holdout_recovered.size() == holdout.conditions.size() &&
                             r.holdout_truth.size() == holdout.conditions.size()));
  const std::vector<std::string> paths = EvaluationPreviewPaths(folder, training, holdout, with_holdout);
  fs::create_directories(folder);
  size_t next = 0;
  for (size_t m = 0; m < training.conditions.size(); ++m) {
    const DatasetCondition& c = training.conditions[m];
    WriteFitComparison(paths[next++], training.shape, c.L, r.training_recovered[m], c.mask);
  }
  if (with_holdout)
    for (size_t m = 0; m < holdout.conditions.size(); ++m)
      WriteFitComparison(paths[next++], holdout.shape, r.holdout_truth[m], r.holdout_recovered[m],
                         holdout.conditions[m].mask);
  return paths;
}

}  // namespace translume
