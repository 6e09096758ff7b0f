// SPDX-License-Identifier: MIT
#include <algorithm>
#include <cerrno>
#include <cmath>
#include <csignal>
#include <cstdlib>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fmt/format.h>
#include <sstream>
#include <fcntl.h>
#include <unistd.h>

#include "solver/status.h"
#include "solver/threads.h"
#include "tools/commands.h"
#include "tools/recovery_flags.h"

namespace translume {
namespace {

volatile std::sig_atomic_t g_interrupted = 0;

void OnSigint(int) {
  if (g_interrupted) {
    std::signal(SIGINT, SIG_DFL);
    std::raise(SIGINT);
  }
  g_interrupted = 1;
}

}  // namespace

SigintGuard::SigintGuard() {
  g_interrupted = 0;
  previous_ = std::signal(SIGINT, OnSigint);
}

SigintGuard::~SigintGuard() { std::signal(SIGINT, previous_); }

bool SigintGuard::interrupted() const { return g_interrupted != 0; }

CLI::Validator PositiveFinite() {
  return CLI::Validator(
      [](std::string& text) -> std::string {
        char* end = nullptr;
        const double v = std::strtod(text.c_str(), &end);
        if (end == text.c_str() || *end != '\0' || !std::isfinite(v) || !(v > 0))
          return text + " is not a finite number > 0";
        return "";
      },
      "> 0");
}

void AddCommonOptions(CLI::App& app) {
  app.add_option_function<int>("--threads", [](int n) { SetNumThreads(n); },
                               "Threads to use (default: TRANSLUME_THREADS, OMP_NUM_THREADS "
                               "or all hardware threads)")
      ->check(CLI::Range(1, 4096).description("").name("1..4096"));
}

std::string Extension(const std::string& path) {
  const auto slash = path.find_last_of('/');
  const auto dot = path.rfind('.');
  if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return "";
  std::string ext = path.substr(dot);
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  return ext;
}

void RequireExtension(const std::string& path, std::initializer_list<const char*> exts,
                      const char* flag) {
  const std::string e = Extension(path);
  std::string names;
  for (const char* x : exts) {
    if (e == x) return;
    names += (names.empty() ? "" : " or ") + std::string(x);
  }
  throw InputError(fmt::format("{} {}: the output must end in {}", flag, path, names));
}

void RequireNotInput(const char* flag, const std::string& out, const std::vector<std::string>& inputs) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::path o = fs::weakly_canonical(out, ec);
  for (const std::string& in : inputs) {
    if (in.empty()) continue;
    const fs::path i = fs::weakly_canonical(in, ec);
    if (o == i) throw InputError(fmt::format("{} {}: would overwrite the input {}", flag, out, in));
    auto below = [](const fs::path& a, const fs::path& folder) {
      for (fs::path p = a.parent_path(); !p.empty() && p != p.root_path(); p = p.parent_path())
        if (p == folder) return true;
      return false;
    };
    if (fs::is_directory(i) && below(o, i))
      throw InputError(fmt::format("{} {}: would write into the input folder {}", flag, out, in));
    if (below(i, o)) throw InputError(fmt::format("{} {}: holds the input {}; choose another folder", flag, out, in));
  }
}

namespace {

// The output `path` is written into its folder (created if missing, under the nearest one that
// exists), as a temporary file or folder renamed into place: that folder must be writable.
void RequireWritableParent(const char* flag, const std::string& path) {
  namespace fs = std::filesystem;
  std::error_code ec;
  fs::path folder = fs::absolute(path, ec).parent_path();
  while (!folder.empty() && !fs::exists(folder, ec) && folder != folder.root_path()) folder = folder.parent_path();
  if (!fs::is_directory(folder, ec))
    throw InputError(fmt::format("{} {}: {} is a file, not a folder", flag, path, folder.string()));
  // A file made and removed at once: permissions alone do not tell (root, read-only mounts).
  const fs::path probe = folder / fmt::format(".translume-probe.{}", getpid());
  const int fd = open(probe.c_str(), O_CREAT | O_EXCL | O_WRONLY, 0600);
  if (fd < 0)
    throw InputError(fmt::format("{} {}: cannot write into {}: {}", flag, path, folder.string(), std::strerror(errno)));
  close(fd);
  unlink(probe.c_str());
}

}  // namespace

