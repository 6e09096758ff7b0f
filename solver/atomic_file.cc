// SPDX-License-Identifier: MIT
#include "solver/atomic_file.h"

#include <unistd.h>

#include <filesystem>
#include <fmt/format.h>
#include <system_error>

#include "solver/status.h"

namespace translume {

void WriteAtomically(const std::string& path,
                     const std::function<void(const std::string&)>& write) {
  namespace fs = std::filesystem;
  const fs::path target(path);
  std::error_code ec;
  if (target.has_parent_path()) {
    fs::create_directories(target.parent_path(), ec);
    if (ec) throw InputError(fmt::format("{}: cannot create folder: {}", path, ec.message()));
  }
  // Keep the extension last: image and VDB writers choose the format from it.
  const std::string tmp = (target.parent_path() / fmt::format(".{}.{}.tmp{}",
      target.stem().string(), getpid(), target.extension().string())).string();
  try {
    write(tmp);
  } catch (...) {
    fs::remove(tmp, ec);
    throw;
  }
  fs::rename(tmp, target, ec);
  if (ec) {
    fs::remove(tmp, ec);
    throw InputError(fmt::format("{}: cannot write: {}", path, ec.message()));
  }
}

}  // namespace translume
