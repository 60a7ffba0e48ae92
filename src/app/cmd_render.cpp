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
#include <limits>
#include <set>

#include <unistd.h>

#include "app/commands.h"
#include "compositor.h"
#include "elements/bounds.h"
#include "elements/mesh_geometry.h"
#include "io/mesh_io.h"
#include "partition.h"
#include "work_split.h"
#include "render/brick_renderer.h"
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

/// The bricks of a job: a k-d tree over bricks (leaves numbered by brick), their boxes
/// (the ownership rule of geom/box.h) and estimated costs, and which rank renders each.
struct BrickPlan {
    KdTree tree;
    std::vector<Box> boxes;
    std::vector<double> cost;
    std::vector<int> rank;
};

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
void AssignRanks(BrickPlan& plan, int node, int r0, int ranks, const std::vector<int>& leaves,
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
    AssignRanks(plan, n.low, r0, low, leaves, cost);
    AssignRanks(plan, n.high, r0 + low, ranks - low, leaves, cost);
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
        for (const Box& b : geometry.boxes) items.push_back({b.lo, b.hi, 1.0, false, {}});
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


/// True when the box lies entirely outside the camera's view: all its corners are on the
/// outer side of one bounding plane of the view volume (perspective: the four side planes
/// through the eye and the near/far distances along the view direction; orthographic: the
/// four side slabs). Conservative: a box that may be seen is never reported outside.
bool OutsideView(const Scene& scene, const Box& box) {
    const Camera camera(scene.camera);
    const auto& f = camera.Forward();
    const auto& r = camera.Right();
    const auto& u = camera.TrueUp();
    const auto& e = camera.Position();
    const double aspect = double(scene.camera.width) / scene.camera.height;
    std::array<std::array<double, 3>, 8> rel;
    for (int q = 0; q < 8; ++q)
        for (int d = 0; d < 3; ++d) rel[q][d] = ((q >> d) & 1 ? box.hi : box.lo)[d] - e[d];
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
                        const Box& box) {
    if (scene.clip.box && !box.Touches(*scene.clip.box)) return false;
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

/// Reduces the stats of all ranks into rank 0's. `wholeMeshEverywhere`: every rank
/// prepared the same whole mesh, so its non-conforming faces are counted once, not summed.
void ReduceStats(RenderStats& stats, int bricksLoaded, bool wholeMeshEverywhere) {
    auto counters = stats.counters.ToArray();
    std::array<double, RenderCounters::kSize> sum{}, max{};
    MPI_Reduce(counters.data(), sum.data(), RenderCounters::kSize, MPI_DOUBLE, MPI_SUM, 0,
               MPI_COMM_WORLD);
    MPI_Reduce(counters.data(), max.data(), RenderCounters::kSize, MPI_DOUBLE, MPI_MAX, 0,
               MPI_COMM_WORLD);
    for (int i = 0; i < RenderCounters::kSize; ++i)
        counters[i] = RenderCounters::IsMax(i) ? max[i] : sum[i];
    double times[8] = {stats.timing.load,      stats.timing.accel,   stats.timing.render,
                       stats.timing.composite, stats.timing.total,   stats.timing.prepass,
                       stats.timing.wait,      -stats.timing.render};
    double timesMax[8];
    MPI_Reduce(times, timesMax, 8, MPI_DOUBLE, MPI_MAX, 0, MPI_COMM_WORLD);
    double range[2] = {stats.isoFieldRange[0], -stats.isoFieldRange[1]}, rangeMin[2];
    MPI_Reduce(range, rangeMin, 2, MPI_DOUBLE, MPI_MIN, 0, MPI_COMM_WORLD);
    int loaded = 0;
    MPI_Reduce(&bricksLoaded, &loaded, 1, MPI_INT, MPI_SUM, 0, MPI_COMM_WORLD);
    TraversalStats& tr = stats.traversal;
    double meshCounts[3] = {tr.nonConformingFaces, tr.nonConformingEdges, tr.nonConformity};
    double meshSum[3], meshMax[3];
    MPI_Reduce(meshCounts, meshSum, 3, MPI_DOUBLE, MPI_SUM, 0, MPI_COMM_WORLD);
    MPI_Reduce(meshCounts, meshMax, 3, MPI_DOUBLE, MPI_MAX, 0, MPI_COMM_WORLD);
    double walk[3] = {tr.walkRepairs, tr.walkFailures, tr.faceNewtonFailures}, walkSum[3];
    MPI_Reduce(walk, walkSum, 3, MPI_DOUBLE, MPI_SUM, 0, MPI_COMM_WORLD);
    double bytes = stats.accelBytes, bytesSum = 0;
    MPI_Reduce(&bytes, &bytesSum, 1, MPI_DOUBLE, MPI_SUM, 0, MPI_COMM_WORLD);
    if (mpi::Root()) {
        stats.counters = RenderCounters::FromArray(counters);
        stats.timing.load = timesMax[0];
        stats.timing.accel = timesMax[1];
        stats.timing.render = timesMax[2];
        stats.timing.composite = timesMax[3];
        stats.timing.total = timesMax[4];
        stats.timing.prepass = timesMax[5];
        stats.timing.wait = timesMax[6];
        stats.timing.renderMin = -timesMax[7];
        stats.isoFieldRange = {rangeMin[0], -rangeMin[1]};
        stats.bricksLoaded = loaded;
        stats.accelBytes = bytesSum;
        tr.nonConformingFaces = wholeMeshEverywhere ? meshMax[0] : meshSum[0];
        tr.nonConformingEdges = wholeMeshEverywhere ? meshMax[1] : meshSum[1];
        tr.nonConformity = meshMax[2];
        tr.walkRepairs = walkSum[0];
        tr.walkFailures = walkSum[1];
        tr.faceNewtonFailures = walkSum[2];
    }
}

/// Deals the tiles of an image out to ranks as they become free: a counter on rank 0
/// that every rank advances with an atomic one-sided fetch-and-add (MPI-3 passive target),
/// so no rank waits for another to hand out work. Collective to create and to destroy.
class TileDealer {
  public:
    TileDealer(int tiles, int chunk) : tiles_(tiles), chunk_(chunk) {
        MPI_Win_allocate(mpi::Root() ? sizeof(long long) : 0, sizeof(long long),
                         MPI_INFO_NULL, MPI_COMM_WORLD, &counter_, &window_);
        MPI_Win_lock_all(0, window_);
        if (mpi::Root()) {
            *counter_ = 0;
            MPI_Win_sync(window_);
        }
        MPI_Barrier(MPI_COMM_WORLD);
    }
    ~TileDealer() {
        MPI_Win_unlock_all(window_);
        MPI_Win_free(&window_);
    }
    TileDealer(const TileDealer&) = delete;
    TileDealer& operator=(const TileDealer&) = delete;

    /// The next chunk [begin, end) of tiles for this rank; false when all are dealt.
    bool Next(int& begin, int& end) {
        const long long add = chunk_;
        long long got = 0;
        MPI_Fetch_and_op(&add, &got, MPI_LONG_LONG, 0, 0, MPI_SUM, window_);
        MPI_Win_flush(0, window_);
        if (got >= tiles_) return false;
        begin = static_cast<int>(got);
        end = static_cast<int>(std::min<long long>(got + chunk_, tiles_));
        ++chunks_;
        return true;
    }
    int Chunks() const { return chunks_; }

  private:
    int tiles_, chunk_, chunks_ = 0;
    long long* counter_ = nullptr;
    MPI_Win window_ = MPI_WIN_NULL;
};

/// Threads per rank when the scene does not say: the cores of this node shared by the
/// ranks on it.
int DefaultThreads() {
    MPI_Comm node;
    MPI_Comm_split_type(MPI_COMM_WORLD, MPI_COMM_TYPE_SHARED, 0, MPI_INFO_NULL, &node);
    int onNode = 1;
    MPI_Comm_size(node, &onNode);
    MPI_Comm_free(&node);
    // The cores this rank may run on (its affinity mask) against the node's: a launcher
    // that bound the rank to fewer cores has already given it its share.
    const int allowed = tbb::info::default_concurrency();
    const long online = sysconf(_SC_NPROCESSORS_ONLN);
    if (online > 0 && allowed < online) return std::max(1, allowed);
    return std::max(1, allowed / onNode);
}

/// Threads beyond the cores a rank may run on only share those cores: say so once.
void WarnIfThreadsExceedBinding(int threads) {
    const int allowed = tbb::info::default_concurrency();
    if (threads <= allowed || !mpi::Root()) return;
    log::Warn("threads is " + std::to_string(threads) + " but this process may run on " +
              (allowed == 1 ? std::string("1 core, so its threads share it")
                            : std::to_string(allowed) + " cores, so its threads share them") +
              "; mpirun binds each rank to one core when it starts 2 ranks or fewer: add "
              "--bind-to none, or a binding that gives each rank as many cores as threads");
}

}  // namespace

int RunRender(const RenderArgs& args) {
    const auto start = std::chrono::steady_clock::now();
    Scene scene = LoadScene(args.scene, args.overrides);
    const int P = mpi::WorldSize(), rank = mpi::WorldRank();
    const bool isPartition = partition::IsPartitionDirectory(scene.data.mesh);
    WarnIfThreadsExceedBinding(scene.threads);
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
    // From here on the job uses collectives (a partition on one process included).
    mpi::EnsureInitialized();
    if (scene.threads == 0 && P > 1) scene.threads = DefaultThreads();
    Distribution mode = scene.distribute;
    if (mode == Distribution::Auto) mode = isPartition ? Distribution::Space : Distribution::Image;
    if (mode == Distribution::Image && isPartition)
        throw InputError(scene.data.mesh, "",
                         "is a partition directory, but distribute: image needs the whole "
                         "mesh on every rank; use distribute: space (or auto) for a "
                         "partition, or give the mesh file");
    RenderStats stats = StartStats(scene);
    stats.ranks = P;
    stats.distribute = mode == Distribution::Image ? "image" : "space";

    ReadOptions options;
    std::set<std::string> fields;
    for (const std::string& name : scene.FieldNames()) fields.insert(name);
    options.fields = fields;

    // The plan: the partition's bricks, or an in-memory split of a small mesh into P boxes
    // (every rank then holds the whole mesh and clips its rays to its own box), or, to
    // split the image instead, the whole mesh on every rank.
    auto t0 = std::chrono::steady_clock::now();
    std::optional<partition::Partition> part;
    std::optional<Mesh> whole;
    BrickPlan plan;
    if (isPartition) {
        part = partition::ReadPartition(scene.data.mesh);
        plan = PlanFromPartition(*part);
    } else {
        whole = ReadMesh(scene.data.mesh, options);
    }
    stats.timing.load += Seconds(t0);
    std::unique_ptr<PreparedBrick> prepared;
    if (whole) prepared = std::make_unique<PreparedBrick>(*whole, std::nullopt, scene, stats);
    if (whole && mode == Distribution::Space) {
        // Rank 0 renders a pre-pass at 1/8 of the resolution, measuring each segment's
        // cost where it lies, and splits space so that each rank's box holds an equal
        // share of the measured cost.
        t0 = std::chrono::steady_clock::now();
        if (mpi::Root()) {
            SceneCamera low = scene.camera;
            low.width = std::min(scene.camera.width, std::max(32, scene.camera.width / 8));
            low.height =
                std::min(scene.camera.height, std::max(32, scene.camera.height / 8));
            std::vector<SegmentCostSample> samples;
            Image preview;
            RenderStats ignored = StartStats(scene);
            prepared->Render(scene, Camera(low), std::nullopt, preview, ignored, &samples);
            plan = SplitMesh(*whole, prepared->Geometry(), P, samples);
            std::string planes;
            for (const KdNode& n : plan.tree.nodes)
                if (n.axis >= 0) {
                    char text[64];
                    std::snprintf(text, sizeof text, " %c=%.17g", "xyz"[n.axis], n.split);
                    planes += text;
                }
            log::Info("split by measured cost (" + std::to_string(samples.size()) +
                      " pre-pass segments):" + planes);
        }
        BroadcastPlan(plan);
        stats.timing.prepass = Seconds(t0);
    }

    const ViewOrigin view = ViewOriginOf(scene.camera);
    Image accumulated;
    accumulated.Resize(scene.camera.width, scene.camera.height);
    int loaded = 0;
    std::unique_ptr<TileDealer> dealer;
    KdTree rankTree;
    if (mode == Distribution::Image) {
        // Every pixel is rendered by exactly one rank, exactly as on one rank; the others
        // leave it empty, which Over leaves unchanged, so any visibility order composites
        // the single-rank image bit for bit.
        const Camera camera(scene.camera);
        const int tiles = RenderTileCount(camera);
        const int chunk = std::max(1, std::min(8 * scene.threads, tiles / (16 * P)));
        dealer = std::make_unique<TileDealer>(tiles, chunk);
        int begin = 0, end = 0;
        while (dealer->Next(begin, end))
            prepared->RenderTiles(scene, camera, begin, end, accumulated, stats);
        loaded = mpi::Root() ? 1 : 0;
        stats.bricksTotal = 1;
        rankTree = RegularKdTree(P, prepared->Geometry().bounds);
    } else {
        t0 = std::chrono::steady_clock::now();
        const int bricks = static_cast<int>(plan.boxes.size());
        if (bricks < P)
            throw InputError(scene.data.mesh, "",
                             "has " + std::to_string(bricks) + " bricks, fewer than the " +
                                 std::to_string(P) + " MPI ranks; partition it into at least " +
                                 std::to_string(P) + " bricks");
        plan.rank.assign(bricks, 0);
        {
            std::vector<int> leaves(plan.tree.nodes.size());
            std::vector<double> cost(plan.tree.nodes.size());
            SubtreeTotals(plan, plan.tree.root, leaves, cost);
            AssignRanks(plan, plan.tree.root, 0, P, leaves, cost);
        }
        stats.bricksTotal = bricks;
        stats.timing.load += Seconds(t0);

        for (int b : plan.tree.FrontToBack(view)) {
            if (plan.rank[b] != rank) continue;
            if (part && !BrickMayContribute(scene, part->bricks[b], plan.boxes[b])) continue;
            Image image;
            if (part) {
                t0 = std::chrono::steady_clock::now();
                const Mesh mesh = partition::LoadBrick(*part, b, options);
                stats.timing.load += Seconds(t0);
                RenderOneBrick(mesh, plan.boxes[b], scene, image, stats, nullptr,
                               &accumulated);
            } else {
                prepared->Render(scene, Camera(scene.camera), plan.boxes[b], image, stats,
                                 nullptr, &accumulated);
            }
            ++loaded;
            CompositeOver(accumulated, image);
        }
        if (P > 1) rankTree = compositor::BuildRankTree(plan.tree, plan.rank, P);
    }

    // Waiting for the slowest rank is imbalance, not compositing: timed apart.
    t0 = std::chrono::steady_clock::now();
    MPI_Barrier(MPI_COMM_WORLD);
    stats.timing.wait = Seconds(t0);
    dealer.reset();
    t0 = std::chrono::steady_clock::now();
    compositor::CompositeStats cs;
    if (P > 1) cs = compositor::Composite(accumulated, rankTree, view, MPI_COMM_WORLD);
    stats.timing.composite = Seconds(t0);
    stats.timing.total = Seconds(start);
    ReduceStats(stats, loaded, !part.has_value());
    if (P > 1) {
        stats.composite.rounds = cs.rounds;
        stats.composite.bytesPerPixel = cs.bytesPerPixel;
        stats.composite.bytesSentMax = static_cast<double>(cs.bytesSentMax);
        stats.composite.bytesSentTotal = static_cast<double>(cs.bytesSentTotal);
        stats.composite.bytesGather = static_cast<double>(cs.bytesGather);
    }
    if (mpi::Root()) {
        WriteJobOutputs(scene, accumulated, stats);
        char split[96];
        if (mode == Distribution::Image)
            std::snprintf(split, sizeof split, "the image split in tiles");
        else
            std::snprintf(split, sizeof split, "%d of %d bricks loaded", stats.bricksLoaded,
                          stats.bricksTotal);
        char line[512];
        std::snprintf(line, sizeof line,
                      "rendered %dx%d on %d ranks x %d threads in %.3f s (render %.3f, "
                      "composite %.3f): %s, %.0f hits, max residual %.3g",
                      stats.width, stats.height, P, stats.threads, stats.timing.total,
                      stats.timing.render, stats.timing.composite, split,
                      stats.counters.isoHits, stats.counters.isoResidualMax);
        log::Info(line);
    }
    return 0;
}

}  // namespace hpray::app
