// The ownership rule of geom/box.h: every point of the root box in exactly one leaf, every
// ray cut into pieces that cover its chord through the root box exactly once, for random
// k-d trees and for rays in split planes, along box edges and through corners.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "geom/box.h"
#include "geom/kd_tree.h"

namespace hpray {
namespace {

/// A random k-d tree of `leaves` leaves over `box`, splits on a grid of 1/8 of each side
/// (so planes are shared by many rays and boxes, as in structured meshes).
int Append(KdTree& tree, int first, int leaves, const Box& box, std::mt19937& rng) {
    KdNode node;
    if (leaves == 1) {
        node.leaf = first;
        tree.nodes.push_back(node);
        return static_cast<int>(tree.nodes.size()) - 1;
    }
    std::uniform_int_distribution<int> axisDist(0, 2), eighth(1, 7), lowDist(1, leaves - 1);
    node.axis = axisDist(rng);
    const double a = box.lo[node.axis], b = box.hi[node.axis];
    node.split = a + (b - a) * eighth(rng) / 8;
    const int self = static_cast<int>(tree.nodes.size());
    tree.nodes.push_back(node);
    const int low = lowDist(rng);
    Box lowBox = box, highBox = box;
    lowBox.hi[node.axis] = node.split;
    highBox.lo[node.axis] = node.split;
    const int l = Append(tree, first, low, lowBox, rng);
    const int h = Append(tree, first + low, leaves - low, highBox, rng);
    tree.nodes[self].low = l;
    tree.nodes[self].high = h;
    return self;
}

KdTree RandomTree(int leaves, std::mt19937& rng) {
    KdTree tree;
    tree.box = Box{{0, 0, 0}, {1, 2, 4}};
    tree.root = Append(tree, 0, leaves, tree.box, rng);
    return tree;
}

TEST(Box, IntersectKeepsInnerFacesOfTheBoxThatSetsThem) {
    Box leaf{{0, 0, 0}, {1, 1, 1}};
    leaf.inner = 0b001001;  // lower and upper x faces on split planes
    const Box clip{{0.5, -1, -1}, {1, 0.5, 2}};
    const Box r = leaf.Intersect(clip);
    EXPECT_EQ(r.lo, (std::array<double, 3>{0.5, 0, 0}));
    EXPECT_EQ(r.hi, (std::array<double, 3>{1, 0.5, 1}));
    EXPECT_FALSE(r.InnerLo(0));  // set by the clip box
    EXPECT_TRUE(r.InnerHi(0));   // a tie: inner if either is
    EXPECT_FALSE(r.InnerHi(1));
    const double onUpperX[3] = {1, 0.2, 0.2}, inside[3] = {0.7, 0.2, 0.2};
    EXPECT_FALSE(r.Contains(onUpperX));
    EXPECT_TRUE(r.Contains(inside));
    EXPECT_TRUE(Box::Empty().IsEmpty());
}

TEST(KdTree, EveryPointOfTheRootBoxIsInExactlyOneLeaf) {
    std::mt19937 rng(3);
    for (int trial = 0; trial < 40; ++trial) {
        const KdTree tree = RandomTree(1 + trial % 12, rng);
        ASSERT_EQ(tree.Problem(1 + trial % 12), "");
        const std::vector<Box> boxes = tree.LeafBoxes();
        std::uniform_int_distribution<int> grid(0, 16);
        for (int k = 0; k < 300; ++k) {
            // Points on the grid of 1/16: many on planes, edges and corners.
            const double x[3] = {grid(rng) / 16.0, 2 * grid(rng) / 16.0, 4 * grid(rng) / 16.0};
            int owners = 0, owner = -1;
            for (std::size_t b = 0; b < boxes.size(); ++b)
                if (boxes[b].Contains(x)) ++owners, owner = static_cast<int>(b);
            ASSERT_EQ(owners, 1) << trial << ": (" << x[0] << ", " << x[1] << ", " << x[2]
                                 << ")";
            EXPECT_EQ(tree.LeafAt(x), owner);
        }
    }
}

/// For a ray, the pieces of all leaves tile its span through the root box: sorted by
/// start, each starts where the previous ended, none overlaps another in more than a
/// point that only one of them holds, and every sample parameter lies in exactly one.
void CheckTiling(const KdTree& tree, const double o[3], const double d[3],
                 const std::string& what) {
    RaySpan whole;
    if (!ClipRay(o, d, tree.box, whole)) return;
    std::vector<RaySpan> pieces;
    std::vector<int> owners;
    const std::vector<Box> boxes = tree.LeafBoxes();
    for (std::size_t b = 0; b < boxes.size(); ++b) {
        RaySpan s;
        if (ClipRay(o, d, boxes[b], s)) {
            pieces.push_back(s);
            owners.push_back(static_cast<int>(b));
        }
    }
    ASSERT_FALSE(pieces.empty()) << what;
    std::vector<double> ts{whole.t0, whole.t1, 0.5 * (whole.t0 + whole.t1)};
    for (const RaySpan& s : pieces) {
        ts.push_back(s.t0);
        ts.push_back(s.t1);
        ts.push_back(0.5 * (s.t0 + s.t1));
    }
    for (double t : ts) {
        int holders = 0;
        for (const RaySpan& s : pieces) holders += s.Holds(t);
        EXPECT_EQ(holders, whole.Holds(t) ? 1 : 0) << what << " at t = " << t;
    }
    // The pieces sum to the whole chord.
    double length = 0;
    for (const RaySpan& s : pieces) length += s.t1 - s.t0;
    EXPECT_NEAR(length, whole.t1 - whole.t0, 1e-12 * (1 + whole.t1 - whole.t0)) << what;
    // Interior points are where the point rule says (pieces long enough that the point
    // computed from t is clear of the planes by more than rounding).
    for (std::size_t k = 0; k < pieces.size(); ++k) {
        if (!(pieces[k].t1 - pieces[k].t0 > 1e-9)) continue;
        const double t = 0.5 * (pieces[k].t0 + pieces[k].t1);
        const double x[3] = {o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]};
        EXPECT_EQ(tree.LeafAt(x), owners[k]) << what;
    }
}

TEST(ClipRay, PiecesTileEveryRayInPlanesAlongEdgesAndThroughCorners) {
    std::mt19937 rng(5);
    std::uniform_int_distribution<int> grid(0, 16), sign(-1, 1);
    std::uniform_real_distribution<double> u(-1, 1);
    for (int trial = 0; trial < 40; ++trial) {
        const KdTree tree = RandomTree(2 + trial % 11, rng);
        const Box& r = tree.box;
        for (int k = 0; k < 200; ++k) {
            // An origin on the grid (often on a plane, an edge or a corner) and a
            // direction with zero components (in planes, along edges) or a generic one.
            double o[3], d[3];
            for (int a = 0; a < 3; ++a) {
                o[a] = r.lo[a] + (r.hi[a] - r.lo[a]) * grid(rng) / 16.0;
                d[a] = k % 3 == 0 ? u(rng) : double(sign(rng));
            }
            if (d[0] == 0 && d[1] == 0 && d[2] == 0) d[k % 3] = 1;
            // Start outside the root box sometimes: back along the ray.
            if (k % 2)
                for (int a = 0; a < 3; ++a) o[a] -= 9 * d[a];
            CheckTiling(tree, o, d, "trial " + std::to_string(trial) + " ray " + std::to_string(k));
        }
    }
}

TEST(ClipRay, ARayInASplitPlaneBelongsToTheHighSideOnly) {
    KdTree tree = RegularKdTree(2, Box{{0, 0, 0}, {2, 1, 1}});  // split x = 1
    const std::vector<Box> boxes = tree.LeafBoxes();
    const double o[3] = {1, 0.5, -1}, d[3] = {0, 0, 1};
    RaySpan low, high;
    EXPECT_FALSE(ClipRay(o, d, boxes[0], low));
    EXPECT_TRUE(ClipRay(o, d, boxes[1], high));
    EXPECT_EQ(high.t0, 1);
    EXPECT_EQ(high.t1, 2);
    // A ray crossing the plane: the crossing point goes to the piece that starts there.
    const double o2[3] = {0, 0.5, 0.5}, d2[3] = {1, 0, 0};
    RaySpan a, b;
    ASSERT_TRUE(ClipRay(o2, d2, boxes[0], a));
    ASSERT_TRUE(ClipRay(o2, d2, boxes[1], b));
    EXPECT_EQ(a.t1, b.t0);
    EXPECT_FALSE(a.closed1);
    EXPECT_TRUE(b.closed0);
    EXPECT_TRUE(b.closed1);  // leaves the root box
    // The other way round.
    const double o3[3] = {2, 0.5, 0.5}, d3[3] = {-1, 0, 0};
    RaySpan c, e;
    ASSERT_TRUE(ClipRay(o3, d3, boxes[1], c));
    ASSERT_TRUE(ClipRay(o3, d3, boxes[0], e));
    EXPECT_FALSE(c.closed1);
    EXPECT_TRUE(e.closed0);
    EXPECT_EQ(c.t1, e.t0);
    // From an eye on the plane into the low side: the high box gets nothing.
    const double o4[3] = {1, 0.5, 0.5}, d4[3] = {-1, 0, 0};
    RaySpan f{0, 10}, g{0, 10};
    EXPECT_FALSE(ClipRay(o4, d4, boxes[1], f));
    EXPECT_TRUE(ClipRay(o4, d4, boxes[0], g));
    EXPECT_EQ(g.t0, 0);
}

TEST(KdTree, FrontToBackPutsTheEyesSideFirstAndFollowsTheRays) {
    const KdTree tree = RegularKdTree(4, Box{{0, 0, 0}, {4, 1, 1}});
    EXPECT_EQ(tree.FrontToBack(ViewOrigin::Perspective({-1, 0.5, 0.5})),
              (std::vector<int>{0, 1, 2, 3}));
    // An eye on the plane x = 2 lies in the high side: it comes first.
    EXPECT_EQ(tree.FrontToBack(ViewOrigin::Perspective({2, 0.5, 0.5})),
              (std::vector<int>{2, 3, 1, 0}));
    EXPECT_EQ(tree.FrontToBack(ViewOrigin::Orthographic({-1, 0, 0})),
              (std::vector<int>{3, 2, 1, 0}));
    EXPECT_EQ(tree.Height(), 2);
}

}  // namespace
}  // namespace hpray
