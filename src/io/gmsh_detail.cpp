// Shared MSH 4.1 parsing helpers: field selection, text numbers, messages.
#include "io/gmsh_detail.h"

#include <charconv>
#include <cstdlib>

namespace hpray::gmsh {

bool ParseUnsigned(std::string_view t, std::uint64_t& v) {
    auto [end, ec] = std::from_chars(t.data(), t.data() + t.size(), v);
    return ec == std::errc() && end == t.data() + t.size();
}

bool ParseInt(std::string_view t, long long& v) {
    auto [end, ec] = std::from_chars(t.data(), t.data() + t.size(), v);
    return ec == std::errc() && end == t.data() + t.size();
}

bool ParseDouble(std::string_view t, double& v) {
    auto [end, ec] = std::from_chars(t.data(), t.data() + t.size(), v);
    if (ec == std::errc::result_out_of_range) {
        v = std::strtod(std::string(t).c_str(), nullptr);  // subnormal or +-inf
        return true;
    }
    return ec == std::errc() && end == t.data() + t.size();
}

std::string UnsupportedTypeMessage(long long type, int nodes) {
    return "gmsh element type " + std::to_string(type) + " (" + std::to_string(nodes) +
           " nodes) is not supported: hpray reads complete Lagrange "
           "tetrahedra, hexahedra, prisms and pyramids and the "
           "20-node hex, 15-node prism and 13-node pyramid";
}

}  // namespace hpray::gmsh
