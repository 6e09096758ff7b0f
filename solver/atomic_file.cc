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
    std::error_code ignored;
    fs::remove_all(tmp, ignored);
    throw;
  }
  fs::rename(tmp, target, ec);
  if (ec) {
    const std::string why = fs::is_directory(target) ? "it is a folder" : ec.message();
    std::error_code ignored;
    fs::remove_all(tmp, ignored);
    throw InputError(fmt::format("{}: cannot write: {}", path, why));
  }
}

void WriteFolderAtomically(const std::string& path,
                           const std::function<void(const std::string&)>& write) {
  namespace fs = std::filesystem;
  fs::path dir = fs::absolute(path).lexically_normal();
  if (dir.filename().empty()) dir = dir.parent_path();  // "out/" names "out"
  const std::string name = dir.filename().string();
  const fs::path tmp = dir.parent_path() / fmt::format(".{}.tmp{}", name, getpid());
  const fs::path old = dir.parent_path() / fmt::format(".{}.old{}", name, getpid());
  std::error_code ec;
  fs::remove_all(tmp, ec);
  try {
    fs::create_directories(tmp);
    write(tmp.string());
  } catch (...) {
    fs::remove_all(tmp, ec);
    throw;
  }
  if (fs::exists(dir)) {
    fs::rename(dir, old, ec);
    if (ec) {
      const std::string why = ec.message();
      fs::remove_all(tmp, ec);
      throw InputError(fmt::format("{}: cannot replace the folder: {}", path, why));
    }
  }
  fs::rename(tmp, dir, ec);
  if (ec) {
    const std::string why = ec.message();
    if (fs::exists(old)) fs::rename(old, dir, ec);
    fs::remove_all(tmp, ec);
    throw InputError(fmt::format("{}: cannot write the folder: {}", path, why));
  }
  fs::remove_all(old, ec);
}

}  // namespace translume
