// SplitWork: k-d splits of measured render work (the in-memory split of hpray render).
#include <gtest/gtest.h>

#include <random>

#include "work_split.h"

namespace hpray::partition {
namespace {

/// A segment of a ray along +x through the cell [x0, x1] x [y0, y0] x [0, 0].
WorkExtent Along(double x0, double x1, double weight, double y = 0.5) {
    WorkExtent e;
    e.lo = {x0, y, 0.5};
    e.hi = {x1, y, 0.5};
    e.weight = weight;
    return e;
}

const Box kUnitX{{0, 0, 0}, {4, 1, 1}};
const std::array<std::vector<double>, 3> kFaces{std::vector<double>{0, 1, 2, 3, 4},
                                                std::vector<double>{0, 1},
                                                std::vector<double>{0, 1}};

TEST(WorkSplit, OneLeafHoldsAllTheWork) {
    const WorkSplit s = SplitWork({Along(0, 1, 2), Along(1, 2, 3)}, 1, kUnitX, kFaces);
    ASSERT_EQ(s.tree.nodes.size(), 1u);
    EXPECT_EQ(s.tree.nodes[0].leaf, 0);
    EXPECT_DOUBLE_EQ(s.cost[0], 5);
    EXPECT_EQ(s.boxes[0], kUnitX);
}

TEST(WorkSplit, PlanesFallOnFacesWhenThatBalances) {
    const WorkSplit s =
        SplitWork({Along(0, 1, 1), Along(1, 2, 1), Along(2, 3, 1), Along(3, 4, 1)}, 2,
                  kUnitX, kFaces);
    ASSERT_EQ(s.tree.nodes[0].axis, 0);
    EXPECT_EQ(s.tree.nodes[0].split, 2.0);
    EXPECT_DOUBLE_EQ(s.cost[0], 2);
    EXPECT_DOUBLE_EQ(s.cost[1], 2);
}

TEST(WorkSplit, ACutCellCountsOnBothSides) {
    // Faces at 1 and 2 give max(4, 7) and max(5, 6); cutting [1, 2] gives max(5, 7): the
    // plane goes through the face at 2 although the weighted median lies inside [1, 2].
    const WorkSplit s =
        SplitWork({Along(0, 1, 4), Along(1, 2, 1), Along(2, 3, 6)}, 2, kUnitX, kFaces);
    ASSERT_EQ(s.tree.nodes[0].axis, 0);
    EXPECT_EQ(s.tree.nodes[0].split, 2.0);
    EXPECT_DOUBLE_EQ(s.cost[0], 5);
    EXPECT_DOUBLE_EQ(s.cost[1], 6);
    // One heavy cell: only cutting it balances, and its work then counts twice.
    const WorkSplit c = SplitWork({Along(0, 4, 8)}, 2, kUnitX, kFaces);
    ASSERT_EQ(c.tree.nodes[0].axis, 0);
    EXPECT_GT(c.tree.nodes[0].split, 0.0);
    EXPECT_LT(c.tree.nodes[0].split, 4.0);
    EXPECT_DOUBLE_EQ(c.cost[0], 8);
    EXPECT_DOUBLE_EQ(c.cost[1], 8);
}

TEST(WorkSplit, WorkBehindAStopCountsOnlyWhereTheStopIsNotInTheBox) {
    // Rays along +x stop at x = 0.5 in the first cell; the three cells behind are
    // occluded in any box that holds the stop, visible in a box that does not.
    std::vector<WorkExtent> items;
    for (int k = 0; k < 4; ++k) {
        WorkExtent e = Along(k, k + 1, 1);
        if (k > 0) {
            e.occluded = true;
            e.occluder = {0.5, 0.5, 0.5};
        }
        items.push_back(e);
    }
    const WorkSplit one = SplitWork(items, 1, kUnitX, kFaces);
    EXPECT_DOUBLE_EQ(one.cost[0], 1);
    // x = 3: low [0, 3] renders the first cell only, high [3, 4] its one visible cell.
    const WorkSplit two = SplitWork(items, 2, kUnitX, kFaces);
    ASSERT_EQ(two.tree.nodes[0].axis, 0);
    EXPECT_EQ(two.tree.nodes[0].split, 3.0);
    EXPECT_DOUBLE_EQ(two.cost[0], 1);
    EXPECT_DOUBLE_EQ(two.cost[1], 1);
    // The same rays travelling along -x (stop at 3.5 in the last cell): mirrored, x = 1.
    std::vector<WorkExtent> back;
    for (int k = 0; k < 4; ++k) {
        WorkExtent e = Along(k, k + 1, 1);
        if (k < 3) {
            e.occluded = true;
            e.occluder = {3.5, 0.5, 0.5};
        }
        back.push_back(e);
    }
    const WorkSplit mirrored = SplitWork(back, 2, kUnitX, kFaces);
    ASSERT_EQ(mirrored.tree.nodes[0].axis, 0);
    EXPECT_EQ(mirrored.tree.nodes[0].split, 1.0);
    EXPECT_DOUBLE_EQ(mirrored.cost[0], 1);
    EXPECT_DOUBLE_EQ(mirrored.cost[1], 1);
}

TEST(WorkSplit, PlanesSnapOntoNodeCoordinates) {
    // Segment ends a rounding error off the face at 2 (as ray points are).
    const double off = 2 + 4e-16 * 4;
    const WorkSplit s =
        SplitWork({Along(0, off, 1), Along(off, 4, 1)}, 2, kUnitX, kFaces);
    EXPECT_EQ(s.tree.nodes[0].split, 2.0);
}

TEST(WorkSplit, AShorterAxisWinsOnlyWhenItBalancesBetter) {
    // All work in one x-cell but spread over y: no x plane can balance, a y plane can.
    std::vector<WorkExtent> items;
    for (int j = 0; j < 10; ++j) items.push_back(Along(1, 2, 1, 0.05 + 0.1 * j));
    std::array<std::vector<double>, 3> faces = kFaces;
    for (int j = 0; j <= 10; ++j) faces[1].push_back(0.1 * j);
    std::sort(faces[1].begin(), faces[1].end());
    const WorkSplit s = SplitWork(items, 2, kUnitX, faces);
    ASSERT_EQ(s.tree.nodes[0].axis, 1);
    EXPECT_DOUBLE_EQ(s.cost[0], 5);
    EXPECT_DOUBLE_EQ(s.cost[1], 5);
    EXPECT_EQ(s.boxes[0].hi[1], s.tree.nodes[0].split);
    EXPECT_EQ(s.boxes[1].lo[1], s.tree.nodes[0].split);
}

TEST(WorkSplit, AnyCountBalancesManySmallPieces) {
    // 20000 short segments of random weight in the unit cube: every count gets boxes
    // tiling the root whose work is within a few pieces of the mean.
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> u(0, 1), w(0.5, 1.5);
    std::vector<WorkExtent> items;
    double total = 0;
    for (int i = 0; i < 20000; ++i) {
        WorkExtent e;
        for (int d = 0; d < 3; ++d) {
            e.lo[d] = u(rng);
            e.hi[d] = e.lo[d];
        }
        e.hi[0] = std::min(1.0, e.lo[0] + 1e-4);
        e.weight = w(rng);
        total += e.weight;
        items.push_back(e);
    }
    const Box cube{{0, 0, 0}, {1, 1, 1}};
    for (int count : {2, 3, 5, 7, 8, 12}) {
        const WorkSplit s = SplitWork(items, count, cube, {{{}, {}, {}}});
        ASSERT_EQ(static_cast<int>(s.boxes.size()), count);
        double volume = 0, worst = 0;
        for (int b = 0; b < count; ++b) {
            double v = 1;
            for (int d = 0; d < 3; ++d) v *= s.boxes[b].hi[d] - s.boxes[b].lo[d];
            volume += v;
            worst = std::max(worst, s.cost[b]);
        }
        EXPECT_NEAR(volume, 1.0, 1e-12) << count;
        EXPECT_LT(worst / (total / count), 1.01) << count;
    }
}

}  // namespace
}  // namespace hpray::partition
