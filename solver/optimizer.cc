// SPDX-License-Identifier: MIT
#include "solver/optimizer.h"

#include <ceres/gradient_problem.h>
#include <ceres/gradient_problem_solver.h>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <condition_variable>
#include <exception>
#include <fmt/format.h>
#include <limits>
#include <mutex>
#include <thread>
#include <vector>

#include "solver/status.h"

namespace translume {
namespace {

// The message of a run that the hook stopped (RunCeres, FitChannels).
constexpr const char* kStoppedMessage = "stopped by the caller (e.g. Ctrl-C) after this iteration";

double Norm(const std::vector<double>& v) {
  double s = 0;
  for (double a : v) s += a * a;
  return std::sqrt(s);
}

// One evaluation of f with its gradient, kept for the optimiser's first call at the same x.
struct Evaluation {
  std::vector<double> x, gradient;
  double value = 0;
  bool ok = false;
};

// An Objective on n unknowns for Ceres, times `scale` (f and its gradient; RunOptimizer).
// Ceres starts by evaluating the starting point, which FirstStepScale has just evaluated:
// `first` (optional) answers that call, once, if Ceres asks for exactly first.x; the problem's
// warm-start fields are already those of that point.
class CeresFunction : public ceres::FirstOrderFunction {
 public:
  CeresFunction(const Objective& f, int n, double scale, Evaluation first = {})
      : f_(f), n_(n), scale_(scale), first_(std::move(first)) {}
  bool Evaluate(const double* x, double* cost, double* grad) const override {
    bool ok;
    if (!first_.x.empty() && std::equal(x, x + n_, first_.x.begin())) {
      *cost = first_.value;
      if (grad) std::copy(first_.gradient.begin(), first_.gradient.end(), grad);
      ok = first_.ok;
      first_ = {};
    } else {
      *cost = f_.evaluate(x, grad);
      ok = f_.ok();
    }
    *cost *= scale_;
    if (grad && scale_ != 1)
      for (int i = 0; i < n_; ++i) grad[i] *= scale_;
    return std::isfinite(*cost) && ok;
  }
  int NumParameters() const override { return n_; }

 private:
  const Objective& f_;
  int n_;
  double scale_;
  mutable Evaluation first_;
};

class CeresHook : public ceres::IterationCallback {
 public:
  explicit CeresHook(const IterationHook& hook) : hook_(hook) {}
  ceres::CallbackReturnType operator()(const ceres::IterationSummary& s) override {
    if (s.iteration == 0) return ceres::SOLVER_CONTINUE;
    if (hook_ && !hook_(s.iteration, s.cost, s.gradient_norm)) {
      stopped = true;
      return ceres::SOLVER_TERMINATE_SUCCESSFULLY;
    }
    return ceres::SOLVER_CONTINUE;
  }
  bool stopped = false;

