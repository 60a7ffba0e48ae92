// Streaming a mesh into a sink cell by cell: .vtu with appended raw or zlib data and
// .pvtu of such pieces in bounded memory; any other input read whole and replayed.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "io/mesh_io.h"
#include "mesh/cell.h"

namespace hpray::partition {

/// A field as streamed: its name and the number of components per point or cell.
struct StreamField {
    std::string name;
    int components = 1;
};

/// Receives a mesh in input order. Points are numbered globally (pieces of a .pvtu
/// follow each other); every point a cell refers to has been delivered before the cell.
class MeshSink {
  public:
    virtual ~MeshSink() = default;
    /// Called once, before any data: the selected point and cell fields (the same set for
    /// every piece).
    virtual void Fields(const std::vector<StreamField>& pointFields,
                        const std::vector<StreamField>& cellFields) = 0;
    /// `count` consecutive points: `xyz` 3 * count coordinates (world units); `values`
    /// count * (sum of point field components), the fields of one point interleaved in
    /// the order of Fields().
    virtual void Points(std::int64_t count, const double* xyz, const double* values) = 0;
    /// One 3-D cell, nodes in internal order as global point indices; `values` the sum
    /// of cell field components, in the order of Fields(); `vtkType` the VTK cell type it
    /// was read as (Mesh::vtkType; 0 = unknown), so the bricks can keep it.
    virtual void Cell(CellShape shape, int order, CellFamily family,
                      const std::int64_t* nodes, int nodeCount, const double* values,
                      std::uint8_t vtkType) = 0;
};

/// Statistics of one streaming pass.
struct StreamStats {
    bool streamed = false;  ///< false: the input was read whole (other formats)
    std::int64_t points = 0;
    std::int64_t cells = 0;          ///< 3-D cells delivered
    std::int64_t skippedCells = 0;   ///< lower-dimensional cells and input ghost cells
    std::size_t wholeMeshBytes = 0;  ///< memory of the whole mesh when read whole
};

/// Streams `path` into `sink`. .vtu files whose arrays are all appended raw (optionally
/// zlib-compressed) and .pvtu files of such pieces are decoded block by block, holding
/// about `bufferBytes` per open array; anything else (ASCII, inline or base64 data,
/// legacy .vtk, gmsh, builtin:) is read whole with ReadMesh and replayed. Cells flagged
/// as duplicates in an input vtkGhostType (bit 1) are skipped, so a partition's own
/// bricks.pvtu can be partitioned again. Throws InputError naming the file and position.
StreamStats StreamMesh(const std::string& path, const ReadOptions& options,
                       std::size_t bufferBytes, MeshSink& sink);

}  // namespace hpray::partition
