// SPDX-License-Identifier: MIT
#include "solver/recover.h"

#include <omp.h>

#include <algorithm>
#include <chrono>
#include <climits>
#include <cmath>
#include <exception>
#include <fmt/format.h>
#include <fstream>
#include <limits>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <span>
#include <thread>

#include "solver/atomic_file.h"
#include "solver/evaluate.h"
#include "solver/memory.h"
#include "solver/optimizer.h"
#include "solver/simulate.h"
#include "solver/status.h"
#include "solver/threads.h"

namespace translume {
namespace {

using Clock = std::chrono::steady_clock;

double Since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

// The objective over all channels on the log-parameters (layout in recover.h), and the
// homogeneous fit that starts it.
class RecoveryProblem {
 public:
  RecoveryProblem(const Dataset& d, const RecoveryOptions& o) : d_(d), o_(o), n_(d.shape.size()) {
    MultigridOptions mg;
    mg.tolerance = o.solve_tolerance;
    mg.max_iterations = 500;
    for (int c = 0; c < 3; ++c) {
      channels_[c] = o.backend == Backend::kGl ? MakeGlChannelObjective(d, c, mg)
                                               : MakeCpuChannelObjective(d, c, mg);
      kappa_[c].resize(n_);
      mu_[c].resize(n_);
      gk_[c].resize(n_);
      gm_[c].resize(n_);
    }
    threads_ = o.threads_per_channel > 0 ? o.threads_per_channel : std::max(1, NumThreads() / 3);
  }

  void set_scales(const std::array<double, 3>& k, const std::array<double, 3>& m) {
    kappa_scale_ = k;
    mu_scale_ = m;
  }
  int64_t num_parameters() const { return 6 * n_; }
  int threads_per_channel() const { return threads_; }
  int64_t cg_iterations() const {
    int64_t s = 0;
    for (const auto& c : channels_) s += c->cg_iterations();
    return s;
  }
  int64_t solves() const {
    int64_t s = 0;
    for (const auto& c : channels_) s += c->solves();
    return s;
  }

  // f(x) and, if grad is non-null, df/dx.
  double Evaluate(const double* x, double* grad) {
    std::array<double, 3> f{};
    ForEachChannel([&](int c) { f[c] = EvaluateChannel(c, x, grad); });
    return (f[0] + f[1] + f[2]) / 3.0;
  }

  // Runs body(c) for the 3 channels in 3 threads, each with threads_ OpenMP threads (on gl in
  // turn); rethrows the first exception.
  template <typename F>
  void ForEachChannel(F&& body) {
    if (o_.backend == Backend::kGl) {
      // The GL context is current on this thread only; the GPU runs the channels in turn.
      for (int c = 0; c < 3; ++c) body(c);
      return;
    }
    std::array<std::exception_ptr, 3> errors;
    auto run = [&](int c) {
      try {
        omp_set_num_threads(threads_);
        body(c);
      } catch (...) {
        errors[c] = std::current_exception();
      }
    };
    std::thread t1(run, 1), t2(run, 2);
    run(0);
    t1.join();
    t2.join();
    for (auto& e : errors)
      if (e) std::rethrow_exception(e);
  }

  // While one lives, the calling thread's work counts as an evaluation in evaluation_seconds.
  class BusyScope {
   public:
    explicit BusyScope(RecoveryProblem* p) : p_(p) {
      std::lock_guard<std::mutex> lock(p_->busy_mutex_);
      if (p_->evaluating_++ == 0) p_->busy_since_ = Clock::now();
    }
    ~BusyScope() {
      std::lock_guard<std::mutex> lock(p_->busy_mutex_);
      if (--p_->evaluating_ == 0) p_->busy_seconds_ += Since(p_->busy_since_);
    }
    BusyScope(const BusyScope&) = delete;
    BusyScope& operator=(const BusyScope&) = delete;

   private:
    RecoveryProblem* p_;
  };

  // Wall seconds so far during which an evaluation of some channel ran (EvaluateOneChannel), or
  // other work under a BusyScope (Recover's validation checks); work at once counts once.
  double evaluation_seconds() const {
    std::lock_guard<std::mutex> lock(busy_mutex_);
    return busy_seconds_ + (evaluating_ > 0 ? Since(busy_since_) : 0.0);
  }

  // Whether every solve of the last evaluation converged (to within 100x the tolerance). Trial
  // points far outside the physical range can stall the solver; the optimisers then treat the
  // evaluation as failed and shorten the step.
  bool last_evaluation_ok() const { return channel_ok(0) && channel_ok(1) && channel_ok(2); }
  bool channel_ok(int c) const { return channels_[c]->worst_residual() <= 100 * o_.solve_tolerance; }
  // The channels as FitChannels takes them.
  ChannelObjectives channel_objectives() {
    ChannelObjectives f;
    f.evaluate = [this](int c, const double* x, double* g) { return EvaluateOneChannel(c, x, g); };
    f.ok = [this](int c) { return channel_ok(c); };
    f.threads_per_channel = threads_per_channel();
    f.serve_here = o_.backend == Backend::kGl;
    return f;
  }

  // Levenberg-Marquardt on the homogeneous problem of each channel, (log kappa, log mu)
  // = (h[2c], h[2c+1]), channels in parallel. The residuals' 2-column Jacobian comes from forward
  // differences in log space (2 extra evaluations of M forward solves per iteration); the fit is
  // quadratically convergent where first-order methods crawl along the kappa-mu valley.
  void FitHomogeneous(int max_iterations, std::vector<double>* h) {
    ForEachChannel([&](int c) { FitChannel(c, max_iterations, &(*h)[2 * c], &(*h)[2 * c + 1]); });
  }

