// Atomic output files: create parent folders, write PATH.tmp, then rename to PATH.
#pragma once

#include <cstdio>
#include <filesystem>
#include <string>
#include <system_error>

#include "util/error.h"

namespace hpray::detail {

/// Creates the missing parent folders of `path` and returns the temporary name the writer
/// should write to (`path + ".tmp"`). Throws InputError(path) if a folder cannot be made.
inline std::string BeginOutputFile(const std::string& path) {
    if (path.empty()) throw InputError("output", "", "empty output path");
    const std::filesystem::path parent = std::filesystem::path(path).parent_path();
    if (!parent.empty()) {
        std::error_code ec;
        std::filesystem::create_directories(parent, ec);
        if (ec)
            throw InputError(
                path, "",
                "cannot create folder '" + parent.string() + "': " + ec.message());
    }
    return path + ".tmp";
}

/// Renames the finished temporary file onto `path` (replacing it). Throws
/// InputError(path).
inline void CommitOutputFile(const std::string& tmpPath, const std::string& path) {
    std::error_code ec;
    std::filesystem::rename(tmpPath, path, ec);
    if (ec) {
        std::filesystem::remove(tmpPath, ec);
        throw InputError(path, "", "cannot rename the temporary file: " + ec.message());
    }
}

/// Removes a temporary file left by a failed write; never throws.
inline void AbandonOutputFile(const std::string& tmpPath) noexcept {
    std::error_code ec;
    std::filesystem::remove(tmpPath, ec);
}

}  // namespace hpray::detail
