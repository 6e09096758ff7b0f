// SPDX-License-Identifier: MIT
// Internal to the gl code (solver/gl_*.cc, render/gl_*.cc): the dispatch profiler that
// TRANSLUME_GL_PROFILE switches on, shared by the solver's and the renderer's dispatches.
#pragma once

#include <chrono>
#include <cstdint>
#include <deque>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "solver/gl_api.h"

namespace translume::gl {

// TRANSLUME_GL_PROFILE selects how dispatches are timed; at exit stderr gets, per key (the
// shader, or what the caller passes), the dispatches and their seconds, largest first:
//   1    each dispatch between two glFinish calls, on the host's clock: what a dispatch costs
//        alone, its launch latency and the finish's wait included (serialises the queue);
//   2    the same, keyed per shader, defines, threads and fields (the solver's detail);
//   gpu  GL_TIMESTAMP queries just before and after each dispatch and no finishes: a
//        timestamp is taken once every earlier command has completed, so each dispatch's
//        interval is its own execution in the stream, its launch gap included. Results are
//        collected as they become available (every 128 dispatches, without waiting; the host
//        waits only when 4096 are outstanding, and at exit), so the queue stays full;
//   gpu2 the same, keyed as 2.
// The table prints when the process exits normally (the profiler's static destructor, which
// reads the last timestamps from the GL context of the exiting thread).
// Use: if (Profiler::Get().on()) around each dispatch: Before(), DispatchCompute, After(key).
class Profiler {
 public:
  // The process's profiler. Call it first after the GL context exists (from the dispatch
  // code), so that it is destroyed, and prints, while the context is still usable.
  static Profiler& Get();
  bool on() const { return on_; }
  bool detailed() const { return detailed_; }
  void Before();
  void After(const std::string& key);
  ~Profiler();

 private:
  Profiler();
  // Reads the oldest pending timestamps: those available, or with `wait` all of them.
  void ReadTimestamps(bool wait);

  bool on_ = false, detailed_ = false, gpu_ = false;
  std::chrono::steady_clock::time_point t0_;
  std::map<std::string, std::pair<int64_t, double>> by_key_;  // dispatches, seconds
  struct Pending {
    std::string key;
    GLuint before, after;
  };
  std::deque<Pending> pending_;
  std::vector<GLuint> idle_queries_;
};

}  // namespace translume::gl