void RequireFilePath(const char* flag, const std::string& path) {
  if (std::filesystem::is_directory(path)) throw InputError(fmt::format("{} {}: is a folder, not a file", flag, path));
  RequireWritableParent(flag, path);
}

void RequireFolderPath(const char* flag, const std::string& path) {
  if (std::filesystem::exists(path) && !std::filesystem::is_directory(path))
    throw InputError(fmt::format("{} {}: is a file, not a folder", flag, path));
  RequireWritableParent(flag, path);
}

InputError OptionsError(const CLI::App& app, const std::string& command, const std::string& why) {
  const size_t space = why.find(' ');
  std::string flag = "--" + why.substr(0, space);
  std::replace(flag.begin(), flag.end(), '_', '-');
  if (space != std::string::npos && app.get_option_no_throw(flag) != nullptr)
    return InputError(fmt::format("{}: {}", flag, why.substr(space + 1)));
  return InputError(command + ": " + why);
}

void RequireFinitePixels(const Image& image, const std::string& what) {
  if (const std::string problem = NonFinitePixel(image); !problem.empty()) throw InputError(what + ": " + problem);
}

bool ParseOrHelp(CLI::App& app, int argc, char** argv) {
  // The arguments the parse did not take, in the order ExtrasError wants them: it lists them
  // last first (its own lists came out reversed: "synth --preset wax foo bar" said "bar foo").
  auto extras = [&app] {
    std::vector<std::string> v = app.remaining();
    std::reverse(v.begin(), v.end());
    return v;
  };
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp&) {
    std::fputs(app.help().c_str(), stdout);
    return true;
  } catch (const CLI::ExtrasError&) {
    const std::vector<std::string> v = extras();
    if (v.empty()) throw;
    throw CLI::ExtrasError(v);
  } catch (const CLI::RequiredError&) {
    // CLI11 checks required options before unknown ones: "synth --presets wax" said only that
    // --preset is required. The arguments it did not take (known by then) are the message.
    const std::vector<std::string> v = extras();
    if (v.empty()) throw;
    std::string message = CLI::ExtrasError(v).what();
    // One bare word where one required option is missing ("synth wax"): most likely its value.
    std::vector<const CLI::Option*> missing;
    for (const CLI::Option* opt : app.get_options())
      if (opt->get_required() && opt->count() == 0 && !opt->get_lnames().empty()) missing.push_back(opt);
    if (missing.size() == 1 && v.size() == 1 && v[0].rfind('-', 0) != 0)
      message += fmt::format("; did you mean --{} {}?", missing[0]->get_lnames()[0], v[0]);
    throw CLI::ExtrasError(message, CLI::ExitCodes::ExtrasError);
  }
  return false;
}

std::vector<double> ParseNumbers(const std::string& text, const char* flag, size_t n1, size_t n2) {
  std::vector<double> v;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) {
    try {
      size_t used = 0;
      v.push_back(std::stod(item, &used));
      if (used != item.size() || !std::isfinite(v.back())) throw std::invalid_argument(item);
    } catch (const std::exception&) {
      throw InputError(fmt::format("{} {}: '{}' is not a number", flag, text, item));
    }
  }
  if (v.size() != n1 && v.size() != n2)
    throw InputError(fmt::format("{} {}: expected {} comma-separated numbers", flag, text,
                                 n1 == n2 ? std::to_string(n1) : fmt::format("{} or {}", n1, n2)));
  return v;
}

void AddValidationFlags(CLI::App& app, RecoveryOptions* o) {
  app.add_option("--validation-every", o->validation_every,
                 "With validation conditions: check the fit on them every this many iterations and keep the "
                 "best iterate (0: off; docs/inverse.md, \"Validation\")")
      ->capture_default_str();
  app.add_option("--validation-patience", o->validation_patience,
                 "Stop when no iterate in this many iterations came within --validation-margin of the least "
                 "validation error")
      ->capture_default_str();
  app.add_option("--validation-margin", o->validation_margin,
                 "Validation errors within this fraction of the least count as equal; the later iterate is kept")
      ->capture_default_str();
}

void AddSolveToleranceFlag(CLI::App& app, RecoveryOptions* o) {
  app.add_option("--solve-tolerance", o->solve_tolerance,
                 "Relative residual of the fit's forward and adjoint solves (tighter costs time per iteration; "
                 "1e-8 fitted no better than 1e-6 on the benchmarks, docs/inverse.md)")
      ->capture_default_str();
}

}  // namespace translume
