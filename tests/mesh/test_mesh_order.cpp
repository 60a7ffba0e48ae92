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
