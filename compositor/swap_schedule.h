// Who sends which pixels to whom: the tree-aware swap and direct-send schedules.
#pragma once

#include <cstddef>
#include <vector>

#include "active_pixels.h"
#include "composite_tree.h"

namespace hpray::compositor {

/// A rank and the pixel range it holds (composited over its group) at some stage.
struct Piece {
    int rank = -1;
    PixelRange range;
};

/// One exchange: the groups of ranks below a tree node merge their partial images. Each
/// child group holds its own composite as pieces tiling the image; afterwards the merged
/// group holds the composite of all children as `result`, again tiling the image. Rank r
/// sends the part of its old piece that lies in another rank's new piece to that rank,
/// and composites what it receives for its new piece in the children's visibility order.
struct MergeStep {
    int node = -1;  ///< the KdTree node merged here; -1 for direct send
    int tag = 0;    ///< message tag: the node's depth, unique along any leaf's path
    /// Per child group, in tree order (low, high) or, for direct send, one per rank: the
    /// pieces its ranks hold before the step, in increasing range order.
    std::vector<std::vector<Piece>> children;
    /// One piece per rank of the step after it, in increasing range order.
    std::vector<Piece> result;
};

/// The whole schedule for P ranks and an image of `pixels` pixels; view-independent (the
/// view only decides the order in which each step's children are composited).
struct CompositePlan {
    std::size_t pixels = 0;
    int ranks = 0;
    std::vector<MergeStep> steps;        ///< every step after the steps of its children
    std::vector<PixelRange> finalRange;  ///< per rank: the range it holds at the end
    int rounds = 0;                      ///< most steps any one rank takes part in
};

/// Binary swap along the tree, for any tree shape and any P. Built top-down: the final
/// pieces are P equal cuts of the image, in an order that interleaves every node's two
/// children evenly; going down, each rank's piece below a node is its piece above the
/// node grown over the gaps left by the other child's ranks (boundaries as near equal
/// cuts as the gaps allow). So at every step a rank's new piece lies inside its old one:
/// it sends |old| - |new| pixels, and over all rounds exactly S - |final| = S (1 - 1/P)
/// (to a pixel of rounding) for every tree shape, balanced or not, with the tree's height
/// as the number of rounds. A balanced tree over P = 2^k ranks gives classic binary swap
/// (halves at every round).
CompositePlan PlanTreeSwap(const KdTree& tree, int ranks, std::size_t pixels);

/// Direct send: one step in which rank k receives range k of P equal ranges from every
/// other rank. Also S (1 - 1/P) per rank, but P - 1 messages per rank instead of log2 P.
CompositePlan PlanDirectSend(int ranks, std::size_t pixels);

/// Pixels each rank sends in the steps of `plan` when every pixel is non-empty.
std::vector<std::size_t> DensePixelsSent(const CompositePlan& plan);

}  // namespace hpray::compositor
