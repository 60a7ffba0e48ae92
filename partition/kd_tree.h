// The k-d tree of a partition: building it by weighted medians over streamed centroids,
// and the queries the partitioner and readers share (owner leaf, overlapped leaves).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <vector>

#include "partition.h"

namespace hpray::partition {

/// A centroid and its cost, as the tree builder streams them.
struct WeightedPoint {
    double x[3];
    double cost;
};

/// Whether any centroid inside the closed box `box` can matter to a pass of the tree
/// builder; false when the pass ignores every centroid there.
using BlockFilter = std::function<bool(const Box& box)>;

/// Calls `visit(points, count)` for the stored centroids, in their order, in blocks; one
/// pass. A pass may leave out stored blocks of centroids whose bounding box `wanted`
/// rejects (see CentroidBlocks); an empty `wanted` keeps everything, and a pass may also
/// ignore the filter (the tree is the same).
using CentroidPass = std::function<void(
    const BlockFilter& wanted,
    const std::function<void(const WeightedPoint* points, std::size_t count)>& visit)>;

/// The bounding boxes of consecutive blocks of centroids, 2^Shift() per block, for passes
/// that skip blocks: centroids are added in their order. The boxes are stored as floats
/// rounded outwards (so they hold their centroids) in at most about `maxBytes`: when they
/// would need more, neighbouring blocks merge.
class CentroidBlocks {
  public:
    explicit CentroidBlocks(std::size_t maxBytes = std::size_t(1) << 20);
    void Add(const double x[3]);
    std::int64_t Count() const { return count_; }
    int Shift() const { return shift_; }
    std::size_t Blocks() const {
        return boxes_.size() +
               ((count_ & ((std::int64_t(1) << shift_) - 1)) != 0 ? 1 : 0);
    }
    /// The box of block b (centroids [b << Shift(), (b + 1) << Shift())).
    Box BlockBox(std::size_t b) const;

  private:
    std::vector<std::array<float, 6>> boxes_;  ///< complete blocks: lo, then hi
    Box current_;                              ///< the block being filled
    std::size_t maxBlocks_;
    int shift_ = 6;
    std::int64_t count_ = 0;
};

/// Builds the tree of `leaves` leaves over the closed box `root`: a node with n leaves
/// splits its longest axis into floor(n/2) and ceil(n/2) leaves, at the plane whose low
/// side (x < split) holds the closest achievable share floor(n/2)/n of the node's cost.
/// The plane is found level by level with shared passes: a histogram of 1024 bins
/// narrows the interval holding the weighted median until it holds at most
/// `collectLimit` centroids, which the next pass collects and sorts for the exact split
/// (between two distinct coordinates). Leaves get brick numbers 0..leaves-1 low side
/// first. nodes[0] is the root.
KdTree BuildKdTree(const Box& root, int leaves, const CentroidPass& pass,
                   std::size_t collectLimit);

/// The brick owning a cell of centroid `x`: descend low when GoesLow, else high.
int OwnerBrick(const KdTree& tree, const double x[3]);

}  // namespace hpray::partition
