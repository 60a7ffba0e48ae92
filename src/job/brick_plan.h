// The bricks of a distributed render and which rank renders each.
#pragma once

#include <vector>

#include "elements/mesh_geometry.h"
#include "geom/kd_tree.h"
#include "partition.h"
#include "render/brick_renderer.h"

namespace hpray::job {

/// The bricks of a job: a k-d tree over bricks (leaves numbered by brick), their boxes
/// (the ownership rule of geom/box.h) and estimated costs, and which rank renders each.
struct BrickPlan {
    KdTree tree;
    std::vector<Box> boxes;
    std::vector<double> cost;
    std::vector<int> rank;
};

/// Fills plan.rank for `ranks` ranks (at most the number of bricks): ranks own whole
/// subtrees; a node given n ranks splits them between its children in proportion to
/// their cost, at least one each and no more than each has leaves.
void AssignRanks(BrickPlan& plan, int ranks);

/// The plan of an in-memory split of a whole mesh into `count` boxes from the pre-pass
/// cost samples (every rank holds the whole mesh and clips its rays to its box, so planes
/// may cut cells); without samples (the mesh is not in view) each cell's guaranteed box
/// weighs one.
BrickPlan SplitMesh(const Mesh& mesh, const MeshGeometry& geometry, int count,
                    const std::vector<SegmentCostSample>& samples);

/// Sends rank 0's plan (tree, boxes, costs) to every rank. Collective.
void BroadcastPlan(BrickPlan& plan);

/// The plan of a partition directory (ranks not yet assigned).
BrickPlan PlanFromPartition(const partition::Partition& part);

}  // namespace hpray::job
