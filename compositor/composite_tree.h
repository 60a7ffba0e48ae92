// The k-d tree over ranks that fixes compositing pairs: a KdTree (geom/kd_tree.h) whose
// leaf numbers are ranks, built from the brick tree and the brick -> rank assignment.
#pragma once

#include <string>
#include <vector>

#include "geom/kd_tree.h"

namespace hpray::compositor {

/// The tree over ranks: a KdTree whose leaves are numbered by rank (in the compositing
/// communicator). Every rank 0..P-1 is exactly one leaf, any leaf order is allowed (the
/// compositor follows the tree, not the rank numbers); its visibility order for a view
/// is KdTree::FrontToBack. Built with BuildRankTree from a k-d tree over bricks, with
/// RegularKdTree (tests, benchmarks, the image split) or by hand.

/// Throws InternalError with KdTree::Problem's message if `tree` is not a valid tree
/// over ranks 0..ranks-1.
void ValidateTree(const KdTree& tree, int ranks);

/// The tree over ranks of a k-d tree over bricks (leaves numbered by brick) and an
/// assignment `brickRank[brick]` in 0..ranks-1. Ranks must own whole subtrees: the
/// bricks of each rank are exactly the leaves of one node, and every rank owns at least
/// one brick; then each rank's region is that node's box, and the result is the brick
/// tree with every one-rank subtree collapsed to a leaf. Throws InternalError if the
/// brick tree is malformed (the manifest reader validates input first) or the assignment
/// breaks these rules (a renderer bug).
KdTree BuildRankTree(const KdTree& brickTree, const std::vector<int>& brickRank, int ranks);

}  // namespace hpray::compositor
