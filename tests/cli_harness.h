// SPDX-License-Identifier: MIT
// Shared by the end-to-end tests: runs the `translume` binary (TRANSLUME_BINARY; the GPU
// benchmark's tests point it at translume-gpubench) as a user would, each test in a fresh
// temporary folder.
#pragma once

#include <gtest/gtest.h>
#include <sys/wait.h>

#include <algorithm>
#include <array>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

namespace translume::testing_cli {

struct CommandRun {
  int status = -1;
  std::string output;  // stdout and stderr
};

// Runs a shell command line, collecting stdout and stderr.
inline CommandRun Run(const std::string& command_line) {
  CommandRun r;
  const std::string cmd = command_line + " 2>&1";
  FILE* pipe = popen(cmd.c_str(), "r");
  if (!pipe) return r;
  std::array<char, 4096> buf;
  size_t n;
  while ((n = fread(buf.data(), 1, buf.size(), pipe)) > 0) r.output.append(buf.data(), n);
  const int st = pclose(pipe);
  r.status = WIFEXITED(st) ? WEXITSTATUS(st) : -1;
  return r;
}

// `env` is prepended to the command line (e.g. "TRANSLUME_GL=osmesa").
inline CommandRun Translume(const std::string& args, const std::string& env = "") {
  return Run(env + " " + std::string(TRANSLUME_BINARY) + " " + args);
}

// Runs `translume ARGS` that prints a JSON object after its progress lines (--json); fails the
// test and returns null when it exits non-zero or prints no object.
inline nlohmann::json TranslumeJson(const std::string& args) {
  const CommandRun r = Translume(args);
  EXPECT_EQ(r.status, 0) << r.output;
  const size_t brace = r.output.find('{');
  EXPECT_NE(brace, std::string::npos) << r.output;
  if (r.status != 0 || brace == std::string::npos) return nullptr;
  return nlohmann::json::parse(r.output.substr(brace));
}

// The cases of `bench recovery ARGS --no-comparison --json`: an empty array (and a failed test)
// when the command fails or prints an optimiser comparison anyway.
inline nlohmann::json RecoveryBenchCases(const std::string& args) {
  const nlohmann::json j = TranslumeJson("bench recovery " + args + " --no-comparison --json");
  if (!j.is_object() || !j.contains("cases")) return nlohmann::json::array();
  EXPECT_FALSE(j.contains("optimizer_comparison")) << j.dump();
  return j["cases"];
}

// A fresh folder per test, removed afterwards; P(name) is a path inside it.
class CliTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = std::filesystem::temp_directory_path() /
           (std::string("translume_") + info->test_suite_name() + "_" + info->name());
    std::filesystem::remove_all(dir_);
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::string P(const std::string& name) const { return (dir_ / name).string(); }
  // A failed command: exit 1 or 2, exactly one line of output naming `what`.
  void ExpectOneLineError(const CommandRun& r, const std::string& what) {
    EXPECT_TRUE(r.status == 1 || r.status == 2) << r.output;
    EXPECT_NE(r.output.find(what), std::string::npos) << r.output;
    EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n'), 1) << r.output;
  }
  std::filesystem::path dir_;
};

}  // namespace translume::testing_cli
