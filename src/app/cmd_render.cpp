// hpray render: one process or many MPI ranks, a mesh or a partition directory. Bricks are
// k-d leaves; ranks own whole subtrees, render their bricks front to back (rays clipped to
// each brick's box), and the compositor assembles the image in exact visibility order.
#include <mpi.h>
#include <tbb/info.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <functional>
#include <set>

#include "app/commands.h"
#include "compositor.h"
#include "elements/bounds.h"
#include "elements/mesh_geometry.h"
#include "io/mesh_io.h"
#include "partition.h"
#include "render/render_job.h"
#include "scene/camera.h"
#include "scene/scene.h"
#include "util/error.h"
#include "util/log.h"
#include "util/mpi.h"

namespace hpray::app {
namespace {

double Seconds(std::chrono::steady_clock::time_point since) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

/// The bricks of a job: a k-d tree over bricks (node 0 is the root), their boxes and
/// estimated costs, and which rank renders each.
struct BrickPlan {
    std::vector<compositor::BrickTreeNode> tree;
    std::vector<AxisBox> boxes;
    std::vector<double> cost;
    std::vector<int> rank;
};

AxisBox ToAxisBox(const partition::Box& b) { return {b.lo, b.hi}; }

/// Leaves and cost under each node.
void SubtreeTotals(const BrickPlan& plan, int node, std::vector<int>& leaves,
                   std::vector<double>& cost) {
    const auto& n = plan.tree[node];
    if (n.axis < 0) {
        leaves[node] = 1;
        cost[node] = std::max(plan.cost[n.brick], 1e-12);
        return;
    }
    SubtreeTotals(plan, n.low, leaves, cost);
    SubtreeTotals(plan, n.high, leaves, cost);
    leaves[node] = leaves[n.low] + leaves[n.high];
    cost[node] = cost[n.low] + cost[n.high];
}

/// Ranks own whole subtrees: a node given P ranks splits them between its children in
/// proportion to their cost, at least one each and no more than each has leaves.
void AssignRanks(BrickPlan& plan, int node, int r0, int ranks, const std::vector<int>& leaves,
                 const std::vector<double>& cost) {
    const auto& n = plan.tree[node];
    if (ranks == 1 || n.axis < 0) {
        std::function<void(int)> own = [&](int x) {
            const auto& m = plan.tree[x];
            if (m.axis < 0) {
                plan.rank[m.brick] = r0;
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
    AssignRanks(plan, n.low, r0, low, leaves, cost);
    AssignRanks(plan, n.high, r0 + low, ranks - low, leaves, cost);
}

/// Estimated render cost of each cell for a scene: in a scene of isosurfaces only, a cell
/// whose guaranteed range holds an isovalue is projected and root-searched (about its line
/// degree + 1 field samples, weighed here as twice that against a traversal step); the
/// others are only traversed. Scenes with a volume or slices weigh every cell the same.
std::vector<double> CellCosts(const Mesh& mesh, const MeshGeometry& geometry,
                              const Scene& scene) {
    std::vector<double> cost(mesh.CellCount(), 1.0);
    if (scene.volume || !scene.slices.empty() || scene.isosurfaces.empty()) return cost;
    std::vector<double> nodal;
    for (const SceneIsosurface& iso : scene.isosurfaces) {
        const auto sel = SelectScalar(mesh, iso.field);
        if (!sel || sel->field->association != Association::Point) continue;
        for (std::int64_t c = 0; c < mesh.CellCount(); ++c) {
            GatherCellValues(mesh, *sel->field, sel->component, c, nodal);
            const BasisTable& basis = *geometry.cells[c].basis;
            const Interval r = FieldBounds(basis, nodal.data());
            if (iso.value >= r.lo && iso.value <= r.hi)
                cost[c] = std::max(cost[c], 1.0 + 2.0 * (basis.lineDegree + 1));
        }
    }
    return cost;
}

/// An in-memory k-d split of a mesh into `count` boxes by estimated cell cost (weighted
/// median of the cell centroids along the longest axis), tiling the guaranteed bounds of
/// its cells.
BrickPlan SplitMesh(const Mesh& mesh, const MeshGeometry& geometry, int count,
                    const std::vector<double>& cellCost) {
    BrickPlan plan;
    std::vector<std::array<double, 3>> centroid(mesh.CellCount());
    for (std::int64_t c = 0; c < mesh.CellCount(); ++c)
        for (int d = 0; d < 3; ++d)
            centroid[c][d] = 0.5 * (geometry.boxes[c].lo[d] + geometry.boxes[c].hi[d]);
    std::vector<std::int64_t> cells(mesh.CellCount());
    for (std::int64_t c = 0; c < mesh.CellCount(); ++c) cells[c] = c;
    std::function<int(AxisBox, std::int64_t, std::int64_t, int)> build =
        [&](AxisBox box, std::int64_t begin, std::int64_t end, int leaves) -> int {
        const int index = static_cast<int>(plan.tree.size());
        plan.tree.emplace_back();
        if (leaves == 1) {
            plan.tree[index].brick = static_cast<int>(plan.boxes.size());
            plan.boxes.push_back(box);
            double c = 0;
            for (std::int64_t i = begin; i < end; ++i) c += cellCost[cells[i]];
            plan.cost.push_back(c);
            return index;
        }
        int axis = 0;
        for (int d = 1; d < 3; ++d)
            if (box[1][d] - box[0][d] > box[1][axis] - box[0][axis]) axis = d;
        const int lowLeaves = leaves / 2;
        // Weighted median: the first cell where the cost prefix reaches lowLeaves / leaves.
        std::sort(cells.begin() + begin, cells.begin() + end, [&](std::int64_t a, std::int64_t b) {
            return centroid[a][axis] < centroid[b][axis];
        });
        double total = 0;
        for (std::int64_t i = begin; i < end; ++i) total += cellCost[cells[i]];
        const double target = total * lowLeaves / leaves;
        std::int64_t mid = begin;
        for (double acc = 0; mid < end && acc + cellCost[cells[mid]] <= target; ++mid)
            acc += cellCost[cells[mid]];
        double split = end > begin ? centroid[cells[mid]][axis] : 0.5 * (box[0][axis] + box[1][axis]);
        split = std::clamp(split, box[0][axis], box[1][axis]);
        AxisBox lowBox = box, highBox = box;
        lowBox[1][axis] = split;
        highBox[0][axis] = split;
        plan.tree[index].axis = axis;
        plan.tree[index].split = split;
        const int lo = build(lowBox, begin, mid, lowLeaves);
        const int hi = build(highBox, mid, end, leaves - lowLeaves);
        plan.tree[index].low = lo;
        plan.tree[index].high = hi;
        return index;
    };
    const AxisBox root{geometry.bounds.lo, geometry.bounds.hi};
    build(root, 0, mesh.CellCount(), count);
    return plan;
}

BrickPlan PlanFromPartition(const partition::Partition& part) {
    BrickPlan plan;
    for (const partition::KdNode& n : part.nodes) {
        compositor::BrickTreeNode b;
        b.axis = n.axis;
        b.split = n.split;
        b.low = n.low;
        b.high = n.high;
        b.brick = n.brick;
        plan.tree.push_back(b);
    }
    for (const partition::BrickInfo& b : part.bricks) {
        plan.boxes.push_back(ToAxisBox(b.box));
        plan.cost.push_back(b.cost);
    }
    return plan;
}

/// This rank's bricks, front to back for the view.
void MyBricksFrontToBack(const BrickPlan& plan, int node, int rank,
                         const compositor::CompositeView& view, std::vector<int>& out) {
    const auto& n = plan.tree[node];
    if (n.axis < 0) {
        if (plan.rank[n.brick] == rank) out.push_back(n.brick);
        return;
    }
    const bool lowFirst = compositor::LowInFront(n.axis, n.split, view);
    MyBricksFrontToBack(plan, lowFirst ? n.low : n.high, rank, view, out);
    MyBricksFrontToBack(plan, lowFirst ? n.high : n.low, rank, view, out);
}

bool BoxesOverlap(const AxisBox& a, const std::array<std::array<double, 3>, 2>& b) {
    for (int d = 0; d < 3; ++d)
        if (a[1][d] < b[0][d] || b[1][d] < a[0][d]) return false;
    return true;
}

/// True when the box lies entirely outside the camera's view: all its corners are on the
/// outer side of one bounding plane of the view volume (perspective: the four side planes
/// through the eye and the near/far distances along the view direction; orthographic: the
/// four side slabs). Conservative: a box that may be seen is never reported outside.
bool OutsideView(const Scene& scene, const AxisBox& box) {
    const Camera camera(scene.camera);
    const auto& f = camera.Forward();
    const auto& r = camera.Right();
    const auto& u = camera.TrueUp();
    const auto& e = camera.Position();
    const double aspect = double(scene.camera.width) / scene.camera.height;
    std::array<std::array<double, 3>, 8> rel;
    for (int q = 0; q < 8; ++q)
        for (int d = 0; d < 3; ++d) rel[q][d] = box[(q >> d) & 1][d] - e[d];
    auto dot = [](const std::array<double, 3>& a, const std::array<double, 3>& b) {
        return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    };
    auto allOutside = [&](auto&& signedDistance) {
        for (const auto& x : rel)
            if (signedDistance(x) <= 0) return false;
        return true;
    };
    // Behind the near limit or beyond the far one (along the forward axis; a ray's t is at
    // least its forward component, so this is conservative for perspective too).
    if (allOutside([&](const auto& x) { return dot(x, f) - scene.clip.far; })) return true;
    if (allOutside([&](const auto& x) { return -dot(x, f); }) && !scene.camera.orthographic)
        return true;
    if (scene.camera.orthographic) {
        const double hy = 0.5 * scene.camera.orthoHeight, hx = hy * aspect;
        if (allOutside([&](const auto& x) { return dot(x, r) - hx; })) return true;
        if (allOutside([&](const auto& x) { return -dot(x, r) - hx; })) return true;
        if (allOutside([&](const auto& x) { return dot(x, u) - hy; })) return true;
        if (allOutside([&](const auto& x) { return -dot(x, u) - hy; })) return true;
        return false;
    }
    const double ty = std::tan(0.5 * scene.camera.fovYDegrees * M_PI / 180), tx = ty * aspect;
    // Side planes through the eye: outside when |x.r| > tx (x.f), etc.
    if (allOutside([&](const auto& x) { return dot(x, r) - tx * dot(x, f); })) return true;
    if (allOutside([&](const auto& x) { return -dot(x, r) - tx * dot(x, f); })) return true;
    if (allOutside([&](const auto& x) { return dot(x, u) - ty * dot(x, f); })) return true;
    if (allOutside([&](const auto& x) { return -dot(x, u) - ty * dot(x, f); })) return true;
    return false;
}

/// A brick of a partition can contribute unless it lies outside the view or the clip box
/// or, in a scene of isosurfaces only, no isovalue lies in its guaranteed field ranges.
bool BrickMayContribute(const Scene& scene, const partition::BrickInfo& brick,
                        const AxisBox& box) {
    if (scene.clip.box && !BoxesOverlap(box, *scene.clip.box)) return false;
    if (OutsideView(scene, box)) return false;
    if (scene.volume || !scene.slices.empty()) return true;
    for (const SceneIsosurface& iso : scene.isosurfaces) {
        std::string name = iso.field;
        auto it = brick.ranges.find(name);
        if (it == brick.ranges.end()) return true;  // no range recorded: be conservative
        if (iso.value >= it->second[0] && iso.value <= it->second[1]) return true;
    }
    return false;
}

void ReduceStats(RenderStats& stats, int bricksLoaded) {
    auto counters = stats.counters.ToArray();
    std::array<double, RenderCounters::kSize> sum{}, max{};
    MPI_Reduce(counters.data(), sum.data(), RenderCounters::kSize, MPI_DOUBLE, MPI_SUM, 0,
               MPI_COMM_WORLD);
    MPI_Reduce(counters.data(), max.data(), RenderCounters::kSize, MPI_DOUBLE, MPI_MAX, 0,
               MPI_COMM_WORLD);
    for (int i = 0; i < RenderCounters::kSize; ++i)
        counters[i] = RenderCounters::IsMax(i) ? max[i] : sum[i];
    double times[5] = {stats.timing.load, stats.timing.accel, stats.timing.render,
                       stats.timing.composite, stats.timing.total};
    double timesMax[5];
    MPI_Reduce(times, timesMax, 5, MPI_DOUBLE, MPI_MAX, 0, MPI_COMM_WORLD);
    double range[2] = {stats.isoFieldRange[0], -stats.isoFieldRange[1]}, rangeMin[2];
    MPI_Reduce(range, rangeMin, 2, MPI_DOUBLE, MPI_MIN, 0, MPI_COMM_WORLD);
    int loaded = 0;
    MPI_Reduce(&bricksLoaded, &loaded, 1, MPI_INT, MPI_SUM, 0, MPI_COMM_WORLD);
    double bytes = stats.accelBytes, bytesSum = 0;
    MPI_Reduce(&bytes, &bytesSum, 1, MPI_DOUBLE, MPI_SUM, 0, MPI_COMM_WORLD);
    if (mpi::Root()) {
        stats.counters = RenderCounters::FromArray(counters);
        stats.timing.load = timesMax[0];
        stats.timing.accel = timesMax[1];
        stats.timing.render = timesMax[2];
        stats.timing.composite = timesMax[3];
        stats.timing.total = timesMax[4];
        stats.isoFieldRange = {rangeMin[0], -rangeMin[1]};
        stats.bricksLoaded = loaded;
        stats.accelBytes = bytesSum;
    }
}

/// Threads per rank when the scene does not say: the cores of this node shared by the
/// ranks on it.
int DefaultThreads() {
    MPI_Comm node;
    MPI_Comm_split_type(MPI_COMM_WORLD, MPI_COMM_TYPE_SHARED, 0, MPI_INFO_NULL, &node);
    int onNode = 1;
    MPI_Comm_size(node, &onNode);
    MPI_Comm_free(&node);
    return std::max(1, tbb::info::default_concurrency() / onNode);
}

}  // namespace

int RunRender(const RenderArgs& args) {
    const auto start = std::chrono::steady_clock::now();
    Scene scene = LoadScene(args.scene, args.overrides);
    const int P = mpi::WorldSize(), rank = mpi::WorldRank();
    const bool isPartition = partition::IsPartitionDirectory(scene.data.mesh);
    if (P == 1 && !isPartition) {
        RenderStats stats;
        RunRenderJob(scene, stats);
        char line[512];
        std::snprintf(line, sizeof line,
                      "rendered %dx%d in %.3f s (load %.3f, accel %.3f, render %.3f, write "
                      "%.3f) on %d threads: %.0f hits, max residual %.3g (%.3g of the field "
                      "range), %.0f root failures, %.0f mapping failures",
                      stats.width, stats.height, stats.timing.total, stats.timing.load,
                      stats.timing.accel, stats.timing.render, stats.timing.write,
                      stats.threads, stats.counters.isoHits, stats.counters.isoResidualMax,
                      stats.counters.isoResidualRelMax, stats.counters.rootFailures,
                      stats.counters.inversionFailures);
        log::Info(line);
        return 0;
    }
    if (scene.threads == 0 && P > 1) scene.threads = DefaultThreads();
    RenderStats stats = StartStats(scene);
    stats.ranks = P;

    ReadOptions options;
    std::set<std::string> fields;
    for (const std::string& name : scene.FieldNames()) fields.insert(name);
    options.fields = fields;

    // The plan: the partition's bricks, or an in-memory split of a small mesh into P boxes
    // (every rank then holds the whole mesh and clips its rays to its own box).
    auto t0 = std::chrono::steady_clock::now();
    std::optional<partition::Partition> part;
    std::optional<Mesh> whole;
    BrickPlan plan;
    if (isPartition) {
        part = partition::ReadPartition(scene.data.mesh);
        plan = PlanFromPartition(*part);
    } else {
        whole = ReadMesh(scene.data.mesh, options);
        const MeshGeometry geometry = MeshGeometry::Build(*whole);
        plan = SplitMesh(*whole, geometry, P, CellCosts(*whole, geometry, scene));
    }
    const int bricks = static_cast<int>(plan.boxes.size());
    if (bricks < P)
        throw InputError(scene.data.mesh, "",
                         "has " + std::to_string(bricks) + " bricks, fewer than the " +
                             std::to_string(P) + " MPI ranks; partition it into at least " +
                             std::to_string(P) + " bricks");
    plan.rank.assign(bricks, 0);
    {
        std::vector<int> leaves(plan.tree.size());
        std::vector<double> cost(plan.tree.size());
        SubtreeTotals(plan, 0, leaves, cost);
        AssignRanks(plan, 0, 0, P, leaves, cost);
    }
    stats.bricksTotal = bricks;
    stats.timing.load += Seconds(t0);

    const compositor::CompositeView view = compositor::ViewFromCamera(scene.camera);
    std::vector<int> mine;
    MyBricksFrontToBack(plan, 0, rank, view, mine);

    Image accumulated;
    accumulated.Resize(scene.camera.width, scene.camera.height);
    int loaded = 0;
    for (int b : mine) {
        if (part && !BrickMayContribute(scene, part->bricks[b], plan.boxes[b])) continue;
        Image image;
        if (part) {
            t0 = std::chrono::steady_clock::now();
            const Mesh mesh = partition::LoadBrick(*part, b, options);
            stats.timing.load += Seconds(t0);
            RenderOneBrick(mesh, plan.boxes[b], scene, image, stats);
        } else {
            RenderOneBrick(*whole, plan.boxes[b], scene, image, stats);
        }
        ++loaded;
        compositor::CompositeOver(accumulated, image);
    }

    t0 = std::chrono::steady_clock::now();
    compositor::CompositeStats cs;
    if (P > 1) {
        std::vector<compositor::BrickTreeNode> tree = plan.tree;
        const compositor::CompositeTree rankTree =
            compositor::BuildRankTree(tree, 0, plan.rank, P);
        cs = compositor::Composite(accumulated, rankTree, view, MPI_COMM_WORLD);
    }
    stats.timing.composite = Seconds(t0);
    stats.timing.total = Seconds(start);
    ReduceStats(stats, loaded);
    if (P > 1) {
        stats.composite.rounds = cs.rounds;
        stats.composite.bytesPerPixel = cs.bytesPerPixel;
        stats.composite.bytesSentMax = static_cast<double>(cs.bytesSentMax);
        stats.composite.bytesSentTotal = static_cast<double>(cs.bytesSentTotal);
        stats.composite.bytesGather = static_cast<double>(cs.bytesGather);
    }
    if (mpi::Root()) {
        WriteJobOutputs(scene, accumulated, stats);
        char line[512];
        std::snprintf(line, sizeof line,
                      "rendered %dx%d on %d ranks x %d threads in %.3f s (render %.3f, "
                      "composite %.3f): %d of %d bricks loaded, %.0f hits, max residual %.3g",
                      stats.width, stats.height, P, stats.threads, stats.timing.total,
                      stats.timing.render, stats.timing.composite, stats.bricksLoaded,
                      stats.bricksTotal, stats.counters.isoHits, stats.counters.isoResidualMax);
        log::Info(line);
    }
    return 0;
}

}  // namespace hpray::app
