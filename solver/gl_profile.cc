// SPDX-License-Identifier: MIT
#include "solver/gl_profile.h"

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <iterator>

namespace translume::gl {

namespace {
constexpr size_t kReadEvery = 128;    // dispatches between two collections of the timestamps
constexpr size_t kMostPending = 4096;  // beyond this many, a collection waits for them
}

Profiler& Profiler::Get() {
  static Profiler profiler;
  return profiler;
}

Profiler::Profiler() {
  const char* env = std::getenv("TRANSLUME_GL_PROFILE");
  const std::string v = env ? env : "";
  on_ = !v.empty() && v != "0";
  gpu_ = v == "gpu" || v == "gpu2";
  detailed_ = v == "2" || v == "gpu2";
}

void Profiler::Before() {
  if (gpu_) {
    if (idle_queries_.size() < 2) {
      GLuint q[2 * kReadEvery];
      api.GenQueries(GLsizei(std::size(q)), q);
      idle_queries_.insert(idle_queries_.end(), q, q + std::size(q));
    }
    pending_.push_back({"", idle_queries_.back(), idle_queries_[idle_queries_.size() - 2]});
    idle_queries_.resize(idle_queries_.size() - 2);
    api.QueryCounter(pending_.back().before, GL_TIMESTAMP);
    return;
  }
  api.Finish();  // earlier work (uploads, copies, other dispatches) is not this dispatch's
  t0_ = std::chrono::steady_clock::now();
}

void Profiler::After(const std::string& key) {
  if (gpu_) {
    pending_.back().key = key;
    api.QueryCounter(pending_.back().after, GL_TIMESTAMP);
    if (pending_.size() % kReadEvery == 0) ReadTimestamps(pending_.size() >= kMostPending);
    return;
  }
  api.Finish();
  auto& [count, seconds] = by_key_[key];
  ++count;
  seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0_).count();
}

void Profiler::ReadTimestamps(bool wait) {
  while (!pending_.empty()) {
    const Pending& p = pending_.front();
    if (!wait) {
      GLuint64 ready = 0;  // the later query ready: the earlier one too
      api.GetQueryObjectui64v(p.after, GL_QUERY_RESULT_AVAILABLE, &ready);
      if (!ready) return;
    }
    GLuint64 t0 = 0, t1 = 0;
    api.GetQueryObjectui64v(p.before, GL_QUERY_RESULT, &t0);
    api.GetQueryObjectui64v(p.after, GL_QUERY_RESULT, &t1);
    auto& [count, seconds] = by_key_[p.key];
    ++count;
    seconds += 1e-9 * double(t1 - t0);
    idle_queries_.push_back(p.before);
    idle_queries_.push_back(p.after);
    pending_.pop_front();
  }
}

Profiler::~Profiler() {
  if (!on()) return;
  ReadTimestamps(true);
  std::vector<std::pair<std::string, std::pair<int64_t, double>>> rows(by_key_.begin(), by_key_.end());
  std::sort(rows.begin(), rows.end(), [](auto& a, auto& b) { return a.second.second > b.second.second; });
  std::fprintf(stderr, "gl profile (%s):\n",
               gpu_ ? "GPU timestamps around each dispatch, no finishes"
                                   : "host clock, a finish before and after each dispatch");
  for (const auto& [key, v] : rows)
    std::fprintf(stderr, "gl profile: %-28s %9lld dispatches %9.4f s %8.1f us each\n", key.c_str(),
                 (long long)v.first, v.second, 1e6 * v.second / double(std::max<int64_t>(v.first, 1)));
}

}  // namespace translume::gl
