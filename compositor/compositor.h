// Distributed image compositing: tree-aware binary swap, direct send, gather reference.
#pragma once

#include <mpi.h>

#include <cstdint>

#include "composite_tree.h"
#include "image/image.h"

namespace hpray::compositor {

/// How partial images are combined.
///
/// Why TreeSwap is the default, for any P (measured with benchmarks/bench_composite on
/// the 2-core development machine, P = 2..8 oversubscribed, 512^2..4096^2 images):
/// - Folding a non-power-of-two P onto the next lower power of two makes each folded
///   rank send its whole image S, over the 1.1 S (1 - 1/P) per-rank budget for every
///   P < 11, and 2-3 swap fixes its own groups of 2 and 3, which a k-d tree over ranks
///   does not have. The tree swap (PlanTreeSwap) follows any tree shape, merges only
///   adjacent groups of the visibility order, and sends exactly S (1 - 1/P) per rank.
/// - Direct send moves the same bytes for dense images and fewer for sparse ones (an
///   active pixel crosses the network once; a swap resends the union of its group's
///   active pixels every round): 0.25 GB against 0.35 GB per rank at 4096^2, P = 4, 16 %
///   active. But every rank exchanges P - 1 messages (P^2 in all) and holds its P - 1
///   incoming pieces at once: for dense 4096^2 images at P = 4 it took 11.6-23.9 s
///   against 7.9-8.3 s for the swap; at 512^2-2048^2 the two are within the noise of a
///   shared machine. The swap's log2 P rounds and O(1) messages per round scale to large
///   P; direct send stays selectable for measurements.
enum class Method {
    /// Binary swap along the tree over ranks (PlanTreeSwap), active pixels only, then a
    /// gather of the final pieces to rank 0. The default.
    TreeSwap,
    /// Every rank sends range k of its image to rank k (PlanDirectSend), then the gather.
    /// Same bytes as TreeSwap, P - 1 messages per rank; kept for measurements.
    DirectSend,
    /// The reference: every rank sends its whole uncompressed image to rank 0, which
    /// composites them one by one in visibility order. Slow and simple on purpose.
    GatherReference,
};

/// What one Composite call did; every field is the same on every rank except the
/// *Local ones.
struct CompositeStats {
    int rounds = 0;                      ///< exchange rounds (tree height for TreeSwap)
    int bytesPerPixel = kBytesPerPixel;  ///< wire bytes per non-empty pixel (no headers)
    std::uint64_t bytesSentMax = 0;      ///< max over ranks of bytes sent in the rounds
    std::uint64_t bytesSentTotal = 0;    ///< sum over ranks of bytes sent in the rounds
    std::uint64_t bytesGather = 0;       ///< bytes sent to rank 0 by the final gather
    std::uint64_t bytesSentLocal = 0;    ///< this rank's bytes sent in the rounds
    double swapSeconds = 0.0;            ///< max over ranks, wall time of the rounds
    double gatherSeconds = 0.0;          ///< max over ranks, wall time of the gather
};

/// Composites the partial images of all ranks of `comm` into rank 0's `image`.
///
/// Collective over `comm` (P ranks), called from the thread that initialised MPI. On
/// entry every rank's `image` is its full-frame partial image (same width and height on
/// all ranks): the rendering of its region of space, the leaf of `tree` it owns. Regions
/// are disjoint, so the result is exact: rank images combined with Over (over.h) in the
/// tree's visibility order for `view`. On return rank 0 holds the composited image; the
/// other ranks' images hold scratch data. `tree` and `view` must be identical on all
/// ranks and `tree` valid for P ranks: a rank that finds otherwise (or mismatched image
/// sizes) makes every rank throw InternalError together, before any exchange. A failure
/// during the exchange ends the job through mpi::Abort, so no rank waits forever.
CompositeStats Composite(Image& image, const KdTree& tree,
                         const ViewOrigin& view, MPI_Comm comm,
                         Method method = Method::TreeSwap);

}  // namespace hpray::compositor
