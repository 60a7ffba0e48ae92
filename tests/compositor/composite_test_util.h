// Compositor test helpers: random k-d trees over ranks, leaf boxes, camera rays, slabs.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numeric>
#include <random>
#include <vector>

#include "composite_tree.h"

namespace hpray::compositor::testutil {

using Vec3 = std::array<double, 3>;

/// An axis-aligned box [lo, hi] in world space.
struct Box {
    Vec3 lo{0.0, 0.0, 0.0};
    Vec3 hi{1.0, 1.0, 1.0};
};

inline Vec3 Normalize(const Vec3& v) {
    const double n = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    return {v[0] / n, v[1] / n, v[2] / n};
}

inline Vec3 Cross(const Vec3& a, const Vec3& b) {
    return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0]};
}

/// Appends a random subtree of `count` leaves over `box`, leaf ranks taken in order from
/// `ranks[first, first + count)`: random axis, split at a random 20-80 % of the box, a
/// random number of leaves on each side. Returns the node index.
inline int AppendRandomSubtree(KdTree& tree, const std::vector<int>& ranks,
                               int first, int count, const Box& box, std::mt19937& rng) {
    if (count == 1) {
        KdNode leaf;
        leaf.leaf = ranks[first];
        tree.nodes.push_back(leaf);
        return static_cast<int>(tree.nodes.size()) - 1;
    }
    std::uniform_int_distribution<int> axisDist(0, 2), lowDist(1, count - 1);
    std::uniform_real_distribution<double> fracDist(0.2, 0.8);
    KdNode node;
    node.axis = axisDist(rng);
    node.split =
        box.lo[node.axis] + fracDist(rng) * (box.hi[node.axis] - box.lo[node.axis]);
    const int lowCount = lowDist(rng);
    tree.nodes.push_back(node);
    const int self = static_cast<int>(tree.nodes.size()) - 1;
    Box lowBox = box, highBox = box;
    lowBox.hi[node.axis] = node.split;
    highBox.lo[node.axis] = node.split;
    const int low = AppendRandomSubtree(tree, ranks, first, lowCount, lowBox, rng);
    const int high = AppendRandomSubtree(tree, ranks, first + lowCount, count - lowCount,
                                         highBox, rng);
    tree.nodes[self].low = low;
    tree.nodes[self].high = high;
    return self;
}

/// A random tree over `count` ranks covering `box`; leaf ranks shuffled if `shuffle`.
inline KdTree RandomRankTree(int count, std::mt19937& rng, const Box& box,
                                    bool shuffle) {
    std::vector<int> ranks(count);
    std::iota(ranks.begin(), ranks.end(), 0);
    if (shuffle) std::shuffle(ranks.begin(), ranks.end(), rng);
    KdTree tree;
    tree.root = AppendRandomSubtree(tree, ranks, 0, count, box, rng);
    return tree;
}

/// The box of every rank's leaf, the root covering `root`.
inline std::vector<Box> LeafBoxes(const KdTree& tree, const Box& root, int ranks) {
    std::vector<Box> boxes(ranks);
    std::vector<std::pair<int, Box>> stack{{tree.root, root}};
    while (!stack.empty()) {
        const auto [id, box] = stack.back();
        stack.pop_back();
        const KdNode& node = tree.nodes[id];
        if (node.IsLeaf()) {
            boxes[node.leaf] = box;
            continue;
        }
        Box low = box, high = box;
        low.hi[node.axis] = node.split;
        high.lo[node.axis] = node.split;
        stack.push_back({node.low, low});
        stack.push_back({node.high, high});
    }
    return boxes;
}

/// The part [t0, t1] of the ray origin + t dir, t >= 0, inside the closed box. Returns
/// false if there is none.
inline bool ClipRay(const Box& box, const Vec3& origin, const Vec3& dir, double& t0,
                    double& t1) {
    t0 = 0.0;
    t1 = std::numeric_limits<double>::infinity();
    for (int d = 0; d < 3; ++d) {
        if (dir[d] == 0.0) {
            if (origin[d] < box.lo[d] || origin[d] > box.hi[d]) return false;
            continue;
        }
        double a = (box.lo[d] - origin[d]) / dir[d], b = (box.hi[d] - origin[d]) / dir[d];
        if (a > b) std::swap(a, b);
        t0 = std::max(t0, a);
        t1 = std::min(t1, b);
    }
    return t0 <= t1;
}

/// The camera of docs/contracts.md, built independently of the scene library.
struct TestCamera {
    bool ortho = false;
    Vec3 position{}, forward{}, right{}, up{};
    double halfExtent = 1.0;  ///< tan(fov_y / 2), or ortho_height / 2
    int width = 1, height = 1;

    static TestCamera Make(bool ortho, const Vec3& position, const Vec3& lookAt,
                           const Vec3& upHint, double fovYDegreesOrHeight, int w, int h) {
        TestCamera c;
        c.ortho = ortho;
        c.position = position;
        c.forward = Normalize(
            {lookAt[0] - position[0], lookAt[1] - position[1], lookAt[2] - position[2]});
        c.right = Normalize(Cross(c.forward, upHint));
        c.up = Cross(c.right, c.forward);
        c.halfExtent = ortho ? fovYDegreesOrHeight / 2.0
                             : std::tan(fovYDegreesOrHeight * std::acos(-1.0) / 360.0);
        c.width = w;
        c.height = h;
        return c;
    }

    /// Origin and unit direction of the ray through the centre of pixel (i, j).
    void Ray(int i, int j, Vec3& origin, Vec3& dir) const {
        const double sx = (2.0 * (i + 0.5) / width - 1.0) * width / height * halfExtent;
        const double sy = (1.0 - 2.0 * (j + 0.5) / height) * halfExtent;
        if (ortho) {
            for (int d = 0; d < 3; ++d) {
                origin[d] = position[d] + sx * right[d] + sy * up[d];
                dir[d] = forward[d];
            }
            return;
        }
        origin = position;
        dir = Normalize({forward[0] + sx * right[0] + sy * up[0],
                         forward[1] + sx * right[1] + sy * up[1],
                         forward[2] + sx * right[2] + sy * up[2]});
    }

    ViewOrigin View() const {
        return ortho ? ViewOrigin::Orthographic(forward)
                     : ViewOrigin::Perspective(position);
    }
};

}  // namespace hpray::compositor::testutil