  // Fit error of the last evaluation: total and per condition (RGB together).
  double FitError(std::vector<double>* per_condition) const {
    const size_t M = d_.conditions.size();
    per_condition->assign(M, 0.0);
    double num = 0, den = 0;
    for (size_t m = 0; m < M; ++m) {
      double a = 0, b = 0;
      for (const auto& c : channels_) {
        a += c->condition_misfit()[m];
        b += c->condition_norm()[m];
      }
      (*per_condition)[m] = b > 0 ? a / b : 0.0;
      num += a;
      den += b;
    }
    return den > 0 ? num / den : 0.0;
  }

 private:
  // J of channel c on the constant volume exp(lk), exp(lm); the residuals into r.
  double EvaluateConstant(int c, double lk, double lm, std::vector<double>* r) {
    std::fill(kappa_[c].begin(), kappa_[c].end(), std::exp(lk));
    std::fill(mu_[c].begin(), mu_[c].end(), std::exp(lm));
    const double J = channels_[c]->Evaluate(kappa_[c].data(), mu_[c].data(), nullptr, nullptr);
    channels_[c]->Residuals(r);
    return J;
  }

  void FitChannel(int c, int max_iterations, double* lk, double* lm) {
    // Forward-difference step in log space, about the square root of the model's relative
    // accuracy: the cpu model is double throughout (1e-4), the gl model float (1e-2). (When the
    // gl operator still applied a float diagonal, whose rounding was ~1e-3 of the absorption
    // term, a 1e-4 step made the mu column of the Jacobian noise and the fit stopped far from
    // the optimum; the difference form of residual.comp fixed that, and 1e-2 keeps a margin.)
    const double kStep = o_.backend == Backend::kGl ? 1e-2 : 1e-4;
    std::vector<double> r0, r1, r2, rt;
    double f0 = EvaluateConstant(c, *lk, *lm, &r0);
    double damping = 1e-3;
    for (int it = 0; it < max_iterations && f0 > 0 && !o_.StopRequested(); ++it) {
      EvaluateConstant(c, *lk + kStep, *lm, &r1);
      EvaluateConstant(c, *lk, *lm + kStep, &r2);
      double a11 = 0, a12 = 0, a22 = 0, g1 = 0, g2 = 0;
      for (size_t i = 0; i < r0.size(); ++i) {
        const double j1 = (r1[i] - r0[i]) / kStep, j2 = (r2[i] - r0[i]) / kStep;
        a11 += j1 * j1;
        a12 += j1 * j2;
        a22 += j2 * j2;
        g1 += j1 * r0[i];
        g2 += j2 * r0[i];
      }
      bool accepted = false, converged = false;
      double step = 0;
      for (int tries = 0; tries < 12 && !accepted && !converged; ++tries) {
        const double b11 = a11 * (1 + damping), b22 = a22 * (1 + damping);
        const double det = b11 * b22 - a12 * a12;
        if (!(det > 0)) {
          damping *= 4;
          continue;
        }
        // Steps longer than 1 in log space are clipped: the model is only local.
        double dk = (-g1 * b22 + g2 * a12) / det, dm = (-g2 * b11 + g1 * a12) / det;
        const double len = std::max(std::abs(dk), std::abs(dm));
        if (len > 1) { dk /= len; dm /= len; }
        // The Gauss-Newton model |r + J d|^2 = J + 2 g.d + d^T A d: where even it promises less
        // than the tolerance, the fit has converged (on the gl backend's float model the
        // objective's last digits are noise, and steps there only wander).
        const double predicted = -(2 * (g1 * dk + g2 * dm) + a11 * dk * dk + 2 * a12 * dk * dm + a22 * dm * dm);
        if (predicted <= o_.tolerance * f0) {
          converged = true;
          break;
        }
        const double ft = EvaluateConstant(c, *lk + dk, *lm + dm, &rt);
        if (ft < f0) {
          *lk += dk;
          *lm += dm;
          step = std::max(std::abs(dk), std::abs(dm));
          const double decrease = f0 - ft;
          f0 = ft;
          r0.swap(rt);
          damping = std::max(damping / 3, 1e-9);
          accepted = true;
          if (decrease <= o_.tolerance * ft) step = 0;  // as the optimisers stop
        } else {
          damping *= 4;
        }
      }
      if (converged || !accepted || step < 1e-7) break;
    }
  }

  double EvaluateChannel(int c, const double* x, double* grad) {
    return EvaluateOneChannel(c, x + 2 * c * n_, grad ? grad + 2 * c * n_ : nullptr);
  }

 public:
  // After channel c's last evaluation: its data term with the residual images low-passed,
  // sum_m |G * r_m|^2 (r as ChannelObjective::Residuals, G a Gaussian of kLowPassNodes nodes'
  // standard deviation over each condition's nx x ny front face, its weights renormalised at
  // the face's edges), and |r|^2 (the data term itself) into *raw.
  double LowPassMisfit(int c, double* raw) const {
    const int nx = d_.shape.nx, ny = d_.shape.ny;
    std::vector<double> r;
    channels_[c]->Residuals(&r);
    const int R = int(std::ceil(3 * kLowPassNodes));
    std::vector<double> kernel(2 * R + 1);
    for (int i = -R; i <= R; ++i) kernel[i + R] = std::exp(-0.5 * i * i / (kLowPassNodes * kLowPassNodes));
    // One axis of the separable blur: out(i) = sum_k g(k) in(i + k) / sum_k g(k), i + k on the face.
    const auto blur = [&](const double* in, double* out, int len, int stride, int count, int step) {
      for (int a = 0; a < count; ++a)
        for (int i = 0; i < len; ++i) {
          double s = 0, w = 0;
          for (int k = std::max(-R, -i); k <= std::min(R, len - 1 - i); ++k) {
            s += kernel[k + R] * in[a * step + (i + k) * stride];
            w += kernel[k + R];
          }
          out[a * step + i * stride] = s / w;
        }
    };
    double low = 0, all = 0;
    std::vector<double> tmp(size_t(nx) * ny), out(size_t(nx) * ny);
    for (size_t m = 0; m * nx * ny < r.size(); ++m) {
      const double* face = r.data() + m * nx * ny;
      blur(face, tmp.data(), nx, 1, ny, nx);        // along x, row by row
      blur(tmp.data(), out.data(), ny, nx, nx, 1);  // along y, column by column
      for (int64_t p = 0; p < int64_t(nx) * ny; ++p) {
        low += out[p] * out[p];
        all += face[p] * face[p];
      }
    }
    *raw = all;
    return low;
  }
  static constexpr double kLowPassNodes = 2;

