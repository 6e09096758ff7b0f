// SPDX-License-Identifier: MIT
#pragma once

#include <functional>
#include <string>

namespace translume {

// Calls write(tmp) with a temporary path in the same folder as `path`, then renames tmp to
// path. If write throws, the temporary file is removed and the exception propagates, so the
// destination is either the complete new file or untouched. Creates missing parent folders.
void WriteAtomically(const std::string& path, const std::function<void(const std::string&)>& write);

// The same for a folder: write(tmp) fills a new temporary sibling folder, which then takes the
// place of `path` (whatever was there, which the caller has decided may go, is removed after
// the swap). If write throws, or the swap fails, `path` is left as it was and the temporary
// folder is removed. Throws InputError naming `path` when the swap fails.
void WriteFolderAtomically(const std::string& path, const std::function<void(const std::string&)>& write);

}  // namespace translume
