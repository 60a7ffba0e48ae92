// Writing meshes as VTK XML UnstructuredGrid (.vtu), appended raw binary.
#pragma once

#include <cstddef>
#include <functional>
#include <string>

#include "mesh/mesh.h"

namespace hpray {

/// `s` with & < > " ' replaced by XML entities (for attribute values).
std::string XmlEscape(const std::string& s);

/// Writes `mesh` as a .vtu (VTK file version 2.2, appended raw binary, UInt64 header,
/// Float64 points and fields, Int64 connectivity/offsets, UInt8 types). Each cell is
/// written as the VTK type it was read with (`mesh.vtkType`, VtkTypeToWrite of
/// io/vtk_cells.h), so ParaView and VisIt show the input's types; cells of unknown type
/// as VTK_TETRA, VTK_HEXAHEDRON, VTK_WEDGE, VTK_PYRAMID (10, 12, 13, 14) when linear,
/// else as VTK 71-74 (Lagrange) or 25-27 (serendipity). Nodes are in the VTK order of the
/// type written (the inverse of the reading permutation), so the file reads back into
/// the same internal cells. HigherOrderDegrees (every cell's order, three times) is
/// written when a cell is of a Lagrange type 71-74, or always with `alwaysWriteDegrees`
/// (for pieces of one .pvtu that declares it).
/// `mesh.ghost`, when non-empty, is written as the cell array vtkGhostType (UInt8).
/// The file is written to `path + ".tmp"` and renamed, so readers never see a partial
/// file. `written`, when given, sees every byte of the file, in order, as it is written
/// (to checksum it without reading it back). Throws InputError(path) if it cannot be
/// written.
void WriteVtu(
    const std::string& path, const Mesh& mesh, bool alwaysWriteDegrees = false,
    const std::function<void(const char* data, std::size_t bytes)>& written = {});

}  // namespace hpray
