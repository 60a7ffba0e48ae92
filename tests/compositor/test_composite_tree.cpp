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
    EXPECT_TRUE(LowInFront(0, 0.5, CompositeView::Perspective({-3.0, 0.5, 0.5})));
    EXPECT_FALSE(LowInFront(0, 0.5, CompositeView::Perspective({4.0, 0.5, 0.5})));
    // Inside the data: only the eye's side matters, not the view direction.
    EXPECT_TRUE(LowInFront(1, 0.5, CompositeView::Perspective({0.3, 0.49, 0.2})));
    EXPECT_FALSE(LowInFront(1, 0.5, CompositeView::Perspective({0.3, 0.51, 0.2})));
    EXPECT_FALSE(LowInFront(2, -1.0, CompositeView::Perspective({0.0, 0.0, -0.5})));
    // Exactly on the plane: the documented tie rule puts low in front.
    EXPECT_TRUE(LowInFront(2, 0.25, CompositeView::Perspective({7.0, -2.0, 0.25})));
}

TEST(LowInFront, OrthographicDirectionSignDecides) {
    EXPECT_TRUE(LowInFront(0, 0.5, CompositeView::Orthographic({1.0, -5.0, 0.0})));
    EXPECT_FALSE(LowInFront(0, 0.5, CompositeView::Orthographic({-1e-9, 1.0, 0.0})));
    EXPECT_FALSE(LowInFront(2, 100.0, CompositeView::Orthographic({0.0, 0.0, -1.0})));
    EXPECT_TRUE(LowInFront(2, -100.0, CompositeView::Orthographic({0.0, 0.0, 2.0})));
    // Parallel to the plane: tie, low in front.
    EXPECT_TRUE(LowInFront(1, 0.5, CompositeView::Orthographic({1.0, 0.0, 1.0})));
}

TEST(LowInFront, ViewFromSceneCamera) {
    SceneCamera camera;
    camera.position = {0.2, 3.0, 0.7};
    camera.lookAt = {0.5, 0.5, 0.5};
    EXPECT_TRUE(LowInFront(0, 0.5, ViewFromCamera(camera)));
    EXPECT_FALSE(LowInFront(1, 0.5, ViewFromCamera(camera)));
    camera.orthographic = true;
    camera.orthoHeight = 2.0;
    // Direction (0.3, -2.5, -0.2): low in front along x, high along y and z.
    EXPECT_TRUE(LowInFront(0, 0.9, ViewFromCamera(camera)));
    EXPECT_FALSE(LowInFront(1, -4.0, ViewFromCamera(camera)));
    EXPECT_FALSE(LowInFront(2, 0.0, ViewFromCamera(camera)));
}

/// Checks, for `rays` random rays of `view`, that the ranks whose leaf box each ray
/// crosses (positive length) come in the order of VisibilityOrder when sorted by where
/// the ray enters them: the independent, geometric truth.
void CheckOrderAlongRays(const CompositeTree& tree, const std::vector<Box>& boxes,
                         const CompositeView& view, std::mt19937& rng, int rays) {
    const std::vector<int> order = VisibilityOrder(tree, view);
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
        const CompositeTree tree =
            testutil::RandomRankTree(ranks, rng, unit, seed % 2 == 1);
        ASSERT_EQ(TreeProblem(tree, ranks), "");
        const std::vector<Box> boxes = testutil::LeafBoxes(tree, unit, ranks);
        std::uniform_real_distribution<double> outside(-3.0, 4.0), inside(0.0, 1.0),
            dir(-1.0, 1.0);
        // Eye outside, eye inside the data, eye exactly on a split plane, orthographic.
        CheckOrderAlongRays(tree, boxes,
                            CompositeView::Perspective({outside(rng), 5.0, outside(rng)}),
                            rng, 200);
        CheckOrderAlongRays(
            tree, boxes,
            CompositeView::Perspective({inside(rng), inside(rng), inside(rng)}), rng,
            200);
        if (!tree.nodes[tree.root].IsLeaf()) {
            Vec3 eye{inside(rng), inside(rng), inside(rng)};
            eye[tree.nodes[tree.root].axis] = tree.nodes[tree.root].split;
            CheckOrderAlongRays(tree, boxes, CompositeView::Perspective(eye), rng, 200);
        }
        CheckOrderAlongRays(tree, boxes,
                            CompositeView::Orthographic({dir(rng), dir(rng), dir(rng)}),
                            rng, 200);
        CheckOrderAlongRays(tree, boxes,
                            CompositeView::Orthographic({dir(rng), 0.0, 1.0}), rng, 200);
    }
}

TEST(VisibilityOrder, SlabsAlongXFrontToBack) {
    const CompositeTree tree = RegularRankTree(4, {0, 0, 0}, {4, 1, 1});
    EXPECT_EQ(VisibilityOrder(tree, CompositeView::Perspective({-1, 0.5, 0.5})),
              (std::vector<int>{0, 1, 2, 3}));
    EXPECT_EQ(VisibilityOrder(tree, CompositeView::Perspective({9, 0.5, 0.5})),
              (std::vector<int>{3, 2, 1, 0}));
    // Inside slab 2 ([2, 3]): 2 first, then 1 and 0 on one side and 3 on the other are
    // ordered by the tree: root split at x = 2 puts {2, 3} first.
    EXPECT_EQ(VisibilityOrder(tree, CompositeView::Perspective({2.5, 0.5, 0.5})),
              (std::vector<int>{2, 3, 1, 0}));
    EXPECT_EQ(VisibilityOrder(tree, CompositeView::Orthographic({-1, 0, 0})),
              (std::vector<int>{3, 2, 1, 0}));
}

