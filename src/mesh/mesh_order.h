// Spatial renumbering of a mesh's cells and points, so that cells near each other in
// space are near each other in memory: a ray walking from cell to neighbouring cell then
// finds its next cell's data in cache instead of main memory.
#pragma once

#include <cstdint>
#include <vector>

#include "mesh/mesh.h"

namespace hpray {

/// Renumbers the cells of `mesh` along a Morton (Z-order) curve of their centres (the
/// mean of their nodes, on a 2^11 grid over the bounds; ties keep their order) and its
/// points along the same curve by their positions. Every per-cell and per-point array
/// moves along (fields, shapes, orders, families, ghost flags, VTK types); each cell
/// keeps its nodes in their order, so every cell is the same cell. Returns the old index
/// of each new cell.
std::vector<std::int64_t> OrderSpatially(Mesh& mesh);

}  // namespace hpray
