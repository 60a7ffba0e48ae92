// Whole input files in memory, and positions in them for error messages.
#pragma once

#include <cstddef>
#include <string>

namespace hpray {

/// The bytes of `path`. Throws InputError(path) if it cannot be opened or read.
std::string ReadWholeFile(const std::string& path);

/// Where `pos` lies in `bytes`: "byte N" in binary data, "line N" (1-based) in text.
std::string ByteOrLineWhere(const std::string& bytes, std::size_t pos, bool binary);

}  // namespace hpray
