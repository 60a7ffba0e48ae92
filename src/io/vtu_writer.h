// Writing meshes as VTK XML UnstructuredGrid (.vtu), appended raw binary.
#pragma once

#include <string>

#include "mesh/mesh.h"

namespace hpray {

/// `s` with & < > " ' replaced by XML entities (for attribute values).
std::string XmlEscape(const std::string& s);

/// Writes `mesh` as a .vtu (VTK file version 2.2, appended raw binary, UInt64 header,
/// Float64 points and fields, Int64 connectivity/offsets, UInt8 types). Lagrange cells are
/// written as VTK 71-74 (with HigherOrderDegrees), serendipity cells as VTK 25-27, linear
/// cells as 71-74 of order 1 as well, so the file reads back into the same internal order;
/// except linear pyramids, written as VTK_PYRAMID (14), which VTK 9.1 can read (it has no
/// class for 74) and whose node order is that of 74 of order 1.
/// `mesh.ghost`, when non-empty, is written as the cell array vtkGhostType (UInt8).
/// The file is written to `path + ".tmp"` and renamed, so readers never see a partial file.
/// Throws InputError(path) if it cannot be written.
void WriteVtu(const std::string& path, const Mesh& mesh);

}  // namespace hpray
