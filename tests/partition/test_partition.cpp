// Partition library: streamed input equals the whole-file reader, balance for any N,
// ownership and ghost coverage against an independent cell model, manifest validation,
// checksums, and the front-to-back order of bricks.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <set>

#include "cost_model.h"
#include "io/mesh_io.h"
#include "io/raw_vtu.h"
#include "io/vtu_writer.h"
#include "kd_tree.h"
#include "mesh/builtin.h"
#include "partition.h"
#include "partition_test_util.h"
#include "renumber.h"
#include "spill.h"
#include "util/error.h"
#include "vtu_stream.h"

namespace hpray {
namespace {

using partition::Partition;
using test::ScratchDir;

const std::string kData = HPRAY_SHARED_DATA;

/// Collects a streamed mesh back into a Mesh.
class CollectSink : public partition::MeshSink {
  public:
    void Fields(const std::vector<partition::StreamField>& pf,
                const std::vector<partition::StreamField>& cf) override {
        pointFields = pf;
        cellFields = cf;
        for (const auto& f : pf) pointComps += f.components;
        for (const auto& f : cf) cellComps += f.components;
    }
    void Points(std::int64_t count, const double* xyz, const double* values) override {
        mesh.points.insert(mesh.points.end(), xyz, xyz + 3 * count);
        pointValues.insert(pointValues.end(), values, values + count * pointComps);
    }
    void Cell(CellShape shape, int order, CellFamily family, const std::int64_t* nodes,
              int count, const double* values, std::uint8_t vtkType) override {
        mesh.AddCell(shape, order, family, nodes, count);
        mesh.vtkType.push_back(vtkType);
        cellValues.insert(cellValues.end(), values, values + cellComps);
    }
    Mesh mesh;
    std::vector<partition::StreamField> pointFields, cellFields;
    int pointComps = 0, cellComps = 0;
    std::vector<double> pointValues, cellValues;
};

/// Streams `path` with a small buffer and compares everything with ReadMesh.
void ExpectStreamEqualsRead(const std::string& path, bool expectStreamed) {
    SCOPED_TRACE(path);
    const Mesh ref = ReadMesh(path);
    CollectSink sink;
    const auto stats = partition::StreamMesh(path, {}, 4096, sink);
    EXPECT_EQ(stats.streamed, expectStreamed);
    EXPECT_EQ(stats.cells, ref.CellCount());
    EXPECT_EQ(sink.mesh.points, ref.points);
    EXPECT_EQ(sink.mesh.connectivity, ref.connectivity);
    EXPECT_EQ(sink.mesh.cellOffsets, ref.cellOffsets);
    EXPECT_EQ(sink.mesh.cellShape, ref.cellShape);
    EXPECT_EQ(sink.mesh.cellOrder, ref.cellOrder);
    EXPECT_EQ(sink.mesh.vtkType, ref.vtkType);
    ASSERT_EQ(sink.pointFields.size(), ref.pointFields.size());
    int offset = 0;
    for (const auto& f : sink.pointFields) {
        const Field* r = ref.FindPointField(f.name);
        ASSERT_NE(r, nullptr) << f.name;
        ASSERT_EQ(r->components, f.components);
        for (std::int64_t p = 0; p < ref.PointCount(); ++p)
            for (int k = 0; k < f.components; ++k)
                ASSERT_EQ(sink.pointValues[p * sink.pointComps + offset + k],
                          r->values[p * f.components + k])
                    << f.name << " point " << p;
        offset += f.components;
    }
    offset = 0;
    for (const auto& f : sink.cellFields) {
        const Field* r = ref.FindCellField(f.name);
        ASSERT_NE(r, nullptr) << f.name;
        for (std::int64_t c = 0; c < ref.CellCount(); ++c)
            for (int k = 0; k < f.components; ++k)
                ASSERT_EQ(sink.cellValues[c * sink.cellComps + offset + k],
                          r->values[c * f.components + k]);
        offset += f.components;
    }
}

TEST(VtuStream, EqualsTheWholeFileReader) {
    // appended raw + zlib UInt32 header; raw uncompressed; zlib UInt64 header (four
    // linear types interleaved); Float32 points with Int32 connectivity.
    ExpectStreamEqualsRead(kData + "/gmsh_boolean_tet_p4.vtu", true);
    ExpectStreamEqualsRead(kData + "/mfem_toroid_wedge_p3.vtu", true);
    ExpectStreamEqualsRead(kData + "/mfem_fichera_mixed16_linear.vtu", true);
    // Inline data (ASCII, base64 + zlib) is read whole and replayed.
    ExpectStreamEqualsRead(kData + "/mfem_spiral_hex_p9.vtu", false);
    ExpectStreamEqualsRead(kData + "/dealii_step44_hex_q2.vtu", false);
}

TEST(VtuStream, PvtuPiecesAndFieldSelection) {
    ScratchDir dir("vtu_stream");
    // Two pieces of a builtin written by the project's writer, indexed by a .pvtu.
    const Mesh whole = MakeBuiltin("builtin:cube-tets-3");
    Mesh a, b;
    for (Mesh* m : {&a, &b}) *m = whole;
    WriteVtu(dir / "a.vtu", a);
    WriteVtu(dir / "b.vtu", b);
    std::ofstream(dir / "both.pvtu")
        << "<?xml version=\"1.0\"?>\n<VTKFile type=\"PUnstructuredGrid\" "
           "version=\"2.2\">\n"
           "<PUnstructuredGrid GhostLevel=\"0\"><PPoints><PDataArray type=\"Float64\" "
           "NumberOfComponents=\"3\"/></PPoints>\n<Piece Source=\"a.vtu\"/><Piece "
           "Source=\"b.vtu\"/></PUnstructuredGrid></VTKFile>\n";
    ExpectStreamEqualsRead(dir / "both.pvtu", true);

    ReadOptions only;
    only.fields = std::set<std::string>{"u"};
    CollectSink sink;
    partition::StreamMesh(kData + "/mfem_escher_tet_p3.vtu", only, 1 << 16, sink);
    ASSERT_EQ(sink.pointFields.size(), 1u);
    EXPECT_EQ(sink.pointFields[0].name, "u");
    EXPECT_TRUE(sink.cellFields.empty());
    only.fields = std::set<std::string>{"nope"};
    EXPECT_THROW(
        partition::StreamMesh(kData + "/mfem_escher_tet_p3.vtu", only, 1 << 16, sink),
        InputError);
}

TEST(VtuStream, GhostCopiesInPiecesAreSkipped) {
    // A partition's bricks.pvtu streamed back (pieces of thousands of cells, ghost copies
    // interleaved with owned cells, read in batches of offsets, types and ghost flags):
    // exactly the cells of the original mesh, each once.
    ScratchDir dir("vtu_stream_ghosts");
    const std::string path = kData + "/mfem_fichera_mixed16_linear.vtu";
    partition::PartitionOptions o;
    o.bricks = 5;
    o.outDir = dir / "p";
    partition::PartitionMesh(path, o);
    const Mesh ref = ReadMesh(path);
    CollectSink sink;
    const auto stats = partition::StreamMesh(o.outDir + "/bricks.pvtu", {}, 4096, sink);
    EXPECT_GT(stats.skippedCells, 0);
    std::multiset<test::CellKey> want, got;
    for (std::int64_t c = 0; c < ref.CellCount(); ++c) want.insert(test::KeyOf(ref, c));
    for (std::int64_t c = 0; c < sink.mesh.CellCount(); ++c)
        got.insert(test::KeyOf(sink.mesh, c));
    EXPECT_EQ(sink.mesh.CellCount(), ref.CellCount());
    EXPECT_TRUE(got == want);
}

TEST(VtuStream, TruncatedFileIsAnInputError) {
    ScratchDir dir("vtu_stream_trunc");
    std::ifstream in(kData + "/mfem_toroid_wedge_p3.vtu", std::ios::binary);
    std::string bytes((std::istreambuf_iterator<char>(in)),
                      std::istreambuf_iterator<char>());
    std::ofstream(dir / "cut.vtu", std::ios::binary)
        << bytes.substr(0, bytes.size() * 2 / 3);
    CollectSink sink;
    try {
        partition::StreamMesh(dir / "cut.vtu", {}, 4096, sink);
        FAIL() << "no error";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("cut.vtu"), std::string::npos) << e.what();
    }
}

/// The cost model's estimate for cell c of `mesh` in a partition of root box `root`.
double ModelCost(const Mesh& mesh, std::int64_t c, const Box& root) {
    std::vector<double> xyz;
    for (std::int64_t k = mesh.cellOffsets[c]; k < mesh.cellOffsets[c + 1]; ++k)
        for (int d = 0; d < 3; ++d) xyz.push_back(mesh.points[3 * mesh.connectivity[k] + d]);
    const partition::CellCostInput cost = partition::CellCostFromNodes(
        mesh.cellShape[c], mesh.cellOrder[c], mesh.cellFamily[c], xyz.data());
    const double diagonal = std::hypot(root.hi[0] - root.lo[0], root.hi[1] - root.lo[1],
                                       root.hi[2] - root.lo[2]);
    return partition::CellRenderSeconds(cost.parts, cost.area, diagonal);
}

/// Balance of a partition computed independently: each cell's owner found by walking the
/// manifest's tree with the cell's centroid, costs from the cost model.
double IndependentBalance(const Mesh& mesh, const Partition& p) {
    std::vector<double> cost(p.bricks.size(), 0.0);
    for (std::int64_t c = 0; c < mesh.CellCount(); ++c) {
        const auto x = test::Centroid(mesh, c);
        const std::vector<KdNode>& nodes = p.tree.nodes;
        int n = p.tree.root;
        while (nodes[n].axis >= 0) {
            // The documented rule: low when x[axis] < split; on the plane, by the
            // tie-break on the next two coordinates when the node has one.
            const auto& node = nodes[n];
            const int a = node.axis;
            bool low = x[a] < node.split;
            if (x[a] == node.split && node.tieBreak) {
                const double y = x[(a + 1) % 3], z = x[(a + 2) % 3];
                low = y < node.tie[0] || (y == node.tie[0] && z < node.tie[1]);
            }
            n = low ? node.low : node.high;
        }
        cost[nodes[n].leaf] += ModelCost(mesh, c, p.tree.box);
    }
    double sum = 0, max = 0;
    for (double v : cost) {
        sum += v;
        max = std::max(max, v);
    }
    return max / (sum / cost.size());
}

TEST(Partition, BalancedForEveryBrickCountUpTo64) {
    // Curved order-3 tets of varying size: 21,504 cells, 336 per brick at 64.
    const std::string path = kData + "/mfem_escher_tet_p3.vtu";
    const Mesh mesh = ReadMesh(path);
    ScratchDir dir("partition_balance");
    for (int n = 2; n <= 64; ++n) {
        partition::PartitionOptions o;
        o.bricks = n;
        o.outDir = dir / "p";
        o.fields = std::vector<std::string>{"u"};
        partition::PartitionMesh(path, o);
        const Partition p = partition::ReadPartition(o.outDir);
        ASSERT_EQ(static_cast<int>(p.bricks.size()), n);
        const double balance = IndependentBalance(mesh, p);
        EXPECT_LE(balance, 1.05) << n << " bricks";
        // The manifest reports the same owned costs.
        double max = 0, sum = 0;
        for (const auto& b : p.bricks) {
            max = std::max(max, b.cost);
            sum += b.cost;
        }
        EXPECT_NEAR(max / (sum / n), balance, 1e-9) << n;
    }
}

TEST(Partition, BalancedOnTheLargeMeshAndMixedCosts) {
    // 1.25M tets; and the mixed linear mesh, whose four cell types cost differently.
    for (const auto& [file, counts] :
         std::vector<std::pair<std::string, std::vector<int>>>{
             {"mfem_gmsh_t16_tets_1M.vtu", {3, 12, 64}},
             {"mfem_fichera_mixed16_linear.vtu", {5, 7, 33}}}) {
        const std::string path = kData + "/" + file;
        const Mesh mesh = ReadMesh(path, ReadOptions{std::set<std::string>{"u"}});
        ScratchDir dir("partition_large");
        for (int n : counts) {
            partition::PartitionOptions o;
            o.bricks = n;
            o.outDir = dir / "p";
            o.fields = std::vector<std::string>{"u"};
            o.memoryLimitBytes = std::size_t(256) << 20;
            partition::PartitionMesh(path, o);
            const Partition p = partition::ReadPartition(o.outDir);
            EXPECT_LE(IndependentBalance(mesh, p), 1.05) << file << " " << n;
        }
    }
}

/// The invariants of a partition of `path`: every input cell owned by exactly one brick
/// (the leaf containing its centroid), present in exactly the bricks whose closed box
/// meets its guaranteed geometry box, fields copied, ranges containing the nodal values,
/// leaf boxes tiling the root box, which is exactly the mesh bounds for linear meshes.
void ExpectValidPartition(const std::string& path, const std::string& dir) {
    SCOPED_TRACE(path);
    const Mesh mesh = ReadMesh(path);
    const Partition p = partition::ReadPartition(dir);
    std::map<test::CellKey, std::int64_t> index;
    for (std::int64_t c = 0; c < mesh.CellCount(); ++c)
        index.emplace(test::KeyOf(mesh, c), c);
    ASSERT_EQ(static_cast<std::int64_t>(index.size()), mesh.CellCount());

    std::vector<int> owners(mesh.CellCount(), 0);
    std::vector<std::set<int>> holders(mesh.CellCount());
    for (int b = 0; b < static_cast<int>(p.bricks.size()); ++b) {
        const Mesh brick = partition::LoadBrick(p, b);
        ASSERT_EQ(brick.ghost.size(), static_cast<std::size_t>(brick.CellCount()));
        for (std::int64_t c = 0; c < brick.CellCount(); ++c) {
            const auto it = index.find(test::KeyOf(brick, c));
            ASSERT_NE(it, index.end())
                << "brick " << b << " cell " << c << " is not an input cell";
            const std::int64_t id = it->second;
            EXPECT_TRUE(holders[id].insert(b).second)
                << "cell " << id << " twice in brick " << b;
            if (brick.ghost[c] == 0) {
                ++owners[id];
                // The owner's box contains the centroid.
                const auto x = test::Centroid(mesh, id);
                for (int d = 0; d < 3; ++d) {
                    EXPECT_GE(x[d], p.bricks[b].box.lo[d]);
                    EXPECT_LE(x[d], p.bricks[b].box.hi[d]);
                }
            } else {
                EXPECT_EQ(brick.ghost[c], 1);
            }
            // Point fields copied with their nodes; ranges contain the nodal values.
            for (const Field& f : brick.pointFields) {
                const Field* r = mesh.FindPointField(f.name);
                ASSERT_NE(r, nullptr);
                for (int k = 0; k < brick.CellNodeCount(c); ++k) {
                    const std::int64_t bp = brick.CellNodes(c)[k];
                    const std::int64_t mp = mesh.CellNodes(id)[k];
                    for (int q = 0; q < f.components; ++q)
                        ASSERT_EQ(f.values[bp * f.components + q],
                                  r->values[mp * f.components + q]);
                    if (f.components == 1) {
                        const auto& range = p.bricks[b].ranges.at(f.name);
                        EXPECT_GE(f.values[bp], range[0]);
                        EXPECT_LE(f.values[bp], range[1]);
                    }
                }
            }
        }
    }
    for (std::int64_t c = 0; c < mesh.CellCount(); ++c) {
        EXPECT_EQ(owners[c], 1) << "cell " << c;
        // Ghosts exactly cover each leaf box.
        const Box box = test::CellBox(mesh, c);
        std::set<int> expected;
        for (int b = 0; b < static_cast<int>(p.bricks.size()); ++b) {
            bool meets = true;
            for (int d = 0; d < 3; ++d)
                meets &= box.lo[d] <= p.bricks[b].box.hi[d] &&
                         box.hi[d] >= p.bricks[b].box.lo[d];
            if (meets) expected.insert(b);
        }
        EXPECT_EQ(holders[c], expected) << "cell " << c;
    }
    // Leaf boxes tile the root box: volumes add up and interiors are disjoint.
    double volume = 0;
    auto vol = [](const Box& b) {
        return (b.hi[0] - b.lo[0]) * (b.hi[1] - b.lo[1]) * (b.hi[2] - b.lo[2]);
    };
    for (std::size_t i = 0; i < p.bricks.size(); ++i) {
        volume += vol(p.bricks[i].box);
        for (int d = 0; d < 3; ++d) {
            EXPECT_GE(p.bricks[i].box.lo[d], p.tree.box.lo[d]);
            EXPECT_LE(p.bricks[i].box.hi[d], p.tree.box.hi[d]);
        }
        for (std::size_t j = i + 1; j < p.bricks.size(); ++j) {
            bool overlap = true;
            for (int d = 0; d < 3; ++d)
                overlap &= p.bricks[i].box.lo[d] < p.bricks[j].box.hi[d] &&
                           p.bricks[j].box.lo[d] < p.bricks[i].box.hi[d];
            EXPECT_FALSE(overlap) << i << " " << j;
        }
    }
    EXPECT_NEAR(volume, vol(p.tree.box), 1e-12 * vol(p.tree.box));
    // Root box: the union of the guaranteed cell boxes.
    Box all = test::CellBox(mesh, 0);
    for (std::int64_t c = 1; c < mesh.CellCount(); ++c) {
        const Box b = test::CellBox(mesh, c);
        for (int d = 0; d < 3; ++d) {
            all.lo[d] = std::min(all.lo[d], b.lo[d]);
            all.hi[d] = std::max(all.hi[d], b.hi[d]);
        }
    }
    EXPECT_EQ(p.tree.box.lo, all.lo);
    EXPECT_EQ(p.tree.box.hi, all.hi);
}

TEST(Partition, OwnershipGhostsAndBoxesOnLinearAndCurvedMeshes) {
    ScratchDir dir("partition_valid");
    struct Case {
        std::string file;
        int bricks;
    };
    for (const Case& c :
         {Case{"mfem_fichera_mixed16_linear.vtu", 7}, Case{"gmsh_boolean_tet_p4.vtu", 5},
          Case{"mfem_fichera_mixed_p3.vtu", 12}, Case{"mfem_toroid_hex_p3.vtu", 3}}) {
        partition::PartitionOptions o;
        o.bricks = c.bricks;
        o.outDir = dir / c.file;
        partition::PartitionMesh(kData + "/" + c.file, o);
        ExpectValidPartition(kData + "/" + c.file, o.outDir);
    }
    // Linear mesh: the root box is exactly the bounds of the points.
    const Mesh linear = ReadMesh(kData + "/mfem_fichera_mixed16_linear.vtu");
    const Partition p = partition::ReadPartition(dir / "mfem_fichera_mixed16_linear.vtu");
    const auto bounds = linear.Bounds();
    EXPECT_EQ(p.tree.box.lo, bounds.lo);
    EXPECT_EQ(p.tree.box.hi, bounds.hi);
    // Curved mesh: cells bulge beyond their nodes; the root box covers the hulls.
    const Mesh curved = ReadMesh(kData + "/gmsh_boolean_tet_p4.vtu");
    const Partition q = partition::ReadPartition(dir / "gmsh_boolean_tet_p4.vtu");
    for (int d = 0; d < 3; ++d) {
        EXPECT_LE(q.tree.box.lo[d], curved.Bounds().lo[d]);
        EXPECT_GE(q.tree.box.hi[d], curved.Bounds().hi[d]);
    }
}

/// One pass over `pts` in blocks of `block` centroids (every block, whatever the
/// filter).
partition::CentroidPass PassOver(const std::vector<partition::WeightedPoint>& pts,
                                 std::size_t block) {
    return [&pts, block](const auto& /*wanted*/, const auto& visit) {
        for (std::size_t i = 0; i < pts.size(); i += block)
            visit(pts.data() + i, std::min(block, pts.size() - i));
    };
}

/// A pass over `pts` that leaves out the blocks of `blocks` the filter rejects (as the
/// partitioner's pass does), adding the centroids it visits to `visited`.
partition::CentroidPass FilteredPassOver(const std::vector<partition::WeightedPoint>& pts,
                                         const partition::CentroidBlocks& blocks,
                                         std::int64_t& visited) {
    return [&pts, &blocks, &visited](const partition::BlockFilter& wanted,
                                     const auto& visit) {
        for (std::size_t b = 0; b < blocks.Blocks(); ++b) {
            if (wanted && !wanted(blocks.BlockBox(b))) continue;
            const std::size_t first = b << blocks.Shift();
            const std::size_t count =
                std::min(std::size_t(1) << blocks.Shift(), pts.size() - first);
            visit(pts.data() + first, count);
            visited += static_cast<std::int64_t>(count);
        }
    };
}

/// The box [0, side]^3.
Box CubeBox(double side) {
    Box b;
    b.lo = {0, 0, 0};
    b.hi = {side, side, side};
    return b;
}

/// A mesh of ../shared/data and a number of bricks for it.
struct MeshCase {
    std::string file;
    int bricks;
};
/// Linear tets, hexes, wedges and pyramids; curved order-4 tets.
const MeshCase kMixedAndCurved[] = {{"mfem_fichera_mixed16_linear.vtu", 7},
                                    {"gmsh_boolean_tet_p4.vtu", 5}};

TEST(Partition, SmallestMemoryLimitGivesValidPartitionsAndTheSameBricks) {
    // At 4M the point caches of the scan and of the distribution (which recomputes the
    // boxes of order-1 cells from their nodes) evict blocks, the scan's batches are
    // small, and bricks are written one at a time or while the next is assembled
    // depending on their sizes: the partition must still satisfy every invariant against
    // the independent cell model, and equal, file for file, the one made with a limit
    // large enough to hold everything.
    ScratchDir dir("partition_small_limit");
    for (const MeshCase& c : kMixedAndCurved) {
        std::vector<std::string> sums[2];
        for (int small = 0; small < 2; ++small) {
            partition::PartitionOptions o;
            o.bricks = c.bricks;
            o.outDir = dir / (c.file + std::to_string(small));
            o.memoryLimitBytes = small ? std::size_t(4) << 20 : std::size_t(2) << 30;
            partition::PartitionMesh(kData + "/" + c.file, o);
            if (small) ExpectValidPartition(kData + "/" + c.file, o.outDir);
            for (const auto& b : partition::ReadPartition(o.outDir).bricks)
                sums[small].push_back(b.sha256);
        }
        EXPECT_EQ(sums[0], sums[1]) << c.file;
    }
}

TEST(Partition, TreeAndOwnedCostsEqualTheCostModelCellByCell) {
    // Each cell's cost is rebuilt from spilled parts (the per-segment part per cell, the
    // setup part from runs of equal values): on a mesh of four cell types and a curved
    // one (curved and affine cells of one type cost differently), at a limit that holds
    // everything and at the smallest one, the tree must be the one built from the cost
    // model's own estimates in input order, and each brick's owned cost their sum.
    ScratchDir dir("partition_costs");
    for (const MeshCase& c : kMixedAndCurved) {
        const std::string path = kData + "/" + c.file;
        const Mesh mesh = ReadMesh(path);
        for (const std::size_t limit : {std::size_t(4) << 20, std::size_t(256) << 20}) {
            SCOPED_TRACE(c.file + " " + std::to_string(limit >> 20) + "M");
            partition::PartitionOptions o;
            o.bricks = c.bricks;
            o.outDir = dir / "p";
            o.memoryLimitBytes = limit;
            partition::PartitionMesh(path, o);
            const Partition p = partition::ReadPartition(o.outDir);
            // The centroids as the scan computes them: the mean of the nodes, clamped to
            // their bounds.
            std::vector<partition::WeightedPoint> pts(mesh.CellCount());
            for (std::int64_t k = 0; k < mesh.CellCount(); ++k) {
                const auto x = test::Centroid(mesh, k);
                for (int d = 0; d < 3; ++d) {
                    double lo = 1e300, hi = -1e300;
                    for (int j = 0; j < mesh.CellNodeCount(k); ++j) {
                        const double v = mesh.points[3 * mesh.CellNodes(k)[j] + d];
                        lo = std::min(lo, v);
                        hi = std::max(hi, v);
                    }
                    pts[k].x[d] = std::clamp(x[d], lo, hi);
                }
                pts[k].cost = ModelCost(mesh, k, p.tree.box);
            }
            const partition::CentroidPass pass = PassOver(pts, 65536);
            const std::size_t collectLimit = std::clamp<std::size_t>(
                limit / 8 / 16 / static_cast<std::size_t>(c.bricks), 256,
                std::size_t(1) << 20);
            const KdTree tree =
                partition::BuildKdTree(p.tree.box, c.bricks, pass, collectLimit);
            // The same tree, node for node from the roots (the manifest numbers its nodes
            // in its own order).
            ASSERT_EQ(tree.nodes.size(), p.tree.nodes.size());
            std::vector<std::pair<int, int>> stack{{tree.root, p.tree.root}};
            while (!stack.empty()) {
                const auto [i, j] = stack.back();
                stack.pop_back();
                const KdNode &a = tree.nodes[i], &b = p.tree.nodes[j];
                ASSERT_EQ(a.axis, b.axis) << "node " << i;
                EXPECT_EQ(a.leaf, b.leaf) << "node " << i;
                if (a.axis < 0) continue;
                EXPECT_EQ(a.split, b.split) << "node " << i;
                EXPECT_EQ(a.tieBreak, b.tieBreak) << "node " << i;
                if (a.tieBreak && b.tieBreak) {
                    EXPECT_EQ(a.tie, b.tie) << "node " << i;
                }
                stack.push_back({a.low, b.low});
                stack.push_back({a.high, b.high});
            }
            std::vector<double> owned(p.bricks.size(), 0.0);
            for (const auto& w : pts) owned[partition::OwnerBrick(p.tree, w.x)] += w.cost;
            for (std::size_t b = 0; b < p.bricks.size(); ++b)
                EXPECT_EQ(p.bricks[b].cost, owned[b]) << "brick " << b;
        }
    }
}

/// The VTK cell types of a partition's bricks as their files store them (the raw
/// `types` and `vtkGhostType` arrays, decoded without hpray's reader).
struct BrickTypes {
    std::map<int, std::int64_t> owned;  ///< cells with vtkGhostType 0, per VTK type
    std::set<int> all;                  ///< every type in a brick, ghosts included
    int bricksWithDegrees = 0;          ///< bricks with a HigherOrderDegrees array
};

BrickTypes RawBrickTypes(const Partition& p) {
    BrickTypes t;
    for (int b = 0; b < static_cast<int>(p.bricks.size()); ++b) {
        const test::RawVtu raw(p.BrickPath(b));
        const auto types = raw.Values<std::uint8_t>("Cells", "types");
        const auto ghost = raw.Values<std::uint8_t>("CellData", "vtkGhostType");
        EXPECT_EQ(static_cast<std::int64_t>(types.size()), raw.Cells());
        EXPECT_EQ(ghost.size(), types.size());
        for (std::size_t c = 0; c < types.size() && c < ghost.size(); ++c) {
            t.all.insert(types[c]);
            if (ghost[c] == 0) ++t.owned[types[c]];
        }
        t.bricksWithDegrees += raw.Has("CellData", "HigherOrderDegrees");
    }
    return t;
}

/// Whether the partition's bricks.pvtu declares a HigherOrderDegrees cell array.
bool PvtuDeclaresDegrees(const std::string& dir) {
    std::ifstream in(dir + "/bricks.pvtu");
    const std::string text((std::istreambuf_iterator<char>(in)),
                           std::istreambuf_iterator<char>());
    EXPECT_FALSE(text.empty());
    return text.find("Name=\"HigherOrderDegrees\"") != std::string::npos;
}

TEST(Partition, BricksKeepTheInputCellTypes) {
    ScratchDir dir("partition_types");
    struct Case {
        std::string path;
        int bricks;
        std::map<int, std::int64_t> types;  ///< the input's 3-D cells per VTK type
        bool degrees;                       ///< some type needs HigherOrderDegrees
    };
    const std::string kTestData = HPRAY_TEST_DATA;
    const std::vector<Case> cases = {
        // The four linear types interleaved (appended raw + zlib, streamed): VTK_TETRA,
        // VTK_HEXAHEDRON, VTK_WEDGE, VTK_PYRAMID, not their Lagrange equivalents.
        {kData + "/mfem_fichera_mixed16_linear.vtu",
         5,
         {{10, 50400}, {12, 4096}, {13, 24576}, {14, 11664}},
         false},
        // VTK_QUADRATIC_TETRA (ASCII, read whole and replayed).
        {kData + "/mfem_escher_quadtet_p2.vtu", 3, {{24, 42}}, false},
        // Gmsh has no VTK types: tet10 -> 24, prism18 -> 73, pyramid14 -> 74.
        {kData + "/gmsh_pripyrtet_p2.msh", 4, {{24, 12}, {73, 135}, {74, 15}}, true},
        // Every 3-D type of a legacy file (lines and triangles dropped), voxel included.
        {kTestData + "/legacy_binary_51.vtk",
         2,
         {{10, 1},
          {11, 1},
          {12, 1},
          {13, 1},
          {14, 1},
          {24, 1},
          {25, 1},
          {26, 1},
          {27, 1},
          {29, 1},
          {32, 1},
          {71, 1},
          {72, 1},
          {73, 1}},
         true},
        // Meshes built in memory: linear tets as VTK_TETRA.
        {"builtin:cube-tets-4", 3, {{10, 5 * 4 * 4 * 4}}, false},
    };
    for (const Case& c : cases) {
        SCOPED_TRACE(c.path);
        partition::PartitionOptions o;
        o.bricks = c.bricks;
        o.outDir = dir / std::to_string(&c - cases.data());
        partition::PartitionMesh(c.path, o);
        const Partition p = partition::ReadPartition(o.outDir);
        const BrickTypes t = RawBrickTypes(p);
        EXPECT_EQ(t.owned, c.types);
        for (int type : t.all) EXPECT_EQ(c.types.count(type), 1u) << "type " << type;
        // HigherOrderDegrees in every brick or in none, as bricks.pvtu declares it.
        EXPECT_EQ(t.bricksWithDegrees, c.degrees ? c.bricks : 0);
        EXPECT_EQ(PvtuDeclaresDegrees(o.outDir), c.degrees);
        // hpray reads the bricks back into the input's cells (ownership, ghosts, nodes
        // in internal order with their coordinates).
        if (c.path.rfind("builtin:", 0) != 0) ExpectValidPartition(c.path, o.outDir);
    }
}

TEST(Partition, BrickRangesBoundTheTrueFieldInsideCurvedCells) {
    // Sample the true (order-4) field inside every cell of every brick at random points.
    ScratchDir dir("partition_ranges");
    partition::PartitionOptions o;
    o.bricks = 4;
    o.outDir = dir / "p";
    o.fields = std::vector<std::string>{"analytic"};
    partition::PartitionMesh(kData + "/gmsh_boolean_tet_p4.vtu", o);
    const Partition p = partition::ReadPartition(o.outDir);
    std::mt19937 rng(3);
    std::uniform_real_distribution<double> u(0, 1);
    std::vector<double> values(kMaxBasisNodes);
    for (int b = 0; b < 4; ++b) {
        const Mesh brick = partition::LoadBrick(p, b);
        ASSERT_EQ(brick.pointFields.size(), 1u);
        const auto range = p.bricks[b].ranges.at("analytic");
        for (std::int64_t c = 0; c < brick.CellCount(); ++c) {
            const BasisTable& basis = GetBasis(brick.cellShape[c], brick.cellOrder[c]);
            for (int s = 0; s < 10; ++s) {
                double r[3] = {u(rng), u(rng), u(rng)};
                const double sum = r[0] + r[1] + r[2];
                if (sum > 1)
                    for (double& v : r) v /= sum + 1e-9;
                EvalBasis(basis, r, values.data(), nullptr);
                double f = 0;
                for (int m = 0; m < basis.nodeCount; ++m)
                    f += values[m] * brick.pointFields[0].values[brick.CellNodes(c)[m]];
                EXPECT_GE(f, range[0] - 1e-12);
                EXPECT_LE(f, range[1] + 1e-12);
            }
        }
    }
}

TEST(Partition, TreeBuilderBalancesTiesAndAnyLeafCount) {
    // Centroids on a coarse lattice (many equal coordinates) with unequal costs: splits
    // are chosen between distinct coordinates; costs in proportion to the leaf counts.
    std::vector<partition::WeightedPoint> pts;
    std::mt19937 rng(7);
    for (int i = 0; i < 40000; ++i)
        pts.push_back({{static_cast<double>(rng() % 97), static_cast<double>(rng() % 89),
                        static_cast<double>(rng() % 83)},
                       1.0 + (rng() % 4)});
    const partition::CentroidPass pass = PassOver(pts, 1000);
    Box root;
    root.lo = {0, 0, 0};
    root.hi = {96, 88, 82};
    for (int n : {1, 2, 3, 5, 7, 12, 17, 31, 64}) {
        for (std::size_t limit : {std::size_t(64), std::size_t(1) << 20}) {
            const auto nodes = partition::BuildKdTree(root, n, pass, limit);
            std::vector<double> cost(n, 0.0);
            for (const auto& p : pts) cost[partition::OwnerBrick(nodes, p.x)] += p.cost;
            double sum = 0, max = 0;
            for (double v : cost) {
                sum += v;
                max = std::max(max, v);
            }
            EXPECT_LE(max / (sum / n), 1.05) << n << " leaves, collect limit " << limit;
            // Each subtree's cost is close to its share by leaf count.
            EXPECT_EQ(static_cast<int>(nodes.nodes.size()), 2 * n - 1);
        }
    }
}

TEST(Partition, TreeBuilderSplitEqualsTheExactWeightedMedian) {
    // Two leaves over distinct random coordinates with random costs: the histogram
    // rounds (1024 bins, narrowed until a bin holds at most `limit` centroids) and the
    // exact selection must divide the centroids where a sort of all of them does: after
    // the first coordinate whose cumulative cost is closest to half the total (the plane
    // lies between that coordinate and the next, or the histogram bin's edge).
    std::mt19937 rng(17);
    std::uniform_real_distribution<double> u(0.0, 40.0), w(0.1, 3.0);
    for (int trial = 0; trial < 4; ++trial) {
        std::vector<partition::WeightedPoint> pts;
        const int n = trial == 0 ? 1000 : 150000;
        // Clustered coordinates in some trials: bins of very unequal counts.
        for (int i = 0; i < n; ++i) {
            const double x = trial == 3 ? 20.0 + std::pow(u(rng) / 40.0, 9.0) : u(rng);
            pts.push_back({{x, u(rng), u(rng) * 0.5}, w(rng)});
        }
        std::vector<std::pair<double, double>> sorted;
        double total = 0;
        for (const auto& p : pts) {
            sorted.push_back({p.x[0], p.cost});
            total += p.cost;
        }
        std::sort(sorted.begin(), sorted.end());
        const double target = total / 2;
        double best = std::abs(0 - target), cum = 0;
        std::size_t lowCount = 0;
        for (std::size_t i = 0; i < sorted.size(); ++i) {
            cum += sorted[i].second;
            if (std::abs(cum - target) < best) {
                best = std::abs(cum - target);
                lowCount = i + 1;
            }
        }
        const partition::CentroidPass pass = PassOver(pts, 65536);
        const Box root = CubeBox(40);
        for (const std::size_t limit :
             {std::size_t(64), std::size_t(4096), std::size_t(1) << 20}) {
            const KdTree tree = partition::BuildKdTree(root, 2, pass, limit);
            const KdNode& r = tree.nodes[tree.root];
            EXPECT_EQ(r.axis, 0) << trial << " " << limit;
            const auto low = std::count_if(
                pts.begin(), pts.end(), [&](const auto& p) { return p.x[0] < r.split; });
            EXPECT_EQ(static_cast<std::size_t>(low), lowCount) << trial << " " << limit;
            EXPECT_FALSE(r.tieBreak) << trial << " " << limit;
        }
    }
}

TEST(Partition, TreeBuilderGivesTheSameTreeOnOneThreadAndMany) {
    // Centroids on a coarse lattice (equal coordinates, tie-breaks, bins of one
    // coordinate) and scattered ones, in blocks large enough to be routed by several
    // tasks: the sums are taken in the points' order, so the tree is the same.
    std::vector<partition::WeightedPoint> pts;
    std::mt19937 rng(11);
    std::uniform_real_distribution<double> u(0.0, 40.0);
    for (int i = 0; i < 200000; ++i) {
        if (i % 3 == 0)
            pts.push_back({{u(rng), u(rng), u(rng)}, 0.5 + (rng() % 7)});
        else
            pts.push_back({{static_cast<double>(rng() % 41), static_cast<double>(rng() % 7),
                            static_cast<double>(rng() % 5)},
                           1.0 + (rng() % 3) * 0.1});
    }
    const partition::CentroidPass pass = PassOver(pts, 65536);
    const Box root = CubeBox(40);
    for (int n : {2, 7, 32, 64}) {
        for (std::size_t limit : {std::size_t(64), std::size_t(4096), std::size_t(1) << 20}) {
            KdTree one;
            {
                tbb::global_control c(tbb::global_control::max_allowed_parallelism, 1);
                one = partition::BuildKdTree(root, n, pass, limit);
            }
            const KdTree many = partition::BuildKdTree(root, n, pass, limit);
            ASSERT_EQ(one.nodes.size(), many.nodes.size());
            for (std::size_t k = 0; k < one.nodes.size(); ++k) {
                const KdNode &a = one.nodes[k], &b = many.nodes[k];
                EXPECT_EQ(a.axis, b.axis) << n << " " << limit << " node " << k;
                EXPECT_EQ(a.split, b.split) << n << " " << limit << " node " << k;
                EXPECT_EQ(a.tieBreak, b.tieBreak) << n << " " << limit << " node " << k;
                EXPECT_EQ(a.tie, b.tie) << n << " " << limit << " node " << k;
                EXPECT_EQ(a.leaf, b.leaf) << n << " " << limit << " node " << k;
            }
        }
    }
}

TEST(Partition, TreeBuilderSkipsBlocksOutsideTheSearchedSlabs) {
    // Centroids in the order of a structured mesh (neighbours close to each other, ties
    // on lattice planes in y and z, scattered in x) and in random order, with unequal
    // costs. After the first pass of a level, a pass may leave out the blocks whose boxes
    // miss every slab still searched: the tree is the same as with every pass over all
    // centroids, and with spatially ordered centroids far fewer are visited.
    std::mt19937 rng(23);
    for (const bool ordered : {true, false}) {
        std::vector<partition::WeightedPoint> pts;
        for (int i = 0; i < 60; ++i)
            for (int j = 0; j < 50; ++j)
                for (int k = 0; k < 40; ++k) {
                    const double jitter = (rng() % 1000) * 0.0009;
                    pts.push_back({{i + jitter, j + 0.5, k + (i % 2) * 0.5},
                                   1.0 + (rng() % 5) * 0.25});
                }
        if (!ordered) std::shuffle(pts.begin(), pts.end(), rng);
        // Small boxes memory: blocks merge while they are added.
        partition::CentroidBlocks blocks(std::size_t(24) << 7);
        for (const auto& p : pts) blocks.Add(p.x);
        EXPECT_GT(blocks.Shift(), 6);
        Box root;
        root.lo = {0, 0.5, 0};
        root.hi = {59.9, 49.5, 39.5};
        for (int n : {2, 5, 16, 33}) {
            for (std::size_t limit : {std::size_t(64), std::size_t(4096)}) {
                std::int64_t all = 0, some = 0;
                const partition::CentroidPass full = [&](const partition::BlockFilter&,
                                                         const auto& visit) {
                    PassOver(pts, 4096)(nullptr, visit);
                    all += static_cast<std::int64_t>(pts.size());
                };
                const KdTree a = partition::BuildKdTree(root, n, full, limit);
                const KdTree b = partition::BuildKdTree(
                    root, n, FilteredPassOver(pts, blocks, some), limit);
                ASSERT_EQ(a.nodes.size(), b.nodes.size());
                for (std::size_t k = 0; k < a.nodes.size(); ++k) {
                    EXPECT_EQ(a.nodes[k].axis, b.nodes[k].axis) << n << " node " << k;
                    EXPECT_EQ(a.nodes[k].split, b.nodes[k].split) << n << " node " << k;
                    EXPECT_EQ(a.nodes[k].tieBreak, b.nodes[k].tieBreak) << n << " " << k;
                    EXPECT_EQ(a.nodes[k].tie, b.nodes[k].tie) << n << " node " << k;
                    EXPECT_EQ(a.nodes[k].leaf, b.nodes[k].leaf) << n << " node " << k;
                }
                EXPECT_LE(some, all);
                if (ordered) {
                    EXPECT_LT(some, all) << n << " leaves, " << limit;
                }
            }
        }
    }
}

TEST(Partition, CentroidBlocksHoldTheirCentroids) {
    // Boxes of 64 centroids until the memory is full, then merged pairs: every centroid
    // lies in its block's box (stored as floats rounded outwards), and the blocks cover
    // the centroids added, the last one possibly partial.
    std::mt19937_64 rng(29);
    std::uniform_real_distribution<double> u(-1e3, 1e3);
    for (const std::size_t count :
         {std::size_t(1), std::size_t(64), std::size_t(100000)}) {
        partition::CentroidBlocks blocks(std::size_t(24) * 100);
        std::vector<std::array<double, 3>> xs(count);
        for (auto& x : xs) {
            x = {u(rng), u(rng) * 1e-7, 1.0 / 3.0 + u(rng) * 1e-12};
            blocks.Add(x.data());
        }
        EXPECT_EQ(blocks.Count(), static_cast<std::int64_t>(count));
        const std::size_t per = std::size_t(1) << blocks.Shift();
        EXPECT_EQ(blocks.Blocks(), (count + per - 1) / per);
        EXPECT_LE(blocks.Blocks(), 101u);
        for (std::size_t i = 0; i < count; ++i) {
            const Box box = blocks.BlockBox(i >> blocks.Shift());
            for (int d = 0; d < 3; ++d) {
                ASSERT_LE(box.lo[d], xs[i][d]) << count << " " << i;
                ASSERT_GE(box.hi[d], xs[i][d]) << count << " " << i;
            }
        }
    }
}

TEST(Partition, SpillReaderThatReleasesReadsTheSameBytes) {
    // A spill read for the last time gives its pages back as it goes (holes punched
    // behind the reader): the bytes read are those written, across many refills, and the
    // file keeps its size but no longer its space.
    ScratchDir dir("partition_spill_release");
    const std::string path = dir / "s.bin";
    const std::int64_t count = 3 << 20;  // 24 MiB of int64
    {
        partition::SpillWriter w(path, 1 << 16);
        for (std::int64_t i = 0; i < count; ++i) {
            if (i % 3 == 0) {
                w.Write(&i, sizeof i);
            } else {
                char* out = w.Append(sizeof i);
                std::memcpy(out, &i, sizeof i);
            }
        }
    }
    {
        partition::SpillReader r(path, 1 << 20, /*release=*/true);
        for (std::int64_t i = 0; i < count; ++i) {
            std::int64_t v = -1;
            ASSERT_TRUE(r.Read(&v, sizeof v)) << i;
            ASSERT_EQ(v, i);
        }
        std::int64_t v;
        EXPECT_FALSE(r.Read(&v, sizeof v));
        EXPECT_EQ(std::filesystem::file_size(path), sizeof(std::int64_t) * count);
        struct stat st {};
        ASSERT_EQ(::stat(path.c_str(), &st), 0);
        // Where the file system has holes (ext4, xfs, tmpfs), only the last few MiB read
        // are still allocated (st_blocks counts 512-byte units).
        if (st.st_blocks * 512 <
            static_cast<std::int64_t>(sizeof(std::int64_t) * count)) {
            EXPECT_LT(st.st_blocks * 512, 8 << 20);
        }
    }
}

TEST(Partition, SpillReleaseGivesBackSpaceAndRemovesTheFile) {
    // A spill no longer read gives its space back a piece at a time (where the file
    // system has holes) and is removed with its SpillRelease.
    ScratchDir dir("partition_spill_space");
    const std::string path = dir / "s.bin";
    const std::size_t size = std::size_t(16) << 20;
    {
        partition::SpillWriter w(path, 1 << 20);
        std::vector<char> bytes(size, 'x');
        w.Write(bytes.data(), bytes.size());
    }
    auto allocated = [&] {
        struct stat st {};
        EXPECT_EQ(::stat(path.c_str(), &st), 0);
        return static_cast<std::uint64_t>(st.st_blocks) * 512;
    };
    {
        partition::SpillRelease release(path);
        const std::uint64_t before = allocated();
        release.Release(std::uint64_t(5) << 20);
        release.Release(std::uint64_t(3) << 20);
        EXPECT_EQ(std::filesystem::file_size(path), size);
        if (before >= size) {  // a file system that allocates blocks and has holes
            EXPECT_LE(allocated(), before - (std::uint64_t(8) << 20));
        }
    }
    EXPECT_FALSE(std::filesystem::exists(path));
}

TEST(Partition, Sha256OfPiecesEqualsTheFileChecksum) {
    // Bytes given in pieces of any size (empty ones too) digest as the file holding them.
    ScratchDir dir("partition_sha256");
    std::mt19937 rng(37);
    std::string bytes(3 << 20, '\0');
    for (char& c : bytes) c = static_cast<char>(rng());
    std::ofstream(dir / "f.bin", std::ios::binary) << bytes;
    partition::Sha256 sha;
    for (std::size_t at = 0; at < bytes.size();) {
        const std::size_t n = std::min<std::size_t>(rng() % 100000, bytes.size() - at);
        sha.Update(bytes.data() + at, n);
        at += n;
    }
    EXPECT_EQ(sha.HexDigest(), partition::FileSha256(dir / "f.bin"));
    partition::Sha256 empty;
    EXPECT_EQ(empty.HexDigest(),
              "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
}

TEST(Partition, RecordCacheReturnsTheStoredRecords) {
    // Records of 3, 5, 8 and 4097 doubles (blocks of 2048, 1024, 1024 and 1 records),
    // read in random order through caches that evict (the smallest holds 16 blocks) and
    // after the file grew (Invalidate): each is the record written.
    ScratchDir dir("partition_record_cache");
    std::mt19937_64 rng(3);
    for (const int stride : {3, 5, 8, 4097}) {
        const std::string path = dir / ("r" + std::to_string(stride) + ".bin");
        const std::int64_t count = stride > 100 ? 40 : 60000;
        auto value = [&](std::int64_t i, int k) { return i * 10007.0 + k; };
        auto write = [&](std::int64_t from, std::int64_t to) {
            partition::SpillWriter w(path, 1 << 16);
            std::vector<double> r(stride);
            for (std::int64_t i = from; i < to; ++i) {
                for (int k = 0; k < stride; ++k) r[k] = value(i, k);
                w.Write(r.data(), sizeof(double) * stride);
            }
        };
        { std::ofstream truncate(path, std::ios::binary | std::ios::trunc); }
        write(0, count / 2);
        for (const std::size_t cacheBytes : {std::size_t(0), std::size_t(64) << 20}) {
            partition::RecordCache cache(path, stride, cacheBytes);
            for (int round = 0; round < 2; ++round) {
                const std::int64_t n = round == 0 ? count / 2 : count;
                for (int q = 0; q < 20000; ++q) {
                    const std::int64_t i =
                        q % 3 == 0 ? q % n : static_cast<std::int64_t>(rng() % n);
                    const double* r = cache.Get(i);
                    ASSERT_EQ(r[0], value(i, 0)) << stride << " " << i;
                    ASSERT_EQ(r[stride - 1], value(i, stride - 1)) << stride << " " << i;
                }
                if (round == 0 && cacheBytes == 0) {
                    // Append the second half (SpillWriter truncates: rewrite all).
                    write(0, count);
                    cache.Invalidate();
                } else if (round == 0) {
                    cache.Invalidate();
                }
            }
        }
    }
}

TEST(Partition, PointRenumberingByBitmapEqualsSorting) {
    std::mt19937_64 rng(5);
    for (const std::int64_t span : {std::int64_t(1), std::int64_t(63), std::int64_t(64),
                                    std::int64_t(1000), std::int64_t(1) << 40}) {
        for (const std::int64_t base : {std::int64_t(0), std::int64_t(12345)}) {
            std::vector<std::int64_t> conn;
            for (int i = 0; i < 5000; ++i)
                conn.push_back(base + static_cast<std::int64_t>(
                                          rng() % static_cast<std::uint64_t>(span)));
            std::vector<std::int64_t> bitmapConn = conn, sortConn = conn, bitmapIds,
                                      sortIds;
            partition::RenumberPoints(bitmapConn, bitmapIds, std::size_t(1) << 20);
            partition::RenumberPoints(sortConn, sortIds, 0);
            EXPECT_EQ(bitmapIds, sortIds) << span << " " << base;
            EXPECT_EQ(bitmapConn, sortConn) << span << " " << base;
            for (std::size_t i = 0; i < conn.size(); ++i)
                ASSERT_EQ(sortIds[sortConn[i]], conn[i]);
            EXPECT_TRUE(std::is_sorted(sortIds.begin(), sortIds.end()));
        }
    }
    std::vector<std::int64_t> empty, ids{7};
    partition::RenumberPoints(empty, ids, 1 << 20);
    EXPECT_TRUE(ids.empty());
}

TEST(Partition, WideNodeIdsInSpillsGiveTheSameBricks) {
    // Node ids are spilled as int32 when they fit, as int64 otherwise; forcing int64
    // gives the same files.
    const std::string path = kData + "/mfem_escher_tet_p3.vtu";
    ScratchDir dir("partition_wide_ids");
    std::vector<std::string> sums[2];
    for (int wide = 0; wide < 2; ++wide) {
        if (wide)
            ::setenv("HPRAY_PARTITION_TEST_WIDE_IDS", "1", 1);
        partition::PartitionOptions o;
        o.bricks = 9;
        o.outDir = dir / ("p" + std::to_string(wide));
        try {
            partition::PartitionMesh(path, o);
        } catch (...) {
            ::unsetenv("HPRAY_PARTITION_TEST_WIDE_IDS");
            throw;
        }
        ::unsetenv("HPRAY_PARTITION_TEST_WIDE_IDS");
        for (const auto& b : partition::ReadPartition(o.outDir).bricks)
            sums[wide].push_back(b.sha256);
    }
    EXPECT_EQ(sums[0], sums[1]);
}

TEST(Partition, EscapedCellKindsInSpillsGiveTheSameBricks) {
    // Cells' fixed parts are spilled as one-byte codes of their kinds, or as escaped
    // records once the table of kinds is full: with tables of 0 or 1 kinds (all cells or
    // all but the first kind escaped, on a mesh of four cell types, owned and ghost) the
    // files are the same as with the full table.
    ScratchDir dir("partition_kind_codes");
    for (const std::string file :
         {"mfem_fichera_mixed16_linear.vtu", "gmsh_boolean_tet_p4.vtu"}) {
        std::vector<std::string> sums[3];
        for (int capacity = 0; capacity < 3; ++capacity) {
            if (capacity < 2)
                ::setenv("HPRAY_PARTITION_TEST_KIND_CODES",
                         std::to_string(capacity).c_str(), 1);
            partition::PartitionOptions o;
            o.bricks = 7;
            o.outDir = dir / (file + std::to_string(capacity));
            o.memoryLimitBytes = std::size_t(4) << 20;
            try {
                partition::PartitionMesh(kData + "/" + file, o);
            } catch (...) {
                ::unsetenv("HPRAY_PARTITION_TEST_KIND_CODES");
                throw;
            }
            ::unsetenv("HPRAY_PARTITION_TEST_KIND_CODES");
            for (const auto& b : partition::ReadPartition(o.outDir).bricks)
                sums[capacity].push_back(b.sha256);
        }
        EXPECT_EQ(sums[0], sums[2]) << file;
        EXPECT_EQ(sums[1], sums[2]) << file;
    }
    // And they satisfy every invariant against the independent cell model.
    ExpectValidPartition(kData + "/mfem_fichera_mixed16_linear.vtu",
                         dir / "mfem_fichera_mixed16_linear.vtu2");
}

/// True when boxes a and b are separated by an axis plane with `eye` on a's side (or on
/// the plane): then nothing of b can hide a from the eye.
bool SeparatedWithEyeOnSide(const Box& a, const Box& b,
                            const std::array<double, 3>& eye) {
    for (int d = 0; d < 3; ++d) {
        if (a.hi[d] <= b.lo[d] && eye[d] <= b.lo[d]) return true;
        if (b.hi[d] <= a.lo[d] && eye[d] >= b.hi[d]) return true;
    }
    return false;
}

TEST(Partition, FrontToBackOrderForAnyCamera) {
    ScratchDir dir("partition_order");
    partition::PartitionOptions o;
    o.bricks = 11;
    o.outDir = dir / "p";
    partition::PartitionMesh("builtin:cube-tets-6", o);
    const Partition p = partition::ReadPartition(o.outDir);
    std::mt19937 rng(11);
    std::uniform_real_distribution<double> u(-2, 3);
    for (int trial = 0; trial < 200; ++trial) {
        const std::array<double, 3> eye{u(rng), u(rng), u(rng)};
        const auto order = p.tree.FrontToBack(ViewOrigin::Perspective(eye));
        ASSERT_EQ(order.size(), 11u);
        EXPECT_EQ(std::set<int>(order.begin(), order.end()).size(), 11u);
        for (std::size_t i = 0; i < order.size(); ++i)
            for (std::size_t j = i + 1; j < order.size(); ++j)
                EXPECT_TRUE(SeparatedWithEyeOnSide(p.bricks[order[i]].box,
                                                   p.bricks[order[j]].box, eye))
                    << trial << ": " << order[i] << " before " << order[j];
        // Parallel rays: an eye far away against the direction gives a valid order too.
        std::array<double, 3> dir{u(rng), u(rng), u(rng)};
        const auto ortho = p.tree.FrontToBack(ViewOrigin::Orthographic(dir));
        std::array<double, 3> far;
        for (int d = 0; d < 3; ++d) far[d] = 0.5 - 1e6 * dir[d];
        for (std::size_t i = 0; i < ortho.size(); ++i)
            for (std::size_t j = i + 1; j < ortho.size(); ++j)
                EXPECT_TRUE(SeparatedWithEyeOnSide(p.bricks[ortho[i]].box,
                                                   p.bricks[ortho[j]].box, far));
    }
}

TEST(Partition, ManifestAndBrickErrorsAreInputErrors) {
    ScratchDir dir("partition_errors");
    partition::PartitionOptions o;
    o.bricks = 3;
    o.outDir = dir / "p";
    partition::PartitionMesh("builtin:cube-tets-4", o);
    Partition p = partition::ReadPartition(o.outDir);
    EXPECT_NO_THROW(partition::LoadBrick(p, 1));

    // A flipped byte inside a brick: the checksum catches it.
    const std::string brick = p.BrickPath(1);
    {
        std::fstream f(brick, std::ios::in | std::ios::out | std::ios::binary);
        f.seekg(-100, std::ios::end);
        char c;
        f.get(c);
        f.seekp(-100, std::ios::end);
        f.put(static_cast<char>(c ^ 0x5a));
    }
    try {
        partition::LoadBrick(p, 1);
        FAIL() << "no error";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("checksum"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("brick-0001.vtu"), std::string::npos);
    }
    // A missing brick.
    std::filesystem::remove(brick);
    try {
        partition::ReadPartition(o.outDir);
        FAIL() << "no error";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("missing"), std::string::npos) << e.what();
    }
    // Broken manifests name the key.
    const std::string manifest = o.outDir + "/manifest.json";
    auto rewrite = [&](const std::function<void(nlohmann::json&)>& edit) {
        nlohmann::json j = p.manifest;
        edit(j);
        std::ofstream(manifest) << j.dump();
    };
    partition::PartitionMesh("builtin:cube-tets-4", o);
    p = partition::ReadPartition(o.outDir);
    auto expectError = [&](const std::string& key) {
        try {
            partition::ReadPartition(o.outDir);
            ADD_FAILURE() << "no error for " << key;
        } catch (const InputError& e) {
            EXPECT_NE(std::string(e.what()).find(key), std::string::npos) << e.what();
        }
    };
    rewrite([](nlohmann::json& j) { j["bricks"][2]["sha256"] = "xyz"; });
    expectError("bricks[2].sha256");
    rewrite([](nlohmann::json& j) { j["bricks"][0].erase("box"); });
    expectError("bricks[0].box");
    rewrite([](nlohmann::json& j) { j["tree"]["high"] = {{"brick", 0}}; });
    expectError("tree");
    rewrite([](nlohmann::json& j) { j["tree"]["split"] = 1e9; });
    expectError("tree.split");
    rewrite([](nlohmann::json& j) { j["bricks"][1]["box"][0][0] = -5.0; });
    expectError("bricks[1].box");
    std::ofstream(manifest) << "{\"bricks\": [";
    expectError("manifest.json");
}

TEST(Partition, MemorySizes) {
    EXPECT_EQ(partition::ParseMemorySize("64M"), std::size_t(64) << 20);
    EXPECT_EQ(partition::ParseMemorySize("1.5G"), std::size_t(3) << 29);
    EXPECT_EQ(partition::ParseMemorySize("512MiB"), std::size_t(512) << 20);
    EXPECT_EQ(partition::ParseMemorySize("8388608"), std::size_t(8) << 20);
    for (const char* bad : {"", "abc", "12X", "1.2.3G", "1K", "-5G", "G"})
        EXPECT_THROW(partition::ParseMemorySize(bad), InputError) << bad;
}

}  // namespace
}  // namespace hpray
