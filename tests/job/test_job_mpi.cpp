// The distributed render job, run with 2 and 3 ranks: rank assignment by whole subtrees,
// tile dealing (every tile to exactly one rank), and a job that renders several cameras
// giving the images of one job per camera.
#include <gtest/gtest.h>
#include <mpi.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <random>
#include <set>
#include <vector>

#include "job/brick_plan.h"
#include "job/frame_job.h"
#include "composite_tree.h"
#include "job/tile_dealer.h"
#include "scene/scene.h"
#include "util/mpi.h"
#include "mpi/mpi_test_main.h"

namespace hpray {
namespace {

/// Leaves (brick numbers) under node `id`.
void LeavesBelow(const KdTree& tree, int id, std::vector<int>& out) {
    const KdNode& n = tree.nodes[id];
    if (n.IsLeaf()) {
        out.push_back(n.leaf);
        return;
    }
    LeavesBelow(tree, n.low, out);
    LeavesBelow(tree, n.high, out);
}

TEST(AssignRanks, EveryRankOwnsOneWholeSubtreeAndCostIsShared) {
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> costDist(0.1, 10.0);
    for (int bricks = 1; bricks <= 24; ++bricks)
        for (int ranks = 1; ranks <= bricks; ++ranks) {
            job::BrickPlan plan;
            plan.tree = RegularKdTree(bricks, Box{{0, 0, 0}, {1, 1, 1}});
            for (int b = 0; b < bricks; ++b) plan.cost.push_back(costDist(rng));
            plan.boxes = plan.tree.LeafBoxes();
            job::AssignRanks(plan, ranks);
            ASSERT_EQ(static_cast<int>(plan.rank.size()), bricks);
            // Each rank's bricks are exactly the leaves of one node.
            for (int r = 0; r < ranks; ++r) {
                std::vector<int> mine;
                for (int b = 0; b < bricks; ++b)
                    if (plan.rank[b] == r) mine.push_back(b);
                ASSERT_FALSE(mine.empty()) << bricks << " bricks, rank " << r;
                bool whole = false;
                for (std::size_t id = 0; id < plan.tree.nodes.size() && !whole; ++id) {
                    std::vector<int> below;
                    LeavesBelow(plan.tree, static_cast<int>(id), below);
                    std::sort(below.begin(), below.end());
                    whole = below == mine;
                }
                EXPECT_TRUE(whole) << bricks << " bricks, " << ranks << " ranks, rank " << r;
            }
            // The compositor accepts the assignment.
            EXPECT_NO_THROW(compositor::BuildRankTree(plan.tree, plan.rank, ranks));
        }
}

TEST(TileDealer, EveryTileGoesToExactlyOneRank) {
    const int P = mpi::WorldSize();
    for (int tiles : {1, 7, 100, 1000})
        for (int chunk : {1, 3, 16}) {
            std::vector<int> mine;
            {
                job::TileDealer dealer(tiles, chunk);
                int begin = 0, end = 0;
                while (dealer.Next(begin, end)) {
                    ASSERT_LT(begin, end);
                    ASSERT_LE(end, tiles);
                    for (int t = begin; t < end; ++t) mine.push_back(t);
                }
            }
            std::vector<int> count(tiles, 0), all(tiles, 0);
            for (int t : mine) ++count[t];
            MPI_Allreduce(count.data(), all.data(), tiles, MPI_INT, MPI_SUM, MPI_COMM_WORLD);
            for (int t = 0; t < tiles; ++t)
                ASSERT_EQ(all[t], 1) << "tile " << t << " of " << tiles << ", chunk " << chunk
                                     << ", " << P << " ranks";
        }
}

const char* kScene = R"(
data: {mesh: "builtin:ball-p2"}
camera: {position: [2.6, 1.8, 3.4], look_at: [0, 0, 0], fov_y: 35, width: 40, height: 36}
isosurfaces:
  - {field: u, value: 0.25, color: [0.85, 0.3, 0.2], opacity: 1.0}
  - {field: u, value: 0.81, color: [0.2, 0.5, 0.9], opacity: 0.35}
)";

/// Every channel within `tolerance` (0: bit for bit), NaN and infinity where the other has
/// them.
void ExpectSame(const Image& a, const Image& b, double tolerance, const std::string& what) {
    const auto x = a.Channels(), y = b.Channels();
    ASSERT_EQ(x.size(), y.size());
    std::size_t differing = 0;
    for (std::size_t k = 0; k < x.size(); ++k)
        for (std::size_t i = 0; i < x[k].second->size(); ++i) {
            const double u = (*x[k].second)[i], v = (*y[k].second)[i];
            if (!std::isfinite(u) || !std::isfinite(v))
                differing += std::isnan(u) ? !std::isnan(v) : u != v;
            else
                differing += !(std::abs(u - v) <= tolerance);
        }
    EXPECT_EQ(differing, 0u) << what;
}

// The job keeps its data and preparation across frames: its frames are the images of a
// fresh job per camera, for the image split (bit for bit) and the space split (to 1e-6:
// its planes follow a timed pre-pass, so they may differ from run to run), and for the
// job's second use of a camera.
TEST(FrameJob, FramesOfOneJobEqualOneJobPerCamera) {
    for (const char* distribute : {"image", "space"}) {
        const double tolerance = std::string(distribute) == "image" ? 0.0 : 1e-6;
        const Scene scene =
            ParseScene(std::string(kScene) + "distribute: " + distribute + "\n", "job.yaml",
                       {}, "");
        std::vector<SceneCamera> cameras(3, scene.camera);
        cameras[1].position = {0.1, -0.2, 0.3};
        cameras[1].lookAt = {1, 1, 1};
        cameras[1].fovYDegrees = 90;
        cameras[2].orthographic = true;
        cameras[2].orthoHeight = 2.4;
        cameras[2].position = {3, 0.5, 0.2};
        job::FrameJob kept(scene);
        std::vector<Image> frames;
        for (const SceneCamera& c : cameras) {
            RenderStats stats;
            frames.push_back(kept.Render(c, stats));
            if (mpi::Root()) {
                EXPECT_GT(stats.counters.isoHits, 0) << distribute;
                // Only the first frame pays the preparation.
                if (frames.size() > 1) {
                    EXPECT_EQ(stats.timing.accel, 0) << distribute;
                }
            }
        }
        RenderStats again;
        frames.push_back(kept.Render(cameras[0], again));
        for (std::size_t k = 0; k < cameras.size(); ++k) {
            Scene one = scene;
            one.camera = cameras[k];
            job::FrameJob fresh(one);
            RenderStats stats;
            const Image image = fresh.Render(std::nullopt, stats);
            if (mpi::Root())
                ExpectSame(image, frames[k], tolerance,
                           std::string(distribute) + " camera " + std::to_string(k));
        }
        if (mpi::Root()) ExpectSame(frames[0], frames[3], tolerance, "the first camera again");
    }
}

}  // namespace
}  // namespace hpray
