// SPDX-License-Identifier: MIT
#include "solver/optimizer.h"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <future>
#include <stdexcept>
#include <thread>
#include <vector>

namespace translume {
namespace {

constexpr int64_t kN = 4;  // nodes: 2 kN unknowns per channel

// Channel c's objective: sum_i w_i (x_i - t_ci)^2 over its 2 kN unknowns, with weights 1..8
// (an anisotropic bowl, so that the optimisers need several iterations), minimum 0 at t_c.
double Target(int c, int i) { return 0.1 * (c + 1) * std::sin(1.0 + i + 3 * c); }
double Bowl(int c, const double* x, double* g) {
  double f = 0;
  for (int i = 0; i < 2 * kN; ++i) {
    const double w = 1 + i, d = x[i] - Target(c, i);
    f += w * d * d;
    if (g) g[i] = 2 * w * d;
  }
  return f;
}

ChannelObjectives Bowls(bool serve_here) {
  ChannelObjectives p;
  p.evaluate = Bowl;
  p.ok = [](int) { return true; };
  p.serve_here = serve_here;
  return p;
}

// Runs FitChannels on another thread and waits at most 60 s: a fit that hangs fails the test
// and ends the process (its threads cannot be stopped), instead of hanging the suite.
template <typename Fn>
void WithinAMinute(Fn&& fn) {
  auto done = std::async(std::launch::async, std::forward<Fn>(fn));
  if (done.wait_for(std::chrono::seconds(60)) != std::future_status::ready) {
    std::fprintf(stderr, "FitChannels did not return within 60 s\n");
    std::fflush(nullptr);
    std::_Exit(1);
  }
  done.get();
}

class FitChannelsTest : public testing::TestWithParam<bool> {};  // serve_here

TEST(RunOptimizer, EveryKindReachesTheMinimumOfABowl) {
  for (OptimizerKind kind : {OptimizerKind::kLbfgs, OptimizerKind::kNcg, OptimizerKind::kPaper}) {
    RecoveryOptions o;
    o.optimizer = kind;
    o.tolerance = 1e-12;
    std::vector<double> x(2 * kN, 0.0);
    const Objective f{[](const double* v, double* g) { return Bowl(0, v, g); }, [] { return true; }};
    int reports = 0;
    const OptimizerResult r = RunOptimizer(f, o, 200, x, [&](int, double, double) { return ++reports > 0; });
    SCOPED_TRACE(OptimizerName(kind));
    EXPECT_GT(r.iterations, 1);
    // (Ceres does not report the iteration in which it converges.)
    EXPECT_GE(r.iterations, reports);
    EXPECT_LE(r.iterations, reports + 1);
    EXPECT_GT(r.initial, 0.1);
    EXPECT_LT(r.final, 1e-8 * r.initial);
    for (int i = 0; i < 2 * kN; ++i) EXPECT_NEAR(x[i], Target(0, i), 1e-4) << i;
  }
}

TEST_P(FitChannelsTest, EachChannelReachesItsOwnMinimum) {
  RecoveryOptions o;
  o.tolerance = 1e-12;
  for (bool with_hook : {false, true}) {
    std::vector<double> x(6 * kN, 0.0);
    std::vector<double> objectives;
    IterationHook hook;
    if (with_hook)
      hook = [&](int it, double f, double) {
        EXPECT_EQ(it, int(objectives.size()) + 1);
        double sum = 0;  // the summed objective is that of the iterates in x at the report
        for (int c = 0; c < 3; ++c) sum += Bowl(c, x.data() + 2 * c * kN, nullptr) / 3;
        EXPECT_NEAR(f, sum, 1e-12 * std::max(1.0, sum));
        objectives.push_back(f);
        return true;
      };
    OptimizerResult r;
    WithinAMinute([&] { r = FitChannels(Bowls(GetParam()), o, kN, 200, {true, true, true}, x.data(), hook); });
    SCOPED_TRACE(with_hook ? "with a hook" : "without");
    EXPECT_NE(r.termination, RecoveryTermination::kFailed) << r.message;
    EXPECT_GT(r.iterations, 1);
    if (with_hook) {
      EXPECT_EQ(int(objectives.size()), r.iterations);
    }
    for (int c = 0; c < 3; ++c)
      for (int i = 0; i < 2 * kN; ++i) EXPECT_NEAR(x[2 * c * kN + i], Target(c, i), 1e-4) << c << " " << i;
  }
}

TEST_P(FitChannelsTest, LeavesAChannelNotFitAlone) {
  RecoveryOptions o;
  std::vector<double> x(6 * kN, 0.5);
  WithinAMinute([&] { FitChannels(Bowls(GetParam()), o, kN, 50, {true, false, true}, x.data(), {}); });
  for (int i = 0; i < 2 * kN; ++i) EXPECT_EQ(x[2 * kN + i], 0.5);
  EXPECT_NEAR(x[0], Target(0, 0), 1e-3);
}

// A channel whose evaluation throws stops the others and its error reaches the caller, also
// while the others wait to report an iteration ahead (with a hook): that once hung the fit.
TEST_P(FitChannelsTest, AChannelsErrorStopsTheFitAndIsRethrown) {
  RecoveryOptions o;
  o.tolerance = 1e-14;
  for (bool with_hook : {false, true}) {
    for (int throw_at : {1, 2, 5, 9}) {
      SCOPED_TRACE(testing::Message() << (with_hook ? "with a hook" : "without") << ", throwing at evaluation "
                                      << throw_at);
      ChannelObjectives p = Bowls(GetParam());
      std::atomic<int> evaluations{0};
      p.evaluate = [&](int c, const double* v, double* g) {
        if (c == 1 && ++evaluations == throw_at) throw std::runtime_error("channel 1 failed");
        return Bowl(c, v, g);
      };
      std::vector<double> x(6 * kN, 0.0);
      const IterationHook hook = [](int, double, double) { return true; };
      WithinAMinute([&] {
        try {
          FitChannels(p, o, kN, 200, {true, true, true}, x.data(), with_hook ? hook : IterationHook());
          ADD_FAILURE() << "no exception";
        } catch (const std::runtime_error& e) {
          EXPECT_STREQ(e.what(), "channel 1 failed");
        }
      });
    }
  }
}

// Without a hook too, a channel's error stops the others: here channel 1 fails at its first
// evaluation and the others, held until 50 ms after that failure and each evaluation 2 ms
// long, stop after their first iteration instead of running their ~30 evaluations each.
TEST(FitChannels, AChannelsErrorStopsTheOthersWithoutAHook) {
  RecoveryOptions o;
  o.tolerance = 1e-14;
  ChannelObjectives p = Bowls(false);
  std::atomic<bool> failed{false};
  std::atomic<int> others{0};
  p.evaluate = [&](int c, const double* v, double* g) {
    if (c == 1) {
      failed = true;
      throw std::runtime_error("channel 1 failed");
    }
    while (!failed) std::this_thread::yield();
    if (++others <= 2) std::this_thread::sleep_for(std::chrono::milliseconds(50));  // (the first two)
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
    return Bowl(c, v, g);
  };
  std::vector<double> x(6 * kN, 0.0);
  WithinAMinute([&] { EXPECT_THROW(FitChannels(p, o, kN, 200, {true, true, true}, x.data(), {}), std::runtime_error); });
  // Unstopped, the two would take 2 x ~30 evaluations (the test below counts them).
  EXPECT_LE(others.load(), 10);
}

TEST(FitChannels, UnstoppedBowlsTakeTensOfEvaluations) {
  RecoveryOptions o;
  o.tolerance = 1e-14;
  ChannelObjectives p = Bowls(false);
  std::atomic<int> evaluations{0};
  p.evaluate = [&](int c, const double* v, double* g) {
    if (c == 0) ++evaluations;
    return Bowl(c, v, g);
  };
  std::vector<double> x(6 * kN, 0.0);
  WithinAMinute([&] { FitChannels(p, o, kN, 200, {true, true, true}, x.data(), {}); });
  EXPECT_GE(evaluations.load(), 20);
}

TEST_P(FitChannelsTest, TheHooksErrorIsRethrownAndAFalseStops) {
  RecoveryOptions o;
  o.tolerance = 1e-14;
  std::vector<double> x(6 * kN, 0.0);
  WithinAMinute([&] {
    EXPECT_THROW(FitChannels(Bowls(GetParam()), o, kN, 200, {true, true, true}, x.data(),
                             [](int it, double, double) -> bool {
                               if (it == 3) throw std::logic_error("hook failed");
                               return true;
                             }),
                 std::logic_error);
  });
  int last = 0;
  OptimizerResult r;
  WithinAMinute([&] {
    r = FitChannels(Bowls(GetParam()), o, kN, 200, {true, true, true}, x.data(), [&](int it, double, double) {
      last = it;
      return it < 2;
    });
  });
  EXPECT_EQ(last, 2);
  EXPECT_EQ(r.termination, RecoveryTermination::kStopped);
  EXPECT_EQ(r.iterations, 2);
}

INSTANTIATE_TEST_SUITE_P(Serving, FitChannelsTest, testing::Bool(),
                         [](const testing::TestParamInfo<bool>& i) { return i.param ? "OnTheCaller" : "OnEachThread"; });

}  // namespace
}  // namespace translume
