// Brick plans: rank assignment by whole subtrees, the in-memory split, the broadcast.
#include "job/brick_plan.h"

#include <mpi.h>

#include <algorithm>
#include <cmath>
#include <functional>

#include "util/mpi.h"
#include "work_split.h"

namespace hpray::job {

namespace {


/// Leaves and cost under each node.
void SubtreeTotals(const BrickPlan& plan, int node, std::vector<int>& leaves,
                   std::vector<double>& cost) {
    const KdNode& n = plan.tree.nodes[node];
    if (n.axis < 0) {
        leaves[node] = 1;
        cost[node] = std::max(plan.cost[n.leaf], 1e-12);
        return;
    }
    SubtreeTotals(plan, n.low, leaves, cost);
    SubtreeTotals(plan, n.high, leaves, cost);
    leaves[node] = leaves[n.low] + leaves[n.high];
    cost[node] = cost[n.low] + cost[n.high];
}

/// Ranks own whole subtrees: a node given P ranks splits them between its children in
/// proportion to their cost, at least one each and no more than each has leaves.
void AssignSubtree(BrickPlan& plan, int node, int r0, int ranks, const std::vector<int>& leaves,
                   const std::vector<double>& cost) {
    const KdNode& n = plan.tree.nodes[node];
    if (ranks == 1 || n.axis < 0) {
        std::function<void(int)> own = [&](int x) {
            const KdNode& m = plan.tree.nodes[x];
            if (m.axis < 0) {
                plan.rank[m.leaf] = r0;
            } else {
                own(m.low);
                own(m.high);
            }
        };
        own(node);
        return;
    }
    int low = static_cast<int>(std::lround(ranks * cost[n.low] / cost[node]));
    low = std::clamp(low, std::max(1, ranks - leaves[n.high]), std::min(ranks - 1, leaves[n.low]));
    AssignSubtree(plan, n.low, r0, low, leaves, cost);
    AssignSubtree(plan, n.high, r0 + low, ranks - low, leaves, cost);
}

}  // namespace

void AssignRanks(BrickPlan& plan, int ranks) {
    plan.rank.assign(plan.cost.size(), 0);
    std::vector<int> leaves(plan.tree.nodes.size());
    std::vector<double> cost(plan.tree.nodes.size());
    SubtreeTotals(plan, plan.tree.root, leaves, cost);
    AssignSubtree(plan, plan.tree.root, 0, ranks, leaves, cost);
}

/// The plan of an in-memory split from the pre-pass cost samples (every rank holds the
/// whole mesh and clips its rays to its box, so planes may cut cells); without samples
/// (the mesh is not in view) each cell's guaranteed box weighs one.
BrickPlan SplitMesh(const Mesh& mesh, const MeshGeometry& geometry, int count,
                    const std::vector<SegmentCostSample>& samples) {
    std::vector<partition::WorkExtent> items;
    double sum = 0;
    for (const SegmentCostSample& s : samples) sum += s.seconds;
    if (sum > 0) {
        items.reserve(samples.size());
        for (const SegmentCostSample& s : samples) {
            partition::WorkExtent x;
            for (int d = 0; d < 3; ++d) {
                x.lo[d] = std::min(s.enter[d], s.exit[d]);
                x.hi[d] = std::max(s.enter[d], s.exit[d]);
                x.occluder[d] = s.occluder[d];
            }
            x.weight = s.seconds;
            x.occluded = s.occluded;
            items.push_back(x);
        }
    } else {
        for (std::int64_t c = 0; c < mesh.CellCount(); ++c) {
            const Box b = geometry.CellBox(c);
            items.push_back({b.lo, b.hi, 1.0, false, {}});
        }
    }
    // Planes snap to node coordinates: exactly where axis-aligned faces lie.
    std::array<std::vector<double>, 3> bounds;
    for (int d = 0; d < 3; ++d) {
        bounds[d].reserve(mesh.PointCount());
        for (std::int64_t i = 0; i < mesh.PointCount(); ++i)
            bounds[d].push_back(mesh.points[3 * i + d]);
        std::sort(bounds[d].begin(), bounds[d].end());
        bounds[d].erase(std::unique(bounds[d].begin(), bounds[d].end()), bounds[d].end());
    }
    const partition::WorkSplit split =
        partition::SplitWork(items, count, geometry.bounds, bounds);
    BrickPlan plan;
    plan.tree = split.tree;
    plan.boxes = split.boxes;
    plan.cost = split.cost;
    return plan;
}

/// Sends rank 0's plan (tree, boxes, costs) to every rank.
void BroadcastPlan(BrickPlan& plan) {
    std::vector<double> buffer;
    if (mpi::Root()) {
        buffer.push_back(static_cast<double>(plan.tree.nodes.size()));
        buffer.push_back(static_cast<double>(plan.cost.size()));
        buffer.push_back(static_cast<double>(plan.tree.root));
        buffer.insert(buffer.end(), plan.tree.box.lo.begin(), plan.tree.box.lo.end());
        buffer.insert(buffer.end(), plan.tree.box.hi.begin(), plan.tree.box.hi.end());
        for (const KdNode& n : plan.tree.nodes)
            buffer.insert(buffer.end(), {double(n.axis), n.split, double(n.low),
                                         double(n.high), double(n.leaf)});
        buffer.insert(buffer.end(), plan.cost.begin(), plan.cost.end());
    }
    long long size = static_cast<long long>(buffer.size());
    MPI_Bcast(&size, 1, MPI_LONG_LONG, 0, MPI_COMM_WORLD);
    buffer.resize(static_cast<std::size_t>(size));
    MPI_Bcast(buffer.data(), static_cast<int>(size), MPI_DOUBLE, 0, MPI_COMM_WORLD);
    if (mpi::Root()) return;
    std::size_t at = 0;
    const auto nodes = static_cast<std::size_t>(buffer[at++]);
    const auto boxes = static_cast<std::size_t>(buffer[at++]);
    plan.tree.root = static_cast<int>(buffer[at++]);
    for (int d = 0; d < 3; ++d) plan.tree.box.lo[d] = buffer[at++];
    for (int d = 0; d < 3; ++d) plan.tree.box.hi[d] = buffer[at++];
    plan.tree.nodes.assign(nodes, {});
    for (KdNode& n : plan.tree.nodes) {
        n.axis = static_cast<int>(buffer[at++]);
        n.split = buffer[at++];
        n.low = static_cast<int>(buffer[at++]);
        n.high = static_cast<int>(buffer[at++]);
        n.leaf = static_cast<int>(buffer[at++]);
    }
    plan.cost.assign(buffer.begin() + at, buffer.begin() + at + boxes);
    plan.boxes = plan.tree.LeafBoxes();
}

BrickPlan PlanFromPartition(const partition::Partition& part) {
    BrickPlan plan;
    plan.tree = part.tree;
    for (const partition::BrickInfo& b : part.bricks) {
        plan.boxes.push_back(b.box);
        plan.cost.push_back(b.cost);
    }
    return plan;
}

}  // namespace hpray::job
