// The k-d tree of a partition: building it by weighted medians over streamed centroids,
// and the queries the partitioner and readers share (owner leaf, overlapped leaves).
#pragma once

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

/// Calls `visit(points, count)` for every stored centroid, in blocks; one full pass.
using CentroidPass = std::function<void(
    const std::function<void(const WeightedPoint* points, std::size_t count)>& visit)>;

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