  // f_c and df_c/dx_c / 3 (the joint objective's gradient on this block) of one channel on its
  // own block of the unknowns, xk = (log kappa_c, log mu_c) (2 n values; g likewise, may be
  // null). Different channels may be evaluated at once from different threads (ForEachChannel,
  // FitChannels on cpu).
  double EvaluateOneChannel(int c, const double* xk, double* g) {
    const BusyScope busy(this);
    std::vector<double>& k = kappa_[c];
    std::vector<double>& m = mu_[c];
    const double* xm = xk + n_;
    // Parallel for the gl backend, whose channels run in turn on one host thread (Wax I: 7.5 ms
    // an evaluation serial, ~2 % of an H200 iteration); on cpu each channel's threads_.
#pragma omp parallel for schedule(static)
    for (int64_t p = 0; p < n_; ++p) {
      k[p] = std::exp(xk[p]);
      m[p] = std::exp(xm[p]);
    }
    double* gk = g ? gk_[c].data() : nullptr;
    double* gm = g ? gm_[c].data() : nullptr;
    double f = channels_[c]->Evaluate(k.data(), m.data(), gk, gm);
    if (o_.lambda > 0) {
      f += o_.lambda * Regularize(d_.shape, k.data(), kappa_scale_[c], o_.regularizer, o_.lambda, gk);
      if (o_.regularize_mu)
        f += o_.lambda * Regularize(d_.shape, m.data(), mu_scale_[c], o_.regularizer, o_.lambda, gm);
    }
    if (g) {
      // Chain rule through kappa = exp(x), and the 1/3 of the channel mean.
#pragma omp parallel for schedule(static)
      for (int64_t p = 0; p < n_; ++p) {
        g[p] = gk[p] * k[p] / 3.0;
        g[n_ + p] = gm[p] * m[p] / 3.0;
      }
    }
    return f;
  }

 private:

