// Spatial renumbering of cells and points: the same cells with the same nodes and data,
// in an order whose consecutive cells are close in space.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <random>
#include <vector>

#include "mesh/builtin.h"
#include "mesh/mesh.h"
#include "mesh/mesh_order.h"

namespace hpray {
namespace {

// builtin:cube-tets-N with its cells and points shuffled, a cell field holding each
// cell's original index, a two-component point field of its position, ghost flags and
// VTK types.
Mesh ShuffledCubeTets(int n, unsigned seed) {
    const Mesh in = MakeBuiltin("builtin:cube-tets-" + std::to_string(n));
    std::mt19937_64 rng(seed);
    std::vector<std::int64_t> cellOrder(in.CellCount()), pointOf(in.PointCount());
    std::iota(cellOrder.begin(), cellOrder.end(), 0);
    std::iota(pointOf.begin(), pointOf.end(), 0);
    std::shuffle(cellOrder.begin(), cellOrder.end(), rng);
    std::shuffle(pointOf.begin(), pointOf.end(), rng);  // old point -> new point
    Mesh out;
    out.points.resize(in.points.size());
    for (std::int64_t p = 0; p < in.PointCount(); ++p)
        for (int d = 0; d < 3; ++d) out.points[3 * pointOf[p] + d] = in.points[3 * p + d];
    Field cellId{"id", Association::Cell, 1, {}};
    for (std::int64_t c : cellOrder) {
        std::vector<std::int64_t> nodes(in.CellNodes(c),
                                        in.CellNodes(c) + in.CellNodeCount(c));
        for (std::int64_t& v : nodes) v = pointOf[v];
        out.AddCell(in.cellShape[c], in.cellOrder[c], in.cellFamily[c], nodes.data(),
                    static_cast<int>(nodes.size()));
        cellId.values.push_back(double(c));
        out.ghost.push_back(c % 7 == 0 ? 1 : 0);
        out.vtkType.push_back(10);
    }
    Field xy{"xy", Association::Point, 2, {}};
    for (std::int64_t p = 0; p < out.PointCount(); ++p) {
        xy.values.push_back(out.points[3 * p]);
        xy.values.push_back(out.points[3 * p + 1]);
    }
    out.cellFields.push_back(std::move(cellId));
    out.pointFields.push_back(std::move(xy));
    return out;
}

double MeanStepBetweenConsecutiveCells(const Mesh& mesh) {
    auto centre = [&](std::int64_t c, int d) {
        double s = 0;
        for (int k = 0; k < mesh.CellNodeCount(c); ++k)
            s += mesh.points[3 * mesh.CellNodes(c)[k] + d];
        return s / mesh.CellNodeCount(c);
    };
    double sum = 0;
    for (std::int64_t c = 1; c < mesh.CellCount(); ++c) {
        double d2 = 0;
        for (int d = 0; d < 3; ++d) d2 += std::pow(centre(c, d) - centre(c - 1, d), 2);
        sum += std::sqrt(d2);
    }
    return sum / double(mesh.CellCount() - 1);
}

TEST(MeshOrder, SameCellsNodesAndDataInASpatialOrder) {
    const Mesh before = ShuffledCubeTets(12, 5);
    Mesh after = before;
    const std::vector<std::int64_t> oldOf = OrderSpatially(after);
    ASSERT_NO_THROW(after.Validate("reordered"));
    ASSERT_EQ(after.CellCount(), before.CellCount());
    ASSERT_EQ(after.PointCount(), before.PointCount());
    // A permutation of the cells.
    std::vector<std::int64_t> sorted = oldOf;
    std::sort(sorted.begin(), sorted.end());
    for (std::int64_t c = 0; c < before.CellCount(); ++c) ASSERT_EQ(sorted[c], c);
    for (std::int64_t c = 0; c < after.CellCount(); ++c) {
        const std::int64_t o = oldOf[c];
        EXPECT_EQ(after.cellShape[c], before.cellShape[o]);
        EXPECT_EQ(after.cellOrder[c], before.cellOrder[o]);
        EXPECT_EQ(after.cellFamily[c], before.cellFamily[o]);
        EXPECT_EQ(after.ghost[c], before.ghost[o]);
        EXPECT_EQ(after.vtkType[c], before.vtkType[o]);
        EXPECT_EQ(after.cellFields[0].values[c], before.cellFields[0].values[o]);
        ASSERT_EQ(after.CellNodeCount(c), before.CellNodeCount(o));
        // Node by node, in the same order: the same positions and point data.
        for (int k = 0; k < after.CellNodeCount(c); ++k) {
            const std::int64_t a = after.CellNodes(c)[k], b = before.CellNodes(o)[k];
            for (int d = 0; d < 3; ++d)
                EXPECT_EQ(after.points[3 * a + d], before.points[3 * b + d]);
            for (int q = 0; q < 2; ++q)
                EXPECT_EQ(after.pointFields[0].values[2 * a + q],
                          before.pointFields[0].values[2 * b + q]);
        }
    }
    // Consecutive cells are neighbours in space, not strangers.
    const double stepBefore = MeanStepBetweenConsecutiveCells(before);
    const double stepAfter = MeanStepBetweenConsecutiveCells(after);
    EXPECT_LT(stepAfter, stepBefore / 5) << stepBefore << " -> " << stepAfter;
    // Points too: a cell's nodes are close in index.
    auto meanSpread = [](const Mesh& m) {
        double spread = 0;
        for (std::int64_t c = 0; c < m.CellCount(); ++c) {
            const std::int64_t* n = m.CellNodes(c);
            spread += double(*std::max_element(n, n + 4) - *std::min_element(n, n + 4));
        }
        return spread / double(m.CellCount());
    };
    EXPECT_LT(meanSpread(after), meanSpread(before) / 4)
        << meanSpread(before) << " -> " << meanSpread(after);
}

// The order is the contract's, computed here the slow way: cell centres on a 2^11 grid
// over the bounds' largest extent, their Morton codes interleaved bit by bit (x lowest),
// ascending, ties in their old order. Once on the unit cube (codes over the whole grid),
// once with a point of no cell far away, which stretches the grid so that the cube's
// cells share codes, several to a grid cell.
TEST(MeshOrder, CellsFollowTheMortonCodesOfTheirCentresTiesInOldOrder) {
    for (const bool stretched : {false, true}) {
        Mesh before = ShuffledCubeTets(20, 9);
        if (stretched) {
            for (const double x : {300.0, 0.0, 0.0}) before.points.push_back(x);
            before.pointFields[0].values.push_back(300.0);
            before.pointFields[0].values.push_back(0.0);
        }
        Mesh after = before;
        const std::vector<std::int64_t> oldOf = OrderSpatially(after);
        double lo[3], hi[3];
        for (int d = 0; d < 3; ++d) {
            lo[d] = hi[d] = before.points[d];
            for (std::int64_t p = 0; p < before.PointCount(); ++p) {
                lo[d] = std::min(lo[d], before.points[3 * p + d]);
                hi[d] = std::max(hi[d], before.points[3 * p + d]);
            }
        }
        const double extent = std::max({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]});
        auto code = [&](std::int64_t c) {
            std::uint64_t grid[3];
            for (int d = 0; d < 3; ++d) {
                double s = 0;
                for (int k = 0; k < before.CellNodeCount(c); ++k)
                    s += before.points[3 * before.CellNodes(c)[k] + d];
                s /= before.CellNodeCount(c);
                grid[d] = static_cast<std::uint64_t>(
                    std::clamp((s - lo[d]) * (2047.0 / extent), 0.0, 2047.0));
            }
            std::uint64_t m = 0;
            for (int b = 0; b < 11; ++b)
                for (int d = 0; d < 3; ++d) m |= (grid[d] >> b & 1) << (3 * b + d);
            return m;
        };
        std::vector<std::int64_t> expected(before.CellCount());
        std::iota(expected.begin(), expected.end(), 0);
        std::vector<std::uint64_t> codes(before.CellCount());
        for (std::int64_t c = 0; c < before.CellCount(); ++c) codes[c] = code(c);
        std::stable_sort(
            expected.begin(), expected.end(),
            [&](std::int64_t a, std::int64_t b) { return codes[a] < codes[b]; });
        std::int64_t ties = 0;
        for (std::int64_t i = 1; i < before.CellCount(); ++i)
            ties += codes[expected[i]] == codes[expected[i - 1]];
        if (stretched) {
            EXPECT_GT(ties, before.CellCount() / 10);
        } else {
            EXPECT_GT(*std::max_element(codes.begin(), codes.end()), std::uint64_t(1)
                                                                         << 32);
        }
        ASSERT_EQ(oldOf.size(), expected.size());
        for (std::size_t i = 0; i < expected.size(); ++i)
            ASSERT_EQ(oldOf[i], expected[i]) << (stretched ? "stretched, " : "") << i;
    }
}

TEST(MeshOrder, EmptyAndOneCellMeshes) {
    Mesh empty;
    EXPECT_TRUE(OrderSpatially(empty).empty());
    Mesh one = MakeBuiltin("builtin:cube-tets-1");
    const Mesh copy = one;
    const auto oldOf = OrderSpatially(one);
    EXPECT_EQ(oldOf.size(), std::size_t(copy.CellCount()));
    EXPECT_NO_THROW(one.Validate("one"));
}

}  // namespace
}  // namespace hpray
