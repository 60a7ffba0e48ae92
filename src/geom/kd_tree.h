// The one k-d tree of hpray: bricks of a partition, boxes of the in-memory split and ranks
// of the compositor are all leaves of a KdTree; what a leaf stands for is its `leaf`
// number, plain data.
#pragma once

#include <array>
#include <string>
#include <vector>

#include "geom/box.h"

namespace hpray {

/// A node of a k-d tree. An inner node cuts its region by the plane x[axis] = split into
/// the low child (x[axis] < split) and the high child (x[axis] >= split): the ownership
/// rule of geom/box.h. A leaf carries a number (a brick, a box or a rank index).
struct KdNode {
    int axis = -1;  ///< 0, 1, 2 for an inner node; -1 for a leaf
    double split = 0;
    int low = -1, high = -1;  ///< child node indices (inner nodes)
    int leaf = -1;            ///< leaf number (leaves)
    /// Partitions only: how cells whose centroid lies exactly on the plane are divided
    /// (structured meshes put many there). With tieBreak, such a centroid goes low when
    /// (x[(axis+1)%3], x[(axis+2)%3]) < tie lexicographically. Space itself is divided by
    /// the plane alone.
    bool tieBreak = false;
    std::array<double, 2> tie{};

    bool IsLeaf() const { return axis < 0; }
};

/// What decides the front-to-back order of a k-d tree's leaves: the eye of a perspective
/// camera, or the ray direction of an orthographic one.
struct ViewOrigin {
    bool orthographic = false;
    std::array<double, 3> eye{0.0, 0.0, 0.0};        ///< world; perspective only
    std::array<double, 3> direction{0.0, 0.0, 1.0};  ///< any length; orthographic only

    static ViewOrigin Perspective(const std::array<double, 3>& eye);
    static ViewOrigin Orthographic(const std::array<double, 3>& direction);
};

/// Whether the low child of a split (axis, split) is in front of the high child for
/// every ray of `view`. Perspective: every ray starts at the eye and crosses the plane at
/// most once, from the eye's side to the other, so the half-space holding the eye comes
/// first; an eye on the plane lies in the high half-space (x >= split), so high comes
/// first. Orthographic: low is in front iff direction[axis] > 0. A ray parallel to the
/// plane (or leaving the eye within it) meets one side only, so the tie rules are exact.
bool LowInFront(int axis, double split, const ViewOrigin& view);

/// A k-d tree: nodes[root] is the root, `box` its region (closed).
struct KdTree {
    std::vector<KdNode> nodes;
    int root = 0;
    Box box;

    /// One leaf numbered 0 over `box`.
    static KdTree SingleLeaf(const Box& box = {});

    /// The region of every node, its faces on split planes marked inner (the ownership
    /// rule of geom/box.h), indexed like nodes.
    std::vector<Box> NodeBoxes() const;
    /// The region of every leaf, indexed by leaf number (count = largest number + 1).
    std::vector<Box> LeafBoxes() const;
    /// The leaf number of the leaf whose region holds `x` (descending low iff
    /// x[axis] < split).
    int LeafAt(const double x[3]) const;
    /// Appends the leaf number of every leaf whose closed region touches the closed box
    /// `b` (a conservative test).
    void TouchedLeaves(const Box& b, std::vector<int>& leaves) const;
    /// The same with a traversal stack the caller keeps (no allocation per call).
    void TouchedLeaves(const Box& b, std::vector<int>& leaves,
                       std::vector<int>& stack) const;
    /// Leaf numbers front to back for `view` (in-order, the front child first).
    std::vector<int> FrontToBack(const ViewOrigin& view) const;
    /// Inner nodes on the longest root-to-leaf path (0 for one leaf).
    int Height() const;
    /// Empty if the tree is well formed with leaf numbers exactly 0..leaves-1, each once:
    /// indices in range, every node reached once from the root, axes 0..2, finite
    /// splits. Otherwise a description of the first problem found.
    std::string Problem(int leaves) const;
};

/// A balanced tree of `count` leaves numbered 0..count-1 in order over `box`: a node of n
/// leaves puts floor(n/2) in its low child and cuts its longest axis at the fraction
/// floor(n/2)/n.
KdTree RegularKdTree(int count, const Box& box);

}  // namespace hpray
