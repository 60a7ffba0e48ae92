// The k-d tree over ranks that fixes compositing pairs, and its visibility order per
// view.
#pragma once

#include <array>
#include <string>
#include <vector>

#include "scene/scene.h"

namespace hpray::compositor {

/// One node of the tree over ranks. A split node divides its region of world space by the
/// plane x[axis] = split into the `low` child (x[axis] <= split) and the `high` child
/// (x[axis] >= split); a leaf is the region (one k-d subtree of bricks) rendered by one
/// rank. Plain data, the same on every rank.
struct CompositeNode {
    int axis = -1;       ///< 0, 1, 2 for a split; -1 for a leaf
    double split = 0.0;  ///< world coordinate of the split plane along `axis`
    int low = -1;        ///< index in CompositeTree::nodes of the low child (split only)
    int high = -1;       ///< index of the high child (split only)
    int rank = -1;       ///< leaf only: the rank (in the compositing communicator)

    bool IsLeaf() const { return axis < 0; }
};

/// The tree over ranks. Every rank 0..P-1 is exactly one leaf; any leaf order is allowed
/// (the compositor follows the tree, not the rank numbers). Built by the renderer with
/// BuildRankTree from the partition's k-d tree and its brick -> rank assignment, or by
/// hand (tests, benchmarks). With brick indices in the leaves instead of ranks, the same
/// structure and VisibilityOrder order a rank's own bricks for CompositeOver.
struct CompositeTree {
    std::vector<CompositeNode> nodes;
    int root = 0;

    /// A tree of one leaf owned by rank 0 (P = 1).
    static CompositeTree SingleRank();
};

/// The camera as the compositor needs it: only the eye (perspective) or the view
/// direction (orthographic) decide the visibility order.
struct CompositeView {
    bool orthographic = false;
    std::array<double, 3> eye{0.0, 0.0, 0.0};        ///< world; perspective only
    std::array<double, 3> direction{0.0, 0.0, 1.0};  ///< world, any length; ortho only

    static CompositeView Perspective(const std::array<double, 3>& eye);
    static CompositeView Orthographic(const std::array<double, 3>& direction);
};

/// The view of a scene camera: its position (perspective), or look_at - position
/// (orthographic, the ray direction of design.md).
CompositeView ViewFromCamera(const SceneCamera& camera);

/// Whether the low child of a split (axis, split) is in front of the high child for every
/// pixel of `view`. Perspective: every ray starts at the eye and crosses the plane at
/// most once, from the eye's side to the other, so the half-space holding the eye is in
/// front for all pixels, wherever the eye is (outside the data, inside it). Orthographic:
/// rays run along `direction`, so low is in front iff direction[axis] > 0. Tie rule: an
/// eye exactly on the plane (perspective) or a direction parallel to it (orthographic,
/// direction[axis] == 0) puts low in front. Either order is then exact: a ray leaving a
/// point of the plane, or parallel to it, meets at most one open side, and the plane
/// itself is a set of measure zero that the renderer assigns to one brick.
bool LowInFront(int axis, double split, const CompositeView& view);

/// The ranks of `tree` front to back for `view` (in-order traversal taking the front
/// child first at every split). Requires a valid tree (ValidateTree).
std::vector<int> VisibilityOrder(const CompositeTree& tree, const CompositeView& view);

/// Empty if `tree` is a valid tree over ranks 0..ranks-1: indices in range, every node
/// reached exactly once from the root, axes 0..2, finite splits, every rank exactly one
/// leaf. Otherwise a description of the first problem found.
std::string TreeProblem(const CompositeTree& tree, int ranks);
/// Throws InternalError with TreeProblem's message if the tree is not valid.
void ValidateTree(const CompositeTree& tree, int ranks);

/// Height of the tree: split nodes on the longest root-to-leaf path (0 for one leaf).
int TreeHeight(const CompositeTree& tree);

/// A k-d tree over bricks, as the partition manifest stores it ({"axis", "split", "low",
/// "high"} or {"brick"}).
struct BrickTreeNode {
    int axis = -1;       ///< 0..2 for a split, -1 for a leaf
    double split = 0.0;  ///< world coordinate of the split plane
    int low = -1, high = -1;
    int brick = -1;  ///< leaf only: brick index
};

/// The tree over ranks of a k-d tree over bricks (root `root`) and an assignment
/// `brickRank[brick]` in 0..ranks-1. Ranks must own whole subtrees: the bricks of each
/// rank are exactly the leaves of one node, and every rank owns at least one brick; then
/// each rank's region is that node's box, and the result is the brick tree with every
/// one-rank subtree collapsed to a leaf. Throws InternalError if the brick tree is
/// malformed (the manifest reader validates input first) or the assignment breaks these
/// rules (a renderer bug).
CompositeTree BuildRankTree(const std::vector<BrickTreeNode>& brickTree, int root,
                            const std::vector<int>& brickRank, int ranks);

/// A balanced tree over `ranks` ranks (ranks in leaf order 0..P-1) splitting the box
/// [lo, hi] recursively: a node of n ranks puts floor(n/2) in the low child, cut along
/// the box's longest axis at the fraction floor(n/2)/n. For tests and benchmarks.
CompositeTree RegularRankTree(int ranks, const std::array<double, 3>& lo,
                              const std::array<double, 3>& hi);

}  // namespace hpray::compositor