 private:
  const IterationHook& hook_;
};

// Ceres' line-search minimiser on `function` (owned by the call) from *x.
OptimizerResult RunCeres(ceres::FirstOrderFunction* function, OptimizerKind kind, int max_iterations,
                         int lbfgs_rank, double tolerance, double* x, const IterationHook& hook) {
  ceres::GradientProblem gp(function);
  ceres::GradientProblemSolver::Options so;
  so.line_search_direction_type =
      kind == OptimizerKind::kNcg ? ceres::NONLINEAR_CONJUGATE_GRADIENT : ceres::LBFGS;
  so.nonlinear_conjugate_gradient_type = ceres::POLAK_RIBIERE;
  so.line_search_type = ceres::WOLFE;
  so.max_num_iterations = max_iterations;
  so.max_lbfgs_rank = lbfgs_rank;
  so.function_tolerance = tolerance;
  so.gradient_tolerance = 1e-16;
  so.parameter_tolerance = 1e-14;
  so.max_num_line_search_step_size_iterations = 30;
  // Scale the initial inverse Hessian by the latest curvature (Nocedal & Wright 6.20): without
  // it every step starts from the raw gradient, which is orders of magnitude too short here.
  so.use_approximate_eigenvalue_bfgs_scaling = true;
  so.logging_type = ceres::SILENT;
  so.minimizer_progress_to_stdout = false;
  so.update_state_every_iteration = true;
  CeresHook cb(hook);
  so.callbacks.push_back(&cb);
  ceres::GradientProblemSolver::Summary sum;
  ceres::Solve(so, gp, x, &sum);
  OptimizerResult r;
  r.iterations = int(sum.iterations.size()) - 1;
  r.initial = sum.initial_cost;
  r.final = sum.final_cost;
  r.message = cb.stopped ? kStoppedMessage : sum.message;
  if (cb.stopped) r.termination = RecoveryTermination::kStopped;
  else if (sum.termination_type == ceres::CONVERGENCE) r.termination = RecoveryTermination::kConverged;
  else if (sum.termination_type == ceres::NO_CONVERGENCE) r.termination = RecoveryTermination::kMaxIterations;
  else r.termination = RecoveryTermination::kFailed;
  return r;
}

// Polak-Ribiere conjugate gradients with a golden-section line search (Wang et al. 2008,
// Table I): bracket the minimum along the direction by golden-ratio expansion or contraction,
// then shrink the bracket by golden sections; only the accepted point gets a gradient (adjoint
// solves); line-search points cost forward solves only.
OptimizerResult RunPaper(const Objective& problem, int max_iterations, double tolerance, std::span<double> x,
                         const IterationHook& hook) {
  constexpr double kGold = 1.618033988749895, kInvGold = 0.618033988749895;
  constexpr int kSectionSteps = 8;
  const size_t n = x.size();
  std::vector<double> g(n), g_new(n), d(n), trial(n);
  OptimizerResult r;
  double f = problem.evaluate(x.data(), g.data());
  r.initial = f;
  for (size_t i = 0; i < n; ++i) d[i] = -g[i];
  double dmax = 0;
  for (double v : d) dmax = std::max(dmax, std::abs(v));
  double step = dmax > 0 ? 0.1 / dmax : 1.0;  // first trial: change a log-parameter by 0.1
  auto at = [&](double a) {
    for (size_t i = 0; i < n; ++i) trial[i] = x[i] + a * d[i];
    const double v = problem.evaluate(trial.data(), nullptr);
    return std::isfinite(v) && problem.ok() ? v : std::numeric_limits<double>::infinity();
  };
  r.termination = RecoveryTermination::kMaxIterations;
  r.message = fmt::format("reached max_iterations = {}", max_iterations);
  for (int it = 1; it <= max_iterations; ++it) {
    // Bracket a < b < c with f(b) < f(a), f(b) <= f(c).
    double a = 0, fa = f, b = step, fb = at(b), c, fc;
    if (fb < fa) {
      c = b + kGold * (b - a);
      fc = at(c);
      for (int e = 0; e < 30 && fc < fb; ++e) {
        a = b; fa = fb; b = c; fb = fc;
        c = b + kGold * (b - a);
        fc = at(c);
      }
    } else {
      c = b; fc = fb;
      b = c * kInvGold * kInvGold;
      fb = at(b);
      for (int e = 0; e < 40 && fb >= fa; ++e) {
        c = b; fc = fb;
        b = c * kInvGold * kInvGold;
        fb = at(b);
      }
      if (fb >= fa) {
        r.termination = RecoveryTermination::kConverged;
        r.message = "line search found no decrease along the search direction";
        break;
      }
    }
    // Golden sections: probe the larger side of b.
    for (int s = 0; s < kSectionSteps; ++s) {
      if (c - b > b - a) {
        const double t = b + (1 - kInvGold) * (c - b), ft = at(t);
        if (ft < fb) { a = b; fa = fb; b = t; fb = ft; } else { c = t; fc = ft; }
      } else {
        const double t = b - (1 - kInvGold) * (b - a), ft = at(t);
        if (ft < fb) { c = b; fc = fb; b = t; fb = ft; } else { a = t; fa = ft; }
      }
    }
    for (size_t i = 0; i < n; ++i) x[i] += b * d[i];
    const double f_new = problem.evaluate(x.data(), g_new.data());
    double num = 0, den = 0;
    for (size_t i = 0; i < n; ++i) {
      num += g_new[i] * (g_new[i] - g[i]);
      den += g[i] * g[i];
    }
    const double beta = den > 0 ? std::max(0.0, num / den) : 0.0;
    double slope = 0;
    for (size_t i = 0; i < n; ++i) {
      d[i] = -g_new[i] + beta * d[i];
      slope += d[i] * g_new[i];
    }
    if (slope >= 0)
      for (size_t i = 0; i < n; ++i) d[i] = -g_new[i];
    const double decrease = f - f_new;
    g.swap(g_new);
    f = f_new;
    step = b;
    r.iterations = it;
    r.final = f;
    if (hook && !hook(it, f, Norm(g))) {
      r.termination = RecoveryTermination::kStopped;
      r.message = "stopped by the caller";
      break;
    }
    if (decrease <= tolerance * std::abs(f)) {
      r.termination = RecoveryTermination::kConverged;
      r.message = fmt::format("objective decrease {:.3e} <= tolerance * objective", decrease);
      break;
    }
  }
  r.final = f;
  return r;
}

// The factor on f that makes Ceres' first step from x (the gradient itself) change the largest
// log-parameter by 0.1; 1 where it already does more. One evaluation with gradient, returned in
// *at_x for the optimiser's first call.
double FirstStepScale(const Objective& f, std::span<const double> x, Evaluation* at_x) {
  constexpr double kFirstChange = 0.1;
  at_x->x.assign(x.begin(), x.end());
  at_x->gradient.assign(x.size(), 0.0);
  at_x->value = f.evaluate(x.data(), at_x->gradient.data());
  at_x->ok = f.ok();
  double gmax = 0;
  for (double v : at_x->gradient) gmax = std::max(gmax, std::abs(v));
  return gmax > 0 && gmax < kFirstChange ? kFirstChange / gmax : 1.0;
}

}  // namespace

OptimizerResult RunOptimizer(const Objective& f, const RecoveryOptions& o, int max_iterations,
                             std::span<double> x, const IterationHook& hook) {
  if (o.optimizer == OptimizerKind::kPaper) return RunPaper(f, max_iterations, o.tolerance, x, hook);
  Evaluation start;
  const double scale = FirstStepScale(f, x, &start);
  const IterationHook unscaled = [&](int it, double v, double gnorm) {
    return hook ? hook(it, v / scale, gnorm / scale) : true;
  };
  OptimizerResult r = RunCeres(new CeresFunction(f, int(x.size()), scale, std::move(start)), o.optimizer,
                               max_iterations, o.lbfgs_rank, o.tolerance, x.data(), unscaled);
  r.initial /= scale;
  r.final /= scale;
  return r;
}

OptimizerResult FitChannels(const ChannelObjectives& problem, const RecoveryOptions& o, int64_t n,
                            int max_iterations, const std::array<bool, 3>& fit, double* x,
                            const IterationHook& hook) {
  const bool serve_here = problem.serve_here;
  struct Channel {
    bool running = false;
    int reported = 0;  // the last iteration whose iterate is in x
    double f = 0, gnorm = 0;
    // serve_here: an evaluation it asks for (at point, gradient into g, may be null), its answer.
    bool requested = false;
    const double* point = nullptr;
    double* g = nullptr;
    double value = 0;
    std::exception_ptr evaluation_error, error;
    std::vector<double> own;  // its optimiser's copy of its block
    OptimizerResult result;
  };
  std::array<Channel, 3> ch;
  std::mutex m;
  std::condition_variable cv;
  int released = 0;  // the last iteration whose hook has run
  bool go_on = true, stopped = false;
  std::exception_ptr hook_error;
  const auto evaluate = [&](int c, const double* v, double* g) {
    if (!serve_here) return problem.evaluate(c, v, g) / 3.0;
    std::unique_lock<std::mutex> lock(m);
    ch[c].point = v;
    ch[c].g = g;
    ch[c].requested = true;
    cv.notify_all();
    cv.wait(lock, [&] { return !ch[c].requested; });
    if (ch[c].evaluation_error) std::rethrow_exception(std::exchange(ch[c].evaluation_error, nullptr));
    return ch[c].value;
  };
  const auto run = [&](int c) {
    try {
      omp_set_num_threads(problem.threads_per_channel);
      double* block = x + 2 * c * n;
      std::vector<double>& own = ch[c].own;
      own.assign(block, block + 2 * n);
      const Objective objective{[&, c](const double* v, double* g) { return evaluate(c, v, g); },
                                [&, c] { return problem.ok(c); }};
      const IterationHook step = [&, c](int it, double f, double gnorm) {
        if (!hook) {  // (go_on: false once a channel has failed)
          std::lock_guard<std::mutex> lock(m);
          return go_on && !o.StopRequested();
        }
        std::unique_lock<std::mutex> lock(m);
        cv.wait(lock, [&] { return released >= it - 1 || !go_on; });
        if (!go_on) return false;
        lock.unlock();
        std::copy(own.begin(), own.end(), block);
        lock.lock();
        ch[c].f = f;
        ch[c].gnorm = gnorm;
        ch[c].reported = it;
        cv.notify_all();
        return true;
      };
      ch[c].result = RunOptimizer(objective, o, max_iterations, own, step);
    } catch (...) {
      ch[c].error = std::current_exception();
    }
    std::lock_guard<std::mutex> lock(m);
    ch[c].running = false;
    // Without reports (no hook, or none made): x's block is the start's with a hook (f the
    // start's), the run's end without.
    if (ch[c].reported == 0) ch[c].f = hook ? ch[c].result.initial : ch[c].result.final;
    if (ch[c].error) go_on = false;
    cv.notify_all();
  };
  std::vector<std::thread> threads;
  threads.reserve(3);  // (a reallocation's failure would destroy a running thread: std::terminate)
  std::exception_ptr start_error;
  for (int c = 0; c < 3 && !start_error; ++c)
    if (fit[c]) {
      std::lock_guard<std::mutex> lock(m);
      try {
        threads.emplace_back(run, c);
        ch[c].running = true;
      } catch (...) {  // no thread (std::system_error): the started ones stop at their first report
        start_error = std::current_exception();
        go_on = false;
      }
    }
  {
    std::unique_lock<std::mutex> lock(m);
    // The next iteration's hook may run: some channel has reported it, and every one running has.
    const auto hook_due = [&] {
      bool any = false;
      for (const Channel& c : ch) {
        if (c.running && c.reported < released + 1) return false;
        any = any || c.reported >= released + 1;
      }
      return any && go_on;
    };
    int served = 2;
    while (true) {
      int asking = -1;
      bool any_running = false;
      cv.wait(lock, [&] {
        asking = -1;
        any_running = false;
        for (int k = 1; k <= 3; ++k) {  // in turn, from the channel after the last one served
          const int c = (served + k) % 3;
          if (ch[c].requested && asking < 0) asking = c;
          any_running = any_running || ch[c].running;
        }
        return asking >= 0 || !any_running || hook_due();
      });
      if (asking >= 0) {
        Channel& a = ch[asking];
        lock.unlock();
        try {
          a.value = problem.evaluate(asking, a.point, a.g) / 3.0;
        } catch (...) {
          a.evaluation_error = std::current_exception();
        }
        lock.lock();
        a.requested = false;
        served = asking;
        cv.notify_all();
        continue;
      }
      if (!hook_due()) break;  // none running, and every reported iteration's hook has run
      const int it = released + 1;
      double f = 0, g2 = 0;
      for (const Channel& c : ch) {
        f += c.f;
        g2 += c.gnorm * c.gnorm;
      }
      lock.unlock();
      bool keep = false;
      try {
        keep = hook(it, f, std::sqrt(g2));
      } catch (...) {
        hook_error = std::current_exception();
      }
      lock.lock();
      if (!keep) stopped = true;
      go_on = go_on && keep;
      released = it;
      cv.notify_all();
    }
  }
  for (std::thread& t : threads) t.join();
  if (start_error) std::rethrow_exception(start_error);
  if (hook_error) std::rethrow_exception(hook_error);
  for (const Channel& c : ch)
    if (c.error) std::rethrow_exception(c.error);
  if (!hook)
    for (int c = 0; c < 3; ++c)
      if (fit[c]) std::copy(ch[c].own.begin(), ch[c].own.end(), x + 2 * c * n);

  OptimizerResult r;
  static constexpr const char* kName[3] = {"R", "G", "B"};
  bool failed = false, unfinished = false, same = true;
  std::string first_message, messages;
  for (int c = 0; c < 3; ++c) {
    if (!fit[c]) continue;
    const OptimizerResult& cr = ch[c].result;
    r.initial += cr.initial;
    r.final += ch[c].f;  // that of the iterate left in x
    r.iterations = std::max(r.iterations, hook ? ch[c].reported : cr.iterations);
    stopped = stopped || cr.termination == RecoveryTermination::kStopped;
    failed = failed || cr.termination == RecoveryTermination::kFailed;
    unfinished = unfinished || cr.termination == RecoveryTermination::kMaxIterations;
    std::string message = cr.message;
    while (!message.empty() && message.back() == '.') message.pop_back();  // Ceres' end in one
    if (first_message.empty()) first_message = message;
    same = same && message == first_message;
    messages += fmt::format("{}{}: {}", messages.empty() ? "" : "; ", kName[c], message);
  }
  r.termination = stopped ? RecoveryTermination::kStopped
                  : failed ? RecoveryTermination::kFailed
                  : unfinished ? RecoveryTermination::kMaxIterations
                               : RecoveryTermination::kConverged;
  r.message = stopped ? kStoppedMessage : same ? first_message : messages;
  return r;
}

}  // namespace translume