  const Dataset& d_;
  const RecoveryOptions& o_;
  int64_t n_;
  int threads_ = 1;
  std::array<std::unique_ptr<ChannelObjective>, 3> channels_;
  std::array<std::vector<double>, 3> kappa_, mu_, gk_, gm_;
  std::array<double, 3> kappa_scale_{1, 1, 1}, mu_scale_{1, 1, 1};
  mutable std::mutex busy_mutex_;  // guards the three below (evaluation_seconds)
  int evaluating_ = 0;
  Clock::time_point busy_since_;
  double busy_seconds_ = 0;
};


// The absorption level search (RecoveryOptions::level_search). The objective is a sum over
// channels, so one trial tries a level for every channel at once and each channel keeps its
// own best. Upward only: the homogeneous fit of a heterogeneous volume sees the light that
// takes the easier paths, more than the mean volume lets through (transmittance and diffuse
// reflectance are convex in mu), so its mu errs low; downward moves measured on thin slabs were
// noise (held-out E 1.2x worse). A channel's next level: one lattice step above its best while
// that is the highest level tried, else none (its search is done). A level other than the
// homogeneous fit's must lower the channel's objective 1.5x below the homogeneous level's. Then
// a quarter-decade refinement either side of that choice (never below the homogeneous level).
// state->x holds the homogeneous fit on entry and the same with mu scaled by the chosen factors
// on return. (Not the best trial's iterate: the trials are short runs for comparing levels,
// each channel on its own; the fit starts from the level itself, as the search was measured.)
struct LevelSearchResult {
  std::array<double, 3> factor{1, 1, 1};
  int trials = 0;
  bool stopped = false;  // RecoveryOptions::stop: abandoned, the homogeneous level kept
};

LevelSearchResult SearchAbsorptionLevel(RecoveryProblem* problem, const RecoveryOptions& o, int64_t n,
                                        RecoveryState* state) {
  constexpr double kStep = 0.5, kReach = 2.0;  // decades, up from the homogeneous fit
  constexpr double kMargin = 1.5, kFineMargin = 1.2;
  const std::vector<double> start = state->x;
  std::array<std::map<double, double>, 3> tried;  // level t -> the channel's trial score
  // The level with the least score so far.
  const auto best = [&](int c) {
    return std::min_element(tried[c].begin(), tried[c].end(),
                            [](const auto& a, const auto& b) { return a.second < b.second; })->first;
  };
  // mu of channel c in x, and its regulariser scale, times 10^t.
  const auto scale_mu = [n](std::vector<double>* x, std::array<double, 3>* mu_scale, int c, double t) {
    for (int64_t p = 0; p < n; ++p) (*x)[(2 * c + 1) * n + p] += t * std::log(10.0);
    (*mu_scale)[c] *= std::pow(10.0, t);
  };
  LevelSearchResult result;
  // Stopped: state->x and its scales are still the homogeneous fit's (the trials work on copies).
  const auto abandon = [&] {
    problem->set_scales(state->kappa_scale, state->mu_scale);
    result.stopped = true;
    return result;
  };
  auto trial = [&](const std::array<double, 3>& t, const std::array<bool, 3>& record) {
    std::vector<double> x = start;
    std::array<double, 3> mu_scale = state->mu_scale;
    for (int c = 0; c < 3; ++c) scale_mu(&x, &mu_scale, c, t[c]);
    problem->set_scales(state->kappa_scale, mu_scale);
    // Each channel its own optimiser (FitChannels), run for the trial's few iterations from the
    // level, its first step sized by FirstStepScale as every fit's.
    FitChannels(problem->channel_objectives(), o, n, o.level_search, record, x.data(), {});
    std::array<double, 3> f{};
    problem->ForEachChannel([&](int c) {
      if (!record[c]) return;  // this channel's search is done
      // The trial's score: its objective with the data term low-passed. A wrong level leaves a
      // residual as smooth as diffusion makes it; the data's noise, which the trial's few
      // iterations have only begun to fit, is rough, and (1 % on wax 64x48x16) it added ~7e-5 to
      // every level's data term of ~1e-5 to 3e-5, so that no level was 1.5x below another. Low-
      // passed, the trials' scores with and without the noise agree within 15 %.
      const double objective = problem->EvaluateOneChannel(c, x.data() + 2 * c * n, nullptr);
      double raw = 0;
      const double low = problem->LowPassMisfit(c, &raw);
      f[c] = objective - raw + low;
    });
    // The trial's vectors were freed in the channels' threads, whose arenas the next trial's
    // threads and the main fit's optimiser need not reuse: without this the recovery's peak
    // memory rose by 22-28 % (RecoverMemory tests).
    ReleaseFreedMemory();
    ++result.trials;
    for (int c = 0; c < 3; ++c)
      if (record[c]) tried[c][t[c]] = std::isfinite(f[c]) ? f[c] : std::numeric_limits<double>::infinity();
  };
  trial({0, 0, 0}, {true, true, true});
  if (o.StopRequested()) return abandon();
  trial({kStep, kStep, kStep}, {true, true, true});
  if (o.StopRequested()) return abandon();
  for (int round = 0; round < int(kReach / kStep); ++round) {
    std::array<double, 3> t{};
    std::array<bool, 3> record{};
    for (int c = 0; c < 3; ++c) {
      const double hi = tried[c].rbegin()->first;
      t[c] = best(c);
      if (t[c] == hi && hi < kReach) {
        t[c] = hi + kStep;
        record[c] = true;
      }
    }
    if (!record[0] && !record[1] && !record[2]) break;
    trial(t, record);
    if (o.StopRequested()) return abandon();
  }
  // A trial's objective depends on the path its few iterations take as well as on the level:
  // levels 0.1-0.5 decades apart measured 1.3-1.75x apart where the level hardly mattered, and
  // the homogeneous fit's own level starts the fit at its optimum. Another level must beat it
  // by more than that.
  std::array<double, 3> coarse{};
  for (int c = 0; c < 3; ++c) coarse[c] = kMargin * tried[c].at(best(c)) < tried[c].at(0.0) ? best(c) : 0.0;
  // Refinement: half a lattice step either side of each channel's coarse choice (not below the
  // homogeneous level), kept where it beats the coarse level by kFineMargin. A level that is
  // off by a quarter decade still costs the held-out error: wax 64x48x16's green 28 % low gave
  // 2.4x the held-out error of green x1.33 or x1.78, whose objectives after 10 iterations are
  // clearly lower. Run after the coarse stage, not as a finer lattice in it: a 0.25-decade lattice
  // with a smaller margin stopped wax's red at x3.16 of its x10 (a neighbour's noise).
  std::array<double, 3> fine = coarse;
  for (const double d : {kStep / 2, -kStep / 2}) {
    std::array<double, 3> t{};
    std::array<bool, 3> record{};
    for (int c = 0; c < 3; ++c) {
      t[c] = coarse[c] + d;
      record[c] = t[c] >= 0 && !tried[c].count(t[c]);
    }
    if (!record[0] && !record[1] && !record[2]) continue;
    trial(t, record);
    if (o.StopRequested()) return abandon();
    for (int c = 0; c < 3; ++c)
      if (record[c] && kFineMargin * tried[c].at(t[c]) < tried[c].at(fine[c])) fine[c] = t[c];
  }
  for (int c = 0; c < 3; ++c) {
    result.factor[c] = std::pow(10.0, fine[c]);
    scale_mu(&state->x, &state->mu_scale, c, fine[c]);
  }
  problem->set_scales(state->kappa_scale, state->mu_scale);
  return result;
}

double GeometricMean(const double* logs, int64_t n) {
  double s = 0;
  for (int64_t p = 0; p < n; ++p) s += logs[p];
  return std::exp(s / double(n));
}

// The most validation conditions rendered at once (their solvers' memory: RecoveryMemoryBytes).
constexpr int kValidationBatch = 4;

// The validation conditions' relighting error of the current iterate (RecoveryOptions::
// validation_every): E = sum w (L^R - L)^2 / sum w L^2 against their measured L, rendered on the
// recovery's backend from zero to a relative residual of 1e-6 (E to ~1e-12, far below the
// differences between iterates that it tells apart), at most kValidationBatch conditions at once.
class Validation {
 public:
  Validation(const Dataset& d, const Dataset* v, const RecoveryOptions& o) : d_(d), o_(o) {
    if (!v || v->conditions.empty() || o.validation_every == 0) return;
    if (std::string err = v->Validate(); !err.empty()) throw InputError("validation dataset: " + err);
    if (std::string err = DifferentProblem(*v, d, /*same_setup=*/true); !err.empty())
      throw InputError("validation dataset: " + err);
    for (const auto& c : v->conditions) {
      q_.push_back(c.q);
      L_.push_back(c.L);
      w_.push_back(c.mask);
    }
  }
  bool active() const { return !q_.empty(); }
  // Checks state->x at `iteration`; keeps it as the result (state->best_x) where its E is within
  // validation_margin of the least so far; returns its E.
  double Check(int iteration, RecoveryState* state) {
    const auto t0 = Clock::now();
    MultigridOptions mg;
    mg.tolerance = 1e-6;
    mg.max_iterations = 500;
    const Material m = MaterialFromState(d_, *state);
    const std::vector<FacePattern> rendered = RenderMeasured(m, d_.setup, q_, mg, o_.backend, kValidationBatch);
    const double e = RelightingError(rendered, L_, w_);
    if (state->least_validation_error < 0 || e < state->least_validation_error) state->least_validation_error = e;
    if (e <= (1 + o_.validation_margin) * state->least_validation_error) {
      state->best_x = state->x;
      state->best_iteration = iteration;
      state->best_validation_error = e;
    }
    ++checks_;
    last_checked_ = iteration;
    seconds_ += Since(t0);
    return e;
  }
  int checks() const { return checks_; }
  int last_checked() const { return last_checked_; }
  double seconds() const { return seconds_; }

