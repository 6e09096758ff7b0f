// SPDX-License-Identifier: MIT
// Shared by the end-to-end tests: runs the `translume` binary (TRANSLUME_BINARY) as a user would,
// each test in a fresh temporary folder.
#pragma once

#include <gtest/gtest.h>
#include <sys/wait.h>

#include <algorithm>
#include <array>
#include <cstdio>
#include <filesystem>
#include <string>

namespace translume::testing_cli {

struct CommandRun {
  int status = -1;
  std::string output;  // stdout and stderr
};

// `env` is prepended to the command line (e.g. "TRANSLUME_GL=osmesa").
inline CommandRun Translume(const std::string& args, const std::string& env = "") {
  CommandRun r;
  const std::string cmd = env + " " + std::string(TRANSLUME_BINARY) + " " + args + " 2>&1";
  FILE* pipe = popen(cmd.c_str(), "r");
  if (!pipe) return r;
  std::array<char, 4096> buf;
  size_t n;
  while ((n = fread(buf.data(), 1, buf.size(), pipe)) > 0) r.output.append(buf.data(), n);
  const int st = pclose(pipe);
  r.status = WIFEXITED(st) ? WEXITSTATUS(st) : -1;
  return r;
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
