// Tests of the tree over ranks: front-child decisions, visibility order against ray
// geometry, validation, construction from a brick tree.
#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <random>
#include <set>

#include "composite_test_util.h"
#include "composite_tree.h"
#include "util/error.h"

namespace hpray::compositor {
namespace {

using testutil::Box;
using testutil::Vec3;

TEST(LowInFront, PerspectiveEyeSideIsFront) {
    // Outside the data, on either side of x = 0.5.
    EXPECT_TRUE(LowInFront(0, 0.5, ViewOrigin::Perspective({-3.0, 0.5, 0.5})));
    EXPECT_FALSE(LowInFront(0, 0.5, ViewOrigin::Perspective({4.0, 0.5, 0.5})));
    // Inside the data: only the eye's side matters, not the view direction.
    EXPECT_TRUE(LowInFront(1, 0.5, ViewOrigin::Perspective({0.3, 0.49, 0.2})));
    EXPECT_FALSE(LowInFront(1, 0.5, ViewOrigin::Perspective({0.3, 0.51, 0.2})));
    EXPECT_FALSE(LowInFront(2, -1.0, ViewOrigin::Perspective({0.0, 0.0, -0.5})));
    // Exactly on the plane: the eye belongs to the high side (x >= split), which is in
    // front.
    EXPECT_FALSE(LowInFront(2, 0.25, ViewOrigin::Perspective({7.0, -2.0, 0.25})));
}

TEST(LowInFront, OrthographicDirectionSignDecides) {
    EXPECT_TRUE(LowInFront(0, 0.5, ViewOrigin::Orthographic({1.0, -5.0, 0.0})));
    EXPECT_FALSE(LowInFront(0, 0.5, ViewOrigin::Orthographic({-1e-9, 1.0, 0.0})));
    EXPECT_FALSE(LowInFront(2, 100.0, ViewOrigin::Orthographic({0.0, 0.0, -1.0})));
    EXPECT_TRUE(LowInFront(2, -100.0, ViewOrigin::Orthographic({0.0, 0.0, 2.0})));
    // Parallel to the plane: every ray lies on one side only; the tie puts high first.
    EXPECT_FALSE(LowInFront(1, 0.5, ViewOrigin::Orthographic({1.0, 0.0, 1.0})));
}

/// Checks, for `rays` random rays of `view`, that the ranks whose leaf box each ray
/// crosses (positive length) come in the order of VisibilityOrder when sorted by where
/// the ray enters them: the independent, geometric truth.
void CheckOrderAlongRays(const KdTree& tree, const std::vector<Box>& boxes,
                         const ViewOrigin& view, std::mt19937& rng, int rays) {
    const std::vector<int> order = tree.FrontToBack(view);
    ASSERT_EQ(order.size(), boxes.size());
    std::vector<int> position(order.size());
    for (std::size_t k = 0; k < order.size(); ++k)
        position[order[k]] = static_cast<int>(k);
    std::uniform_real_distribution<double> u(-1.0, 2.0), s(-1.0, 1.0);
    for (int n = 0; n < rays; ++n) {
        Vec3 origin = view.eye, dir;
        if (view.orthographic) {
            dir = testutil::Normalize(view.direction);
            for (int d = 0; d < 3; ++d) origin[d] = u(rng) - 3.0 * dir[d];
        } else {
            dir = testutil::Normalize({s(rng), s(rng), s(rng)});
        }
        std::vector<std::pair<double, int>> hits;
        for (std::size_t r = 0; r < boxes.size(); ++r) {
            double t0, t1;
            if (testutil::ClipRay(boxes[r], origin, dir, t0, t1) && t1 - t0 > 1e-12)
                hits.push_back({t0, static_cast<int>(r)});
        }
        std::sort(hits.begin(), hits.end());
        for (std::size_t k = 1; k < hits.size(); ++k)
            ASSERT_LT(position[hits[k - 1].second], position[hits[k].second])
                << "ray " << n << ": rank " << hits[k - 1].second << " entered at "
                << hits[k - 1].first << " before rank " << hits[k].second << " at "
                << hits[k].first;
    }
}

TEST(VisibilityOrder, MatchesRayGeometryForRandomTreesAndCameras) {
    const Box unit;
    for (int seed = 0; seed < 60; ++seed) {
        std::mt19937 rng(seed);
        const int ranks = 1 + seed % 13;
        const KdTree tree =
            testutil::RandomRankTree(ranks, rng, unit, seed % 2 == 1);
        ASSERT_EQ(tree.Problem(ranks), "");
        const std::vector<Box> boxes = testutil::LeafBoxes(tree, unit, ranks);
        std::uniform_real_distribution<double> outside(-3.0, 4.0), inside(0.0, 1.0),
            dir(-1.0, 1.0);
        // Eye outside, eye inside the data, eye exactly on a split plane, orthographic.
        CheckOrderAlongRays(tree, boxes,
                            ViewOrigin::Perspective({outside(rng), 5.0, outside(rng)}),
                            rng, 200);
        CheckOrderAlongRays(
            tree, boxes,
            ViewOrigin::Perspective({inside(rng), inside(rng), inside(rng)}), rng,
            200);
        if (!tree.nodes[tree.root].IsLeaf()) {
            Vec3 eye{inside(rng), inside(rng), inside(rng)};
            eye[tree.nodes[tree.root].axis] = tree.nodes[tree.root].split;
            CheckOrderAlongRays(tree, boxes, ViewOrigin::Perspective(eye), rng, 200);
        }
        CheckOrderAlongRays(tree, boxes,
                            ViewOrigin::Orthographic({dir(rng), dir(rng), dir(rng)}),
                            rng, 200);
        CheckOrderAlongRays(tree, boxes,
                            ViewOrigin::Orthographic({dir(rng), 0.0, 1.0}), rng, 200);
    }
}

TEST(VisibilityOrder, SlabsAlongXFrontToBack) {
    const KdTree tree = RegularKdTree(4, hpray::Box{{0, 0, 0}, {4, 1, 1}});
    EXPECT_EQ(tree.FrontToBack(ViewOrigin::Perspective({-1, 0.5, 0.5})),
              (std::vector<int>{0, 1, 2, 3}));
    EXPECT_EQ(tree.FrontToBack(ViewOrigin::Perspective({9, 0.5, 0.5})),
              (std::vector<int>{3, 2, 1, 0}));
    // Inside slab 2 ([2, 3]): 2 first, then 1 and 0 on one side and 3 on the other are
    // ordered by the tree: root split at x = 2 puts {2, 3} first.
    EXPECT_EQ(tree.FrontToBack(ViewOrigin::Perspective({2.5, 0.5, 0.5})),
              (std::vector<int>{2, 3, 1, 0}));
    EXPECT_EQ(tree.FrontToBack(ViewOrigin::Orthographic({-1, 0, 0})),
              (std::vector<int>{3, 2, 1, 0}));
}

TEST(TreeValidation, ReportsEveryKindOfProblem) {
    KdTree good = RegularKdTree(3, hpray::Box{{0, 0, 0}, {1, 1, 1}});
    EXPECT_EQ(good.Problem(3), "");
    EXPECT_NE(good.Problem(4), "");  // rank 3 owns no leaf
    EXPECT_NE(good.Problem(2), "");  // rank 2 out of range
    KdTree duplicate = good;
    for (auto& node : duplicate.nodes)
        if (node.IsLeaf() && node.leaf == 2) node.leaf = 1;
    EXPECT_NE(duplicate.Problem(3), "");
    KdTree cycle = good;
    cycle.nodes[cycle.nodes[cycle.root].high].low = cycle.root;
    EXPECT_NE(cycle.Problem(3), "");
    KdTree badAxis = good;
    badAxis.nodes[badAxis.root].axis = 3;
    EXPECT_NE(badAxis.Problem(3), "");
    KdTree badIndex = good;
    badIndex.nodes[badIndex.root].low = 99;
    EXPECT_NE(badIndex.Problem(3), "");
    EXPECT_THROW(ValidateTree(badIndex, 3), InternalError);
    EXPECT_EQ(KdTree::SingleLeaf().Problem(1), "");
}

TEST(TreeHeight, RegularTreesAreLogarithmic) {
    for (int ranks = 1; ranks <= 33; ++ranks) {
        const KdTree tree = RegularKdTree(ranks, hpray::Box{{0, 0, 0}, {1, 2, 3}});
        ASSERT_EQ(tree.Problem(ranks), "") << ranks;
        int ceilLog2 = 0;
        while ((1 << ceilLog2) < ranks) ++ceilLog2;
        EXPECT_EQ(tree.Height(), ceilLog2) << ranks;
    }
}

/// A random brick tree of `bricks` leaves (leaves numbered by brick), root 0.
KdTree RandomBrickTree(int bricks, std::mt19937& rng) {
    KdTree tree = testutil::RandomRankTree(bricks, rng, Box{}, false);
    return tree;
}

/// Every brick below node `id`.
void BricksBelow(const std::vector<KdNode>& nodes, int id, std::vector<int>& out) {
    if (nodes[id].axis < 0) {
        out.push_back(nodes[id].leaf);
        return;
    }
    BricksBelow(nodes, nodes[id].low, out);
    BricksBelow(nodes, nodes[id].high, out);
}

TEST(BuildRankTree, CollapsesWholeSubtreesAndKeepsTheirBoxes) {
    for (int seed = 0; seed < 50; ++seed) {
        std::mt19937 rng(100 + seed);
        const int bricks = 2 + seed % 15;
        const KdTree brickTree = RandomBrickTree(bricks, rng);
        const std::vector<KdNode>& nodes = brickTree.nodes;
        // Choose whole subtrees: split the frontier node with most bricks until P nodes.
        std::uniform_int_distribution<int> extra(0, bricks - 1);
        const int ranks = 1 + extra(rng);
        std::vector<int> frontier{0};
        while (static_cast<int>(frontier.size()) < ranks) {
            int best = -1;
            std::size_t most = 1;
            for (std::size_t f = 0; f < frontier.size(); ++f) {
                std::vector<int> below;
                BricksBelow(nodes, frontier[f], below);
                if (below.size() > most) most = below.size(), best = static_cast<int>(f);
            }
            const int id = frontier[best];
            frontier.erase(frontier.begin() + best);
            frontier.push_back(nodes[id].low);
            frontier.push_back(nodes[id].high);
        }
        std::vector<int> rankOf(ranks);
        std::iota(rankOf.begin(), rankOf.end(), 0);
        std::shuffle(rankOf.begin(), rankOf.end(), rng);
        std::vector<int> brickRank(bricks, -1);
        for (int f = 0; f < ranks; ++f) {
            std::vector<int> below;
            BricksBelow(nodes, frontier[f], below);
            for (int b : below) brickRank[b] = rankOf[f];
        }
        const KdTree tree = BuildRankTree(brickTree, brickRank, ranks);
        ASSERT_EQ(tree.Problem(ranks), "") << seed;
        // Each rank's leaf box is the union of its bricks' boxes: compare the brick boxes
        // (from the brick tree) with the rank boxes (from the rank tree).
        const std::vector<Box> brickBoxes = testutil::LeafBoxes(brickTree, Box{}, bricks);
        const std::vector<Box> rankBoxes = testutil::LeafBoxes(tree, Box{}, ranks);
        std::vector<double> volume(ranks, 0.0);
        for (int b = 0; b < bricks; ++b) {
            const Box& bb = brickBoxes[b];
            const Box& rb = rankBoxes[brickRank[b]];
            for (int d = 0; d < 3; ++d) {
                EXPECT_GE(bb.lo[d], rb.lo[d]) << seed;
                EXPECT_LE(bb.hi[d], rb.hi[d]) << seed;
            }
            volume[brickRank[b]] +=
                (bb.hi[0] - bb.lo[0]) * (bb.hi[1] - bb.lo[1]) * (bb.hi[2] - bb.lo[2]);
        }
        for (int r = 0; r < ranks; ++r) {
            const Box& rb = rankBoxes[r];
            EXPECT_NEAR(
                volume[r],
                (rb.hi[0] - rb.lo[0]) * (rb.hi[1] - rb.lo[1]) * (rb.hi[2] - rb.lo[2]),
                1e-12)
                << seed;
        }
    }
}

TEST(BuildRankTree, RejectsRanksThatDoNotOwnWholeSubtrees) {
    // Four slabs along x: ((0 | 1) | (2 | 3)).
    KdTree nodes;
    nodes.nodes.resize(7);
    nodes.nodes[0] = {0, 0.5, 1, 2, -1};
    nodes.nodes[1] = {0, 0.25, 3, 4, -1};
    nodes.nodes[2] = {0, 0.75, 5, 6, -1};
    for (int b = 0; b < 4; ++b) nodes.nodes[3 + b] = {-1, 0.0, -1, -1, b};
    EXPECT_NO_THROW(BuildRankTree(nodes, {0, 0, 1, 2}, 3));
    EXPECT_EQ(BuildRankTree(nodes, {0, 0, 1, 2}, 3).nodes.size(), 5u);
    // Rank 1 owns bricks 1 and 2, on both sides of the root: not one subtree.
    EXPECT_THROW(BuildRankTree(nodes, {0, 1, 1, 2}, 3), InternalError);
    // Rank 2 owns nothing.
    EXPECT_THROW(BuildRankTree(nodes, {0, 0, 1, 1}, 3), InternalError);
    // Malformed: a shared child.
    KdTree shared = nodes;
    shared.nodes[2].low = 3;
    EXPECT_THROW(BuildRankTree(shared, {0, 0, 1, 2}, 3), InternalError);
}

}  // namespace
}  // namespace hpray::compositor