 private:
  const Dataset& d_;
  const RecoveryOptions& o_;
  std::vector<FacePattern> q_, L_;
  std::vector<std::vector<float>> w_;
  int checks_ = 0, last_checked_ = -1;
  double seconds_ = 0;
};

}  // namespace

OptimizerKind ParseOptimizer(const std::string& text) {
  if (text == "lbfgs") return OptimizerKind::kLbfgs;
  if (text == "ncg") return OptimizerKind::kNcg;
  if (text == "paper") return OptimizerKind::kPaper;
  throw InputError(fmt::format("--optimizer: unknown optimizer '{}' (lbfgs, ncg, paper)", text));
}

const char* OptimizerName(OptimizerKind kind) {
  switch (kind) {
    case OptimizerKind::kLbfgs: return "lbfgs";
    case OptimizerKind::kNcg: return "ncg";
    case OptimizerKind::kPaper: return "paper";
  }
  return "?";
}

const char* TerminationName(RecoveryTermination t) {
  switch (t) {
    case RecoveryTermination::kConverged: return "converged";
    case RecoveryTermination::kMaxIterations: return "max_iterations";
    case RecoveryTermination::kStopped: return "stopped";
    case RecoveryTermination::kFailed: return "failed";
    case RecoveryTermination::kValidated: return "validated";
  }
  return "?";
}

std::string RecoveryOptions::Validate() const {
  if (!(lambda >= 0) || !std::isfinite(lambda)) return fmt::format("lambda must be a finite number >= 0, got {}", lambda);
  if (max_iterations < 0) return "max_iterations must be >= 0";
  if (lbfgs_rank < 1 || lbfgs_rank > 1000) return fmt::format("lbfgs_rank must be in [1, 1000], got {}", lbfgs_rank);
  if (!(tolerance > 0 && tolerance < 1)) return fmt::format("tolerance must be in (0, 1), got {}", tolerance);
  if (homogeneous_iterations < 0) return "homogeneous_iterations must be >= 0";
  if (level_search < 0 || level_search > 1000) return fmt::format("level_search must be in [0, 1000], got {}", level_search);
  if (!(homogeneous_kappa > 0) || !(homogeneous_mu > 0)) return "the homogeneous start must be > 0";
  if (!(solve_tolerance > 0 && solve_tolerance < 1e-3)) return "solve_tolerance must be in (0, 1e-3)";
  if (threads_per_channel < 0) return "threads_per_channel must be >= 0";
  if (validation_every < 0) return fmt::format("validation_every must be >= 0, got {}", validation_every);
  if (validation_patience < 1) return fmt::format("validation_patience must be >= 1, got {}", validation_patience);
  if (!(validation_margin >= 0 && validation_margin <= 1))
    return fmt::format("validation_margin must be in [0, 1], got {}", validation_margin);
  return regularizer.Validate();
}

int64_t RecoveryMemoryBytes(const GridShape& shape, int conditions, const RecoveryOptions& o) {
  // Vectors of 6N doubles. Ceres' line search and its directions' working vectors (iterates,
  // gradients, directions, line-search points): 17-21 measured besides the L-BFGS history
  // (docs/benchmarks.md, "The recovery's memory estimate"), counted as 32 for a margin; the
  // history, 2 per rank. RunPaper's: x, g, g_new, d, trial, and one for a margin.
  int vectors = 6;
  if (o.optimizer == OptimizerKind::kNcg) vectors = 32;
  if (o.optimizer == OptimizerKind::kLbfgs) vectors = 32 + 2 * o.lbfgs_rank;
  // (FitChannels' copies of the channels' blocks, one vector in all, are within that margin:
  // RecoverMemory's rank-20 case measured 0.76 of the estimate with and without them.)
  // The level search's start, its trial's iterate and two for a margin (its peak varied
  // 0.86-0.96 of the estimate in RecoverMemory's rank-20 case); its optimisers run per channel
  // on a third of the unknowns each, so no more than the main fit.
  if (o.level_search > 0) vectors += 4;
  // Validation keeps the best iterate (RecoveryState::best_x), and its checks render up to
  // kValidationBatch conditions at once, one forward solver each (cpu: in parallel threads).
  int64_t validation = 0;
  if (o.validation_every > 0) {
    vectors += 1;
    const int at_once = o.backend == Backend::kCpu ? std::min(kValidationBatch, NumThreads()) : 1;
    validation = at_once * EstimateMemory(shape, 1, Precision::kDouble).forward_bytes;
  }
  return EstimateMemory(shape, conditions, Precision::kDouble, vectors).recovery_bytes + validation;
}

std::string RecoverySummary::BriefReport() const {
  return fmt::format("{} ({}): {} iterations, {} solves, {:.1f} s ({:.1f} s in the optimiser), "
                     "objective {:.4e} -> {:.4e}, fit E {:.3e}{}{}", TerminationName(termination),
                     OptimizerName(optimizer), iterations, solves, seconds, optimizer_seconds,
                     initial_objective, final_objective, fit_error,
                     message.empty() ? "" : ": ", message);
}

RecoveryState StateFromMaterial(const Dataset& d, const Material& m) {
  if (!(m.shape == d.shape))
    throw InputError(fmt::format("--init: material grid {} differs from the dataset grid {}",
                                 m.shape.ToString(), d.shape.ToString()));
  if (std::string err = m.Validate(); !err.empty()) throw InputError("--init: " + err);
  const int64_t n = d.shape.size();
  RecoveryState s;
  s.x.resize(6 * n);
  for (int c = 0; c < 3; ++c) {
    for (int64_t p = 0; p < n; ++p) {
      s.x[2 * c * n + p] = std::log(double(m.kappa[c][p]));
      s.x[(2 * c + 1) * n + p] = std::log(double(m.mu[c][p]));
    }
    s.kappa_scale[c] = s.homogeneous_kappa[c] = GeometricMean(s.x.data() + 2 * c * n, n);
    s.mu_scale[c] = s.homogeneous_mu[c] = GeometricMean(s.x.data() + (2 * c + 1) * n, n);
  }
  return s;
}

Material MaterialFromState(const Dataset& d, const RecoveryState& s, double eta) {
  const int64_t n = d.shape.size();
  TL_CHECK(int64_t(s.x.size()) == 6 * n);
  Material m = Material::Constant(d.shape, d.spacing_mm, {1, 1, 1}, {1, 1, 1}, eta);
  m.C = d.C;
  for (int c = 0; c < 3; ++c)
    for (int64_t p = 0; p < n; ++p) {
      m.kappa[c][p] = float(std::exp(s.x[2 * c * n + p]));
      m.mu[c][p] = float(std::exp(s.x[(2 * c + 1) * n + p]));
    }
  return m;
}

RecoverySummary Recover(const Dataset& d, const RecoveryOptions& o, RecoveryState* state,
                        const RecoveryCallback& callback, const Dataset* validation_data) {
  if (std::string err = o.Validate(); !err.empty()) throw InputError("recovery options: " + err);
  if (std::string err = d.Validate(); !err.empty()) throw InputError("dataset: " + err);
  Validation validation(d, validation_data, o);
  const auto t0 = Clock::now();
  const int64_t n = d.shape.size();
  RecoveryProblem problem(d, o);
  RecoverySummary sum;
  sum.optimizer = o.optimizer;
  const int64_t solves0 = state->solves;
  const double seconds0 = state->seconds;
  auto solves = [&] { return solves0 + problem.solves(); };
  auto seconds = [&] { return seconds0 + Since(t0); };

  if (state->x.empty()) {
    // Homogeneous initialisation: 6 unknowns, same objective on constant volumes.
    std::vector<double> h(6);
    for (int c = 0; c < 3; ++c) {
      h[2 * c] = std::log(o.homogeneous_kappa);
      h[2 * c + 1] = std::log(o.homogeneous_mu);
    }
    if (o.homogeneous_iterations > 0) problem.FitHomogeneous(o.homogeneous_iterations, &h);
    state->x.resize(6 * n);
    for (int c = 0; c < 3; ++c) {
      std::fill_n(state->x.begin() + 2 * c * n, n, h[2 * c]);
      std::fill_n(state->x.begin() + (2 * c + 1) * n, n, h[2 * c + 1]);
      state->kappa_scale[c] = state->homogeneous_kappa[c] = std::exp(h[2 * c]);
      state->mu_scale[c] = state->homogeneous_mu[c] = std::exp(h[2 * c + 1]);
    }
    sum.homogeneous_seconds = Since(t0);
    sum.homogeneous_solves = problem.solves();
    sum.homogeneous_cg_iterations = problem.cg_iterations();
    if (o.level_search > 0 && o.max_iterations > 0 && !o.StopRequested()) {
      problem.set_scales(state->kappa_scale, state->mu_scale);
      const LevelSearchResult level = SearchAbsorptionLevel(&problem, o, n, state);
      state->level_factor = level.factor;
      sum.level_trials = level.trials;
      sum.level_stopped = level.stopped;
      sum.level_seconds = Since(t0) - sum.homogeneous_seconds;
      sum.level_solves = problem.solves() - sum.homogeneous_solves;
    }
  }
  sum.level_factor = state->level_factor;
  TL_CHECK(int64_t(state->x.size()) == 6 * n);
  problem.set_scales(state->kappa_scale, state->mu_scale);
  sum.homogeneous_kappa = state->homogeneous_kappa;
  sum.homogeneous_mu = state->homogeneous_mu;

  const int first_iteration = state->iteration;
  // The start is a candidate too (a fresh fit's, or a resumed one's from before validation).
  if (validation.active() && state->best_iteration < 0) validation.Check(first_iteration, state);
  bool validated = false;  // validation_patience iterations since the result's (RecoveryOptions)
  IterationHook hook = [&](int it, double f, double gnorm) {
    IterationReport rep;
    rep.iteration = first_iteration + it;
    rep.objective = f;
    rep.gradient_norm = gnorm;
    rep.solves = solves();
    state->iteration = rep.iteration;
    if (validation.active() && rep.iteration % o.validation_every == 0) {
      // Busy: on cpu the channels may evaluate their next iteration meanwhile (FitChannels).
      const RecoveryProblem::BusyScope busy(&problem);
      rep.validation_error = validation.Check(rep.iteration, state);
      validated = rep.iteration - state->best_iteration >= o.validation_patience;
    }
    rep.seconds = seconds();
    state->solves = rep.solves;
    state->seconds = rep.seconds;
    state->history.push_back(rep);
    const bool go_on = callback ? callback(rep, *state) : true;
    return go_on && !validated;
  };
  const int remaining = std::max(0, o.max_iterations - first_iteration);
  const auto t_optimizer = Clock::now();
  const double evaluation0 = problem.evaluation_seconds();
  OptimizerResult r;
  if (remaining == 0 || o.StopRequested()) {
    r.termination = remaining == 0 ? RecoveryTermination::kMaxIterations : RecoveryTermination::kStopped;
    r.message = remaining == 0 ? "no iterations left"
                               : fmt::format("stopped by the caller (e.g. Ctrl-C) before the fit's first iteration{}",
                                             sum.level_stopped ? ", in the absorption level search (the homogeneous "
                                                                 "fit's level kept)" : "");
    r.initial = r.final = problem.Evaluate(state->x.data(), nullptr);
  } else {
    if (o.joint_optimizer) {
      const Objective whole{[&](const double* v, double* g) { return problem.Evaluate(v, g); },
                            [&] { return problem.last_evaluation_ok(); }};
      r = RunOptimizer(whole, o, remaining, state->x, hook);
    } else {
      r = FitChannels(problem.channel_objectives(), o, n, remaining, {true, true, true}, state->x.data(), hook);
    }
  }
  // (The validation checks count as evaluations: on cpu the channels may evaluate meanwhile.)
  sum.optimizer_seconds = std::max(0.0, Since(t_optimizer) - (problem.evaluation_seconds() - evaluation0));
  if (validation.active()) {
    if (validation.last_checked() != state->iteration) validation.Check(state->iteration, state);
    if (state->best_iteration != state->iteration) state->x = state->best_x;
    sum.validation_error = state->best_validation_error;
    sum.validation_iteration = state->best_iteration;
    sum.validation_checks = validation.checks();
    sum.validation_seconds = validation.seconds();
    if (validated && r.termination == RecoveryTermination::kStopped) {
      r.termination = RecoveryTermination::kValidated;
      r.message = fmt::format("validation E has not come within {:g} % of its least for {} iterations",
                              100 * o.validation_margin, o.validation_patience);
    }
    while (!r.message.empty() && r.message.back() == '.') r.message.pop_back();  // Ceres' messages end in one
    r.message += fmt::format("; the result is iteration {}'s iterate (validation E {:.3e})",
                             state->best_iteration, state->best_validation_error);
  }
  // Final evaluation at the result: fit errors per condition (warm-started, cheap).
  sum.final_objective = problem.Evaluate(state->x.data(), nullptr);
  sum.fit_error = problem.FitError(&sum.condition_fit_error);
  sum.termination = r.termination;
  sum.message = r.message;
  sum.initial_objective = r.initial;
  sum.iterations = state->iteration;
  sum.solves = state->solves = solves();
  sum.cg_iterations = problem.cg_iterations();
  sum.seconds = state->seconds = seconds();
  sum.history = state->history;
  return sum;
}

void WriteCheckpoint(const std::string& path, const Dataset& d, const RecoveryState& s) {
  nlohmann::json j;
  j["format"] = "translume-checkpoint/1";
  j["grid"] = {d.shape.nx, d.shape.ny, d.shape.nz};
  j["x"] = s.x;
  j["kappa_scale"] = s.kappa_scale;
  j["mu_scale"] = s.mu_scale;
  j["homogeneous_kappa"] = s.homogeneous_kappa;
  j["homogeneous_mu"] = s.homogeneous_mu;
  j["level_factor"] = s.level_factor;
  j["iteration"] = s.iteration;
  j["solves"] = s.solves;
  j["seconds"] = s.seconds;
  nlohmann::json h = nlohmann::json::array();
  for (const auto& r : s.history)
    h.push_back({r.iteration, r.objective, r.gradient_norm, r.solves, r.seconds, r.validation_error});
  j["history"] = h;
  if (s.best_iteration >= 0)
    j["validation"] = {{"best_iteration", s.best_iteration}, {"best_error", s.best_validation_error},
                       {"least_error", s.least_validation_error}, {"best_x", s.best_x}};
  const std::vector<uint8_t> bytes = nlohmann::json::to_cbor(j);
  WriteAtomically(path, [&](const std::string& tmp) {
    std::ofstream out(tmp, std::ios::binary);
    out.write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
    if (!out) throw InputError(fmt::format("{}: cannot write checkpoint", path));
  });
}

namespace {

// Parses nothing; refuses nesting deeper than a checkpoint's (nlohmann's CBOR reader recurses
// once per level, so 200000 nested arrays overflowed the stack).
class NestingCheck : public nlohmann::json_sax<nlohmann::json> {
 public:
  bool null() override { return true; }
  bool boolean(bool) override { return true; }
  bool number_integer(number_integer_t) override { return true; }
  bool number_unsigned(number_unsigned_t) override { return true; }
  bool number_float(number_float_t, const string_t&) override { return true; }
  bool string(string_t&) override { return true; }
  bool binary(binary_t&) override { return true; }
  bool start_object(std::size_t) override { return ++depth_ <= kMaxDepth; }
  bool key(string_t&) override { return true; }
  bool end_object() override { return --depth_, true; }
  bool start_array(std::size_t) override { return ++depth_ <= kMaxDepth; }
  bool end_array() override { return --depth_, true; }
  bool parse_error(std::size_t, const std::string&, const nlohmann::detail::exception&) override { return false; }
  bool too_deep() const { return depth_ > kMaxDepth; }

