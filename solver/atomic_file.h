// SPDX-License-Identifier: MIT
#pragma once

#include <functional>
#include <string>

namespace translume {

// Calls write(tmp) with a temporary path in the same folder as `path`, then renames tmp to
// path. If write throws, the temporary file is removed and the exception propagates, so the
// destination is either the complete new file or untouched. Creates missing parent folders.
void WriteAtomically(const std::string& path, const std::function<void(const std::string&)>& write);

}  // namespace translume
