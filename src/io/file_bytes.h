// Whole input files in memory, positions in them for error messages, host byte order.
#pragma once

#include <cstddef>
#include <string>

namespace hpray {

/// The bytes of `path`. Throws InputError(path) if it cannot be opened or read.
std::string ReadWholeFile(const std::string& path);

/// Whether this machine stores multi-byte numbers most significant byte first.
bool HostIsBigEndian();

/// Where `pos` lies in `bytes`: "byte N" in binary data, "line N" (1-based) in text.
std::string ByteOrLineWhere(const std::string& bytes, std::size_t pos, bool binary);

}  // namespace hpray
