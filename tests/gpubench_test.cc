// SPDX-License-Identifier: MIT
// Runs translume-gpubench, the self-contained GPU benchmark (tools/gpu_bundle.sh), as the GPU
// session does (tools/gpu_session.sh): bench recovery in memory on the gl backend with the cpu
// as its peer, and no file IO library linked.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>
#include <string>

#include "tests/cli_harness.h"

namespace translume {
namespace {

using testing_cli::CommandRun;
using testing_cli::Translume;

class GpuBench : public testing_cli::CliTest {};

TEST_F(GpuBench, LinksNoFileIoLibrary) {
  const CommandRun r = testing_cli::Run("ldd " + std::string(TRANSLUME_BINARY));
  ASSERT_EQ(r.status, 0) << r.output;
  for (const char* lib : {"openvdb", "OpenImageIO", "opencv"})
    EXPECT_EQ(r.output.find(lib), std::string::npos) << lib << " is linked:\n" << r.output;
}

TEST_F(GpuBench, RecoveryOneCaseOnGlWithTheCpuAsPeer) {
  const auto cases = testing_cli::RecoveryBenchCases(
      "--grid 8x6x4 --presets wax --setups back --noises 0 --backend gl,cpu --data-backend gl "
      "--max-iterations 3");
  ASSERT_EQ(cases.size(), 2u);
  EXPECT_EQ(cases[0]["backend"], "gl");
  EXPECT_EQ(cases[1]["backend"], "cpu");
  for (const auto& c : cases) {
    EXPECT_EQ(c["grid"], "8x6x4");
    EXPECT_LE(c["iterations"].get<int>(), 3);
    EXPECT_GT(c["seconds_per_iteration"].get<double>(), 0);
    EXPECT_GT(c["holdout_error"].get<double>(), 0);
    EXPECT_LT(c["holdout_error"].get<double>(), 0.1);
  }
}

TEST_F(GpuBench, UsageAndGlInfo) {
  EXPECT_EQ(Translume("bench recovery --help").status, 0);
  EXPECT_EQ(Translume("bench forward --help").status, 0);
  EXPECT_EQ(Translume("frobnicate").status, 2);
  const CommandRun r = Translume("gl-info");
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("GL_RENDERER"), std::string::npos) << r.output;
}

}  // namespace
}  // namespace translume
