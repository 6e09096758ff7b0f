// SPDX-License-Identifier: MIT
// The images of an evaluation (file IO: apart from evaluate.h, whose library the GPU bundle
// links without OpenImageIO).
#pragma once

#include <string>
#include <vector>

#include "solver/dataset.h"
#include "solver/evaluate.h"

namespace translume {

// WriteFitComparison previews of an evaluation into `folder` (created; its files written under
// temporary names and renamed): fit_NAME.png per training condition (measured | recovered |
// residual, the condition's mask) and, where the report has them, holdout_NAME.png per
// held-out condition (the truth relit | the recovery relit | residual). Returns the paths.
std::vector<std::string> WriteEvaluationPreviews(const std::string& folder, const EvaluationReport& report,
                                                 const Dataset& training, const Dataset& holdout);
// The paths WriteEvaluationPreviews writes for these datasets (those of holdout only if
// `with_holdout`).
std::vector<std::string> EvaluationPreviewPaths(const std::string& folder, const Dataset& training,
                                                const Dataset& holdout, bool with_holdout);

}  // namespace translume