 private:
  static constexpr int kMaxDepth = 8;
  int depth_ = 0;
};

}  // namespace

RecoveryState ReadCheckpoint(const std::string& path, const Dataset& d) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(fmt::format("{}: cannot open checkpoint", path));
  const std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)), {});
  RecoveryState s;
  const auto corrupt = [&](const std::string& why) {
    return InputError(fmt::format("{}: corrupt checkpoint ({})", path, why));
  };
  NestingCheck nesting;
  nlohmann::json::sax_parse(bytes, &nesting, nlohmann::json::input_format_t::cbor);
  if (nesting.too_deep()) throw corrupt("nested deeper than a checkpoint");
  try {
    const nlohmann::json j = nlohmann::json::from_cbor(bytes);
    if (j.at("format") != "translume-checkpoint/1")
      throw InputError(fmt::format("{}: not a translume checkpoint", path));
    const auto grid = j.at("grid").get<std::vector<int64_t>>();
    if (grid != std::vector<int64_t>{d.shape.nx, d.shape.ny, d.shape.nz})
      throw InputError(fmt::format("{}: checkpoint grid differs from the dataset grid {}", path,
                                   d.shape.ToString()));
    s.x = j.at("x").get<std::vector<double>>();
    if (int64_t(s.x.size()) != 6 * d.shape.size())
      throw InputError(fmt::format("{}: checkpoint has the wrong number of parameters", path));
    // Every scale and homogeneous value is a kappa or mu: finite and > 0.
    const auto positive = [&](const char* key) {
      const auto v = j.at(key).get<std::array<double, 3>>();
      for (double x : v)
        if (!(x > 0 && std::isfinite(x))) throw corrupt(fmt::format("{} must be finite and > 0, got {}", key, x));
      return v;
    };
    s.kappa_scale = positive("kappa_scale");
    s.mu_scale = positive("mu_scale");
    s.homogeneous_kappa = positive("homogeneous_kappa");
    s.homogeneous_mu = positive("homogeneous_mu");
    if (j.contains("level_factor")) s.level_factor = positive("level_factor");  // since 2026-12-02
    const auto count = [&](const nlohmann::json& v, const char* what, int64_t most) {
      if (!v.is_number_integer() || v.get<int64_t>() < 0 || v.get<int64_t>() > most)
        throw corrupt(fmt::format("{} must be a whole number within 0..{}, got {}", what, most, v.dump()));
      return v.get<int64_t>();
    };
    s.iteration = int(count(j.at("iteration"), "iteration", INT_MAX));
    s.solves = count(j.at("solves"), "solves", INT64_MAX);
    s.seconds = j.at("seconds").get<double>();
    if (!(s.seconds >= 0 && std::isfinite(s.seconds))) throw corrupt("seconds must be finite and >= 0");
    const nlohmann::json& history = j.at("history");
    if (!history.is_array()) throw corrupt("history must be a list");
    for (size_t r = 0; r < history.size(); ++r) {
      const nlohmann::json& h = history[r];
      // 6 since validation (2026-12-02): the validation error, -1 where not checked.
      bool numbers = h.is_array() && (h.size() == 5 || h.size() == 6);
      for (size_t k = 0; numbers && k < h.size(); ++k) numbers = h[k].is_number();
      if (!numbers) throw corrupt(fmt::format("history row {} must be 5 or 6 numbers", r));
      s.history.push_back({int(count(h[0], "a history row's iteration", INT_MAX)), h[1].get<double>(),
                           h[2].get<double>(), count(h[3], "a history row's solves", INT64_MAX),
                           h[4].get<double>(), h.size() == 6 ? h[5].get<double>() : -1.0});
    }
    if (j.contains("validation")) {
      const nlohmann::json& v = j.at("validation");
      s.best_iteration = int(count(v.at("best_iteration"), "validation best_iteration", s.iteration));
      s.best_validation_error = v.at("best_error").get<double>();
      s.least_validation_error = v.at("least_error").get<double>();
      if (!(s.best_validation_error >= 0 && std::isfinite(s.best_validation_error)))
        throw corrupt("validation best_error must be finite and >= 0");
      if (!(s.least_validation_error >= 0 && s.least_validation_error <= s.best_validation_error))
        throw corrupt("validation least_error must be within 0..best_error");
      s.best_x = v.at("best_x").get<std::vector<double>>();
      if (s.best_x.size() != s.x.size()) throw corrupt("validation best_x has the wrong number of parameters");
    }
  } catch (const nlohmann::json::exception& e) {
    throw corrupt(e.what());
  }
  // The parameters are log kappa and log mu: the material they make must be valid.
  if (std::string err = MaterialFromState(d, s).Validate(); !err.empty()) throw corrupt("parameters: " + err);
  if (!s.best_x.empty()) {
    RecoveryState best = s;
    best.x = s.best_x;
    if (std::string err = MaterialFromState(d, best).Validate(); !err.empty())
      throw corrupt("validation best_x: " + err);
  }
  return s;
}

}  // namespace translume
