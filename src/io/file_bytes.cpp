// Whole input files and positions in them (see file_bytes.h).
#include "io/file_bytes.h"

#include <algorithm>
#include <cerrno>
#include <cstdint>
#include <cstring>
#include <fstream>

#include "util/error.h"

namespace hpray {

std::string ReadWholeFile(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in)
        throw InputError(path, "", std::string("cannot open: ") + std::strerror(errno));
    in.seekg(0, std::ios::end);
    const std::streamoff size = in.tellg();
    if (size < 0) throw InputError(path, "", "cannot determine the file size");
    std::string data(static_cast<std::size_t>(size), '\0');
    in.seekg(0, std::ios::beg);
    if (size > 0 && !in.read(data.data(), size)) throw InputError(path, "", "read error");
    return data;
}

bool HostIsBigEndian() {
    const std::uint16_t one = 1;
    std::uint8_t first;
    std::memcpy(&first, &one, 1);
    return first == 0;
}

std::string ByteOrLineWhere(const std::string& bytes, std::size_t pos, bool binary) {
    if (binary) return "byte " + std::to_string(pos);
    const std::size_t end = std::min(pos, bytes.size());
    return "line " +
           std::to_string(1 + std::count(bytes.begin(), bytes.begin() + end, '\n'));
}

}  // namespace hpray
