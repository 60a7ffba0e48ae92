// A k-d split of measured render work: the in-memory split of `hpray render` on P ranks
// places its planes where a low-resolution pre-pass measured the work (see SplitWork).
#pragma once

#include <array>
#include <vector>

#include "geom/kd_tree.h"

namespace hpray::partition {

/// A piece of measured render work: the axis-aligned extent of a pre-pass segment, its
/// cost in seconds, and the last point before it where its ray stopped (if any).
struct WorkExtent {
    std::array<double, 3> lo, hi;
    double weight;
    bool occluded = false;
    std::array<double, 3> occluder{};
};

/// The k-d tree (leaves numbered by box), the leaf boxes (under the ownership rule of
/// geom/box.h) and the work estimated in each.
struct WorkSplit {
    KdTree tree;
    std::vector<Box> boxes;
    std::vector<double> cost;
};

/// A k-d split of measured work into `count` boxes tiling `root`, so that each box's work
/// is proportional to its number of leaves.
///
/// Work of a box B: the extents that meet B and are visible in it. A brick renders its
/// rays from where they enter its box, so a segment is skipped only when its ray stopped
/// earlier *inside the same box*; since a ray meets a box in one interval, that is when
/// the ray's last stop before the segment lies in B. A cut segment counts fully on both
/// sides (each part is projected and searched like a whole).
///
/// At each node, over the three axes, the plane x minimises max(low(x) / lowLeaves,
/// high(x) / highLeaves). For an extent [lo, hi] along the axis whose stop q lies in the
/// node's box, it is visible on the low side for x in (lo, q] (q beyond x: the stop falls
/// on the high side) and on the high side for x in [q, hi); otherwise for x > lo and
/// x < hi. So planes fall on cell faces unless cutting cells balances better, and behind
/// opaque surfaces only work a brick really does is counted. A plane within 1e-9 of the
/// box size of a node coordinate (`bounds[axis]`, sorted) is moved onto it, so planes
/// through axis-aligned faces lie exactly on them.
WorkSplit SplitWork(const std::vector<WorkExtent>& items, int count, const Box& root,
                    const std::array<std::vector<double>, 3>& bounds);

}  // namespace hpray::partition