TEST(TreeValidation, ReportsEveryKindOfProblem) {
    CompositeTree good = RegularRankTree(3, {0, 0, 0}, {1, 1, 1});
    EXPECT_EQ(TreeProblem(good, 3), "");
    EXPECT_NE(TreeProblem(good, 4), "");  // rank 3 owns no leaf
    EXPECT_NE(TreeProblem(good, 2), "");  // rank 2 out of range
    CompositeTree duplicate = good;
    for (auto& node : duplicate.nodes)
        if (node.IsLeaf() && node.rank == 2) node.rank = 1;
    EXPECT_NE(TreeProblem(duplicate, 3), "");
    CompositeTree cycle = good;
    cycle.nodes[cycle.nodes[cycle.root].high].low = cycle.root;
    EXPECT_NE(TreeProblem(cycle, 3), "");
    CompositeTree badAxis = good;
    badAxis.nodes[badAxis.root].axis = 3;
    EXPECT_NE(TreeProblem(badAxis, 3), "");
    CompositeTree badIndex = good;
    badIndex.nodes[badIndex.root].low = 99;
    EXPECT_NE(TreeProblem(badIndex, 3), "");
    EXPECT_THROW(ValidateTree(badIndex, 3), InternalError);
    EXPECT_EQ(TreeProblem(CompositeTree::SingleRank(), 1), "");
}

TEST(TreeHeight, RegularTreesAreLogarithmic) {
    for (int ranks = 1; ranks <= 33; ++ranks) {
        const CompositeTree tree = RegularRankTree(ranks, {0, 0, 0}, {1, 2, 3});
        ASSERT_EQ(TreeProblem(tree, ranks), "") << ranks;
        int ceilLog2 = 0;
        while ((1 << ceilLog2) < ranks) ++ceilLog2;
        EXPECT_EQ(TreeHeight(tree), ceilLog2) << ranks;
    }
}

/// A random brick tree of `bricks` leaves; returns the nodes, root 0.
std::vector<BrickTreeNode> RandomBrickTree(int bricks, std::mt19937& rng) {
    // Build through the rank-tree helper, then relabel leaves as bricks.
    const CompositeTree shape = testutil::RandomRankTree(bricks, rng, Box{}, false);
    std::vector<BrickTreeNode> nodes(shape.nodes.size());
    for (std::size_t i = 0; i < nodes.size(); ++i) {
        nodes[i].axis = shape.nodes[i].axis;
        nodes[i].split = shape.nodes[i].split;
        nodes[i].low = shape.nodes[i].low;
        nodes[i].high = shape.nodes[i].high;
        nodes[i].brick = shape.nodes[i].rank;
    }
    return nodes;
}

/// Every brick below node `id`.
void BricksBelow(const std::vector<BrickTreeNode>& nodes, int id, std::vector<int>& out) {
    if (nodes[id].axis < 0) {
        out.push_back(nodes[id].brick);
        return;
    }
    BricksBelow(nodes, nodes[id].low, out);
    BricksBelow(nodes, nodes[id].high, out);
}

TEST(BuildRankTree, CollapsesWholeSubtreesAndKeepsTheirBoxes) {
    for (int seed = 0; seed < 50; ++seed) {
        std::mt19937 rng(100 + seed);
        const int bricks = 2 + seed % 15;
        const std::vector<BrickTreeNode> nodes = RandomBrickTree(bricks, rng);
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
        const CompositeTree tree = BuildRankTree(nodes, 0, brickRank, ranks);
        ASSERT_EQ(TreeProblem(tree, ranks), "") << seed;
        // Each rank's leaf box is the union of its bricks' boxes: compare the brick boxes
        // (from the brick tree) with the rank boxes (from the rank tree).
        CompositeTree brickShape;
        for (const BrickTreeNode& n : nodes) {
            CompositeNode c;
            c.axis = n.axis, c.split = n.split, c.low = n.low, c.high = n.high,
            c.rank = n.brick;
            brickShape.nodes.push_back(c);
        }
        const std::vector<Box> brickBoxes =
            testutil::LeafBoxes(brickShape, Box{}, bricks);
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
    std::vector<BrickTreeNode> nodes(7);
    nodes[0] = {0, 0.5, 1, 2, -1};
    nodes[1] = {0, 0.25, 3, 4, -1};
    nodes[2] = {0, 0.75, 5, 6, -1};
    for (int b = 0; b < 4; ++b) nodes[3 + b] = {-1, 0.0, -1, -1, b};
    EXPECT_NO_THROW(BuildRankTree(nodes, 0, {0, 0, 1, 2}, 3));
    EXPECT_EQ(BuildRankTree(nodes, 0, {0, 0, 1, 2}, 3).nodes.size(), 5u);
    // Rank 1 owns bricks 1 and 2, on both sides of the root: not one subtree.
    EXPECT_THROW(BuildRankTree(nodes, 0, {0, 1, 1, 2}, 3), InternalError);
    // Rank 2 owns nothing.
    EXPECT_THROW(BuildRankTree(nodes, 0, {0, 0, 1, 1}, 3), InternalError);
    // Malformed: a shared child.
    std::vector<BrickTreeNode> shared = nodes;
    shared[2].low = 3;
    EXPECT_THROW(BuildRankTree(shared, 0, {0, 0, 1, 2}, 3), InternalError);
}

}  // namespace
}  // namespace hpray::compositor
