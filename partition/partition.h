// k-d decomposition of a mesh into load-balanced bricks (hpray partition): writing a
// partition directory out of core, reading it back, and ordering its bricks for a camera.
//
// Partition directory (docs/contracts.md): brick-NNNN.vtu (one VTU piece
// per k-d leaf, appended raw, points renumbered), bricks.pvtu (indexes the pieces) and
// manifest.json, written last. Decisions this implementation documents:
//  - Cell centroid: the arithmetic mean of the cell's nodes. The owner of a cell is the
//  leaf
//    containing its centroid, where a centroid on a split plane belongs to the high side
//    (low child: x[axis] < split, high child: x[axis] >= split) unless the node carries
//    a tie-break (KdNode::tieBreak, GoesLow) dividing the centroids on the plane.
//  - A cell is stored in every brick whose closed leaf box intersects the cell's
//  guaranteed
//    geometry box (exact vertex bounds for order-1 cells, the Bernstein hull of
//    elements/bounds.h GeometryBox otherwise), with vtkGhostType = 1 everywhere but in
//    its owner brick. So each brick holds every cell that can reach into its box.
//  - Root box: the union of those geometry boxes. For a mesh of order-1 cells it is
//    exactly the bounds of the points; for curved cells it also covers their bulges
//    beyond the nodes (the Bernstein hull is conservative, so it may exceed the true
//    extent by the hull's slack but never misses any part of a cell). Leaf boxes tile the
//    root box under the ownership rule of geom/box.h (half-open at split planes).
//  - "cost" of a brick is the estimated render cost of the cells it owns (the quantity
//  the
//    splits balance); "cost_with_ghosts" adds the replicated cells.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "geom/kd_tree.h"
#include "io/mesh_io.h"
#include "mesh/mesh.h"

namespace hpray::partition {

struct PartitionOptions {
    int bricks = 1;
    std::string outDir;
    /// Bytes the process may hold (inputs, spills, one brick). 0: a quarter of the
    /// physical memory.
    std::size_t memoryLimitBytes = 0;
    /// Fields to keep (point or cell arrays; a component name selects its array);
    /// std::nullopt keeps every field.
    std::optional<std::vector<std::string>> fields;
    /// Write into a folder that holds other files too (otherwise an input error).
    bool force = false;
};

/// What PartitionMesh did (for logs and benchmarks).
struct PartitionReport {
    std::int64_t inputCells = 0;
    std::int64_t inputPoints = 0;
    std::int64_t storedCells = 0;  ///< sum over bricks, ghosts included
    std::uint64_t bytesWritten = 0;
    double balance = 0;  ///< max / mean owned cost
    double seconds = 0;
    bool streamed = false;  ///< false: the input format was read whole
};

/// Partitions `meshPath` into options.bricks bricks under options.outDir. Streams the
/// input (see vtu_stream.h), keeps at most options.memoryLimitBytes of data in memory and
/// spills to a temporary folder inside outDir. Every file is written to a temporary name
/// and renamed; manifest.json comes last. A run first removes the manifest, then any
/// bricks, index and spills a previous (possibly interrupted) run left, so a rerun starts
/// clean and never mixes runs; a lock file keeps two runs from writing one folder at
/// once. Throws InputError for bad input or options (bricks < 1 or more than the cells,
/// a brick that does not fit the memory limit).
PartitionReport PartitionMesh(const std::string& meshPath,
                              const PartitionOptions& options);

/// Parses a memory size: "4096", "512K", "64M", "1.5G", "2T" (binary units, an optional
/// trailing "B" or "iB"). Throws InputError("command line", "--memory-limit", ...) for
/// anything else or a size below 4 MiB.
std::size_t ParseMemorySize(const std::string& text);

/// A quarter of the physical memory, in bytes.
std::size_t DefaultMemoryLimit();

/// Whether the cell of centroid `x` belongs to the low child of inner node `node` (the
/// plane, then the node's tie-break; see KdNode). A partition's k-d tree numbers its
/// leaves by brick.
inline bool GoesLow(const KdNode& node, const double x[3]) {
    const double v = x[node.axis];
    if (v != node.split || !node.tieBreak) return v < node.split;
    const double y = x[(node.axis + 1) % 3], z = x[(node.axis + 2) % 3];
    return y < node.tie[0] || (y == node.tie[0] && z < node.tie[1]);
}

/// One brick of a partition as the manifest describes it.
struct BrickInfo {
    std::string file;  ///< file name inside the partition directory
    Box box;           ///< the leaf's region, with the ownership rule's open faces
    std::int64_t cells = 0;   ///< all cells in the file, ghosts included
    std::int64_t ghosts = 0;  ///< cells with vtkGhostType = 1
    double cost = 0;          ///< estimated render cost of the owned cells
    /// Guaranteed [min, max] over all cells of the brick, per field name (vector fields:
    /// "name" is the magnitude, "name[i]" component i).
    std::map<std::string, std::array<double, 2>> ranges;
    std::string sha256;       ///< hex digest of the file
    std::uint64_t bytes = 0;  ///< file size
};

/// A partition directory read back; nodes[0] is the root of the k-d tree.
struct Partition {
    std::string dir;
    KdTree tree;  ///< leaves numbered by brick; tree.box is the root box
    std::vector<BrickInfo> bricks;
    nlohmann::json manifest;  ///< the whole manifest (fields, statistics, ...)

    std::string BrickPath(int brick) const;
};

/// True when `path` is a folder holding a manifest.json.
bool IsPartitionDirectory(const std::string& path);

/// Reads and validates DIR/manifest.json: schema, tree (every brick exactly once, leaf
/// boxes equal to the boxes the splits carve out of the root box), and every brick file
/// present with the size the manifest records. Throws InputError naming the manifest and
/// the key (e.g. "bricks[3].sha256") or the missing file.
Partition ReadPartition(const std::string& dir);

/// Checks the SHA-256 of brick `brick` against the manifest; throws InputError naming
/// the file on a mismatch or read error.
void VerifyBrick(const Partition& partition, int brick);

/// Verifies the checksum, then reads brick `brick` (only the requested fields) and checks
/// its cell and ghost counts against the manifest. Throws InputError on any mismatch.
Mesh LoadBrick(const Partition& partition, int brick, const ReadOptions& options = {});

/// The summary `hpray info DIR --json` prints: bricks, cells (stored, owned, ghosts),
/// ghost_fraction, balance (max / mean cost), bytes, root box, fields, tree depth,
/// checksums_ok (every brick verified). Throws InputError for a broken partition.
nlohmann::json SummarizePartition(const std::string& dir);

/// The same summary as text, one item per line.
std::string FormatPartitionSummary(const nlohmann::json& summary);

/// SHA-256 of a file as 64 lowercase hex digits. Throws InputError(path) if unreadable.
std::string FileSha256(const std::string& path);

/// SHA-256 of bytes given piece by piece (the same digest as FileSha256 of a file of
/// those bytes).
class Sha256 {
  public:
    Sha256();
    ~Sha256();
    Sha256(const Sha256&) = delete;
    Sha256& operator=(const Sha256&) = delete;
    void Update(const void* data, std::size_t bytes);
    /// The digest of everything given, as 64 lowercase hex digits; once.
    std::string HexDigest();

  private:
    void* context_ = nullptr;  ///< the OpenSSL digest context
};

}  // namespace hpray::partition
