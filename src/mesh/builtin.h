// Built-in data sets generated in memory: builtin:NAME[?key=value&...].
#pragma once

#include <string>
#include <vector>

#include "mesh/mesh.h"

namespace hpray {

/// Builds a built-in data set. Names (see README "Built-in data sets"):
///   nk-sinc[?order=8]      Nelson & Kirby example 1, 5x5x5 uneven hexes on [0,1]^3
///   nk-quartic[?order=8]   Nelson & Kirby example 2, 8 non-rectangular hexes
///   ball-p2[?n=4]          straight quadratic tets on [-1,1]^3, u = x^2 + y^2 + z^2, v = x
///   cube-tets-N            5 N^3 linear tets on [0,1]^3, u = x + 2y + 3z
/// Every builtin names its scalar field `u`. Throws InputError("builtin:...") for an
/// unknown name or parameter.
Mesh MakeBuiltin(const std::string& spec);

/// The names accepted by MakeBuiltin (for help texts and suggestions).
std::vector<std::string> BuiltinNames();

}  // namespace hpray
