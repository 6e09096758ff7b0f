// SPDX-License-Identifier: MIT
#pragma once

#include <CLI/CLI.hpp>
#include <string>
#include <vector>

#include "solver/image.h"
#include "solver/status.h"

namespace translume {

// Subcommands: argv[0] is the subcommand's name. Each returns the process exit status and may
// throw InputError (exit 1, one line) or CLI::Error (usage, exit 2).
int RunSynth(int argc, char** argv);
int RunForward(int argc, char** argv);
int RunInfo(int argc, char** argv);
int RunBench(int argc, char** argv);
int RunDemo(int argc, char** argv);
int RunCalibrate(int argc, char** argv);  // calibrate camera|projector|response|white
// The subcommands' names of `calibrate` and `bench`, in their help's order (error lines name them).
std::vector<std::string> CalibrateSubcommands();
std::vector<std::string> BenchSubcommands();
int RunHdr(int argc, char** argv);
int RunSimulate(int argc, char** argv);
int RunSolve(int argc, char** argv);
int RunEvaluate(int argc, char** argv);
int RunSimulateCapture(int argc, char** argv);
int RunPatterns(int argc, char** argv);
int RunAcquire(int argc, char** argv);

// `bench forward` and `bench recovery` (tools/bench_commands.cc, no file IO): each registers
// the subcommand, whose callback runs the benchmark, on a `bench` app.
void AddBenchForward(CLI::App& bench);
void AddBenchRecovery(CLI::App& bench);
void PrintBenchProgress(const std::string& line);
// `bench exposure-times` and `bench patterns` (tools/bench_capture_commands.cc; link calib and
// acquire).
void AddBenchExposureTimes(CLI::App& bench);
void AddBenchPatterns(CLI::App& bench);
int RunRender(int argc, char** argv);
int RunEdit(int argc, char** argv);

// A CLI11 check that a number is finite and > 0 (CLI::PositiveNumber's message prints the
// largest double).
CLI::Validator PositiveFinite();

// Options every subcommand takes (--threads).
void AddCommonOptions(CLI::App& app);
// The lower-case extension of `path` (".png"), or "" if it has none.
std::string Extension(const std::string& path);
// Throws InputError "FLAG PATH: the output must end in EXT" unless `path` ends in one of `exts`
// (case-insensitive).
void RequireExtension(const std::string& path, std::initializer_list<const char*> exts,
                      const char* flag);

// Throws InputError "FLAG OUT: would overwrite the input IN" when the output `out` is one of
// `inputs` (files or folders; empty ones are skipped), "... would write into the input
// folder IN" when it lies anywhere below an input folder, or "... holds the input IN" when an
// input lies below `out` (an output folder replaced whole would take it along). Paths compare
// in canonical form.
void RequireNotInput(const char* flag, const std::string& out, const std::vector<std::string>& inputs);
// Throws InputError "FLAG PATH: is a folder, not a file" when an output file's path names an
// existing folder, and "FLAG PATH: cannot write into FOLDER: ..." when the folder it would be
// written into (or the nearest existing folder above it) is not writable (checked before the
// work, so that it is not lost at the end).
void RequireFilePath(const char* flag, const std::string& path);
// The same for an output folder (written as a temporary sibling renamed into place): "FLAG PATH:
// is a file, not a folder", or the folder above it not writable.
void RequireFolderPath(const char* flag, const std::string& path);
// An options struct's Validate() message as the user typed it: "max_iterations must be >= 0" ->
// "--max-iterations: must be >= 0" where `app` has that flag, else "COMMAND: WHY".
InputError OptionsError(const CLI::App& app, const std::string& command, const std::string& why);
// Throws InputError "WHAT: pixel (X, Y) is not finite" at an image's first NaN or inf.
void RequireFinitePixels(const Image& image, const std::string& what);

// Ctrl-C as a request to stop early: while a SigintGuard lives, the first SIGINT only sets a
// flag that long-running work polls (between iterations, stages); a second one ends the
// process at once (the default action). The previous handler comes back with the guard's end.
// Exit status 130 is the shell's for a SIGINT.
class SigintGuard {
 public:
  SigintGuard();
  ~SigintGuard();
  SigintGuard(const SigintGuard&) = delete;
  SigintGuard& operator=(const SigintGuard&) = delete;
  bool interrupted() const;

 private:
  void (*previous_)(int);
};
constexpr int kInterruptedExit = 130;

// The comma-separated numbers of a flag's value, n1 or n2 of them, each finite; throws
// InputError "FLAG TEXT: ..." naming the item that is not a number, or the count expected.
std::vector<double> ParseNumbers(const std::string& text, const char* flag, size_t n1, size_t n2);

// Parses argv into app; on --help prints and returns true (caller exits 0).
bool ParseOrHelp(CLI::App& app, int argc, char** argv);

}  // namespace translume
