// Streaming a Gmsh MSH 4.1 file (binary or ASCII) into a MeshSink in bounded memory.
//
// The sink sees the same mesh ReadGmsh builds: points in the order of $Nodes, the 3-D
// elements in file order (nodes in internal order, io/gmsh_nodes.h), lower-dimensional
// elements skipped, and the selected $NodeData / $ElementData fields (latest time step;
// sections of one step merged, later values winning), point fields then cell fields,
// each in name order. The file is read in three passes, none holding it whole:
//  1. structure: section offsets and data headers; the node tag -> index map is built
//     from the $Nodes tags (binary coordinates and element records are skipped by size);
//  2. fields: each selected data section is read and its values written to a spill file
//     per field, one record per node (or 3-D element) in index order, through a
//     write-combining buffer; missing entries are found by a sequential check;
//  3. delivery: $Nodes and $Elements are read again and handed to the sink with the
//     field values read back sequentially.
//
// Tag -> index maps (node tags, and element tags when cell fields are selected) may be
// sparse and in any order. They are kept as runs of consecutive tags with consecutive
// indices (24 bytes per run; gmsh numbers nodes in runs, usually one per entity block or
// one in all), as long as the runs fit in `mapBytes` (64 runs always do). Beyond that
// the map moves to a table on disk with one 8-byte slot per tag of the declared range
// [minTag, maxTag] (a sparse file: only the slots written take space), read through an
// LRU block cache of `mapBytes` (at least 1 MiB). A tag range wider than 2^36 whose
// runs do not fit is an input error (renumber the mesh or raise the limit).
// Element tags are mapped only when cell fields are selected; then a tag defined twice
// among the 3-D elements is an error (ReadGmsh keeps the first).
//
// Errors name the file and the byte offset (binary) or the line (ASCII, counted only
// when an error is reported), at the same place ReadGmsh reports them.
#pragma once

#include <cstddef>
#include <string>

#include "io/mesh_io.h"
#include "vtu_stream.h"

namespace hpray::partition {

struct GmshStreamOptions {
    /// Read buffer of the file, and the buffer of each spill file.
    std::size_t bufferBytes = std::size_t(1) << 20;
    /// Memory of each tag -> index map (runs, or the table's cache); at least 1 MiB is
    /// used for a table.
    std::size_t mapBytes = std::size_t(16) << 20;
    /// An existing folder for the field and table spill files (removed when done).
    std::string spillDir;
};

/// True for a path ending in ".msh" (any case).
bool IsGmshPath(const std::string& path);

/// Streams the MSH 4.1 file `path` into `sink` (see the file comment), with the fields
/// selected by options.fields (a name that matches no field is an error, as for other
/// formats). Holds about bufferBytes * (3 + selected fields) plus two maps of mapBytes.
/// Throws InputError naming the file and the byte offset (binary) or line (ASCII).
StreamStats StreamGmsh(const std::string& path, const ReadOptions& options,
                       const GmshStreamOptions& streamOptions, MeshSink& sink);

}  // namespace hpray::partition
