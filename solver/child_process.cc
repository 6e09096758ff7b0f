// SPDX-License-Identifier: MIT
#include "solver/child_process.h"

#include <fcntl.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fmt/format.h>
#include <fstream>
#include <new>

#include "solver/memory.h"
#include "solver/status.h"

namespace translume {
namespace {

// The first byte of the child's answer on the pipe; the rest is the payload.
constexpr char kResult = 'R', kInputError = 'I', kOutOfMemory = 'M', kOtherError = 'E';

bool WriteAll(int fd, const char* data, size_t size) {
  while (size > 0) {
    const ssize_t n = write(fd, data, size);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return false;
    data += n;
    size -= size_t(n);
  }
  return true;
}

std::string ReadAll(int fd) {
  std::string out;
  char buffer[65536];
  for (;;) {
    const ssize_t n = read(fd, buffer, sizeof buffer);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return out;
    out.append(buffer, size_t(n));
  }
}

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
constexpr bool kLimitAddressSpace = false;
#else
constexpr bool kLimitAddressSpace = true;
#endif

void LimitAddressSpace() {
  const int64_t available = AvailableMemoryBytes();
  long pages = 0;
  std::ifstream statm("/proc/self/statm");
  if (available <= 0 || !(statm >> pages)) return;
  const rlim_t limit = rlim_t(pages) * rlim_t(sysconf(_SC_PAGESIZE)) + rlim_t(available);
  const rlimit r{limit, limit};
  setrlimit(RLIMIT_AS, &r);
}

[[noreturn]] void RunChild(const std::function<std::string()>& work, int answer_fd, int stderr_fd) {
  dup2(stderr_fd, STDERR_FILENO);
  if (kLimitAddressSpace) LimitAddressSpace();
  char kind = kResult;
  std::string payload;
  try {
    payload = work();
  } catch (const InputError& e) {
    kind = kInputError;
    payload = e.what();
  } catch (const std::bad_alloc&) {
    kind = kOutOfMemory;
    payload.clear();
  } catch (const std::exception& e) {
    kind = kOtherError;
    payload = e.what();
  }
  _exit(WriteAll(answer_fd, &kind, 1) && WriteAll(answer_fd, payload.data(), payload.size()) ? 0 : 1);
}

// The last non-empty line of the file behind `fd`, at most 200 characters.
std::string LastLine(int fd) {
  std::string text;
  lseek(fd, 0, SEEK_SET);
  text = ReadAll(fd);
  while (!text.empty() && (text.back() == '\n' || text.back() == ' ')) text.pop_back();
  const size_t start = text.find_last_of('\n');
  if (start != std::string::npos) text.erase(0, start + 1);
  if (text.size() > 200) text = text.substr(0, 200) + "...";
  return text;
}

}  // namespace

std::string RunInChildProcess(const std::function<std::string()>& work) {
  int pipe_fds[2];
  if (pipe2(pipe_fds, O_CLOEXEC) != 0)
    throw std::runtime_error(fmt::format("cannot create a pipe: {}", std::strerror(errno)));
  FILE* child_stderr = std::tmpfile();
  if (!child_stderr) {
    close(pipe_fds[0]);
    close(pipe_fds[1]);
    throw std::runtime_error(fmt::format("cannot create a temporary file: {}", std::strerror(errno)));
  }
  std::fflush(nullptr);
  const pid_t pid = fork();
  if (pid == 0) {
    close(pipe_fds[0]);
    RunChild(work, pipe_fds[1], fileno(child_stderr));
  }
  close(pipe_fds[1]);
  if (pid < 0) {
    const int err = errno;
    close(pipe_fds[0]);
    std::fclose(child_stderr);
    throw std::runtime_error(fmt::format("cannot start a child process: {}", std::strerror(err)));
  }
  std::string answer = ReadAll(pipe_fds[0]);
  close(pipe_fds[0]);
  int status = 0;
  while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  const std::string last_line = LastLine(fileno(child_stderr));
  std::fclose(child_stderr);

  const bool finished = WIFEXITED(status) && WEXITSTATUS(status) == 0 && !answer.empty();
  if (!finished) {
    std::string how = WIFSIGNALED(status)
                          ? fmt::format("was killed by signal {} ({})", WTERMSIG(status), strsignal(WTERMSIG(status)))
                          : fmt::format("exited with status {}", WEXITSTATUS(status));
    if (!last_line.empty()) how += ": " + last_line;
    throw ChildCrashed(how);
  }
  const char kind = answer[0];
  answer.erase(0, 1);
  switch (kind) {
    case kResult: return answer;
    case kInputError: throw InputError(answer);
    case kOutOfMemory: throw std::bad_alloc();
    default: throw std::runtime_error(answer);
  }
}

}  // namespace translume
