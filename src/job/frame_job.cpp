// FrameJob: loading and preparation once, frames rendered on every rank and composited
// (moved out of the hpray render command so that a service can keep it).
#include "job/frame_job.h"

#include <mpi.h>
#include <tbb/info.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>
#include <optional>
#include <set>
#include <thread>

#include "compositor.h"
#include "io/mesh_io.h"
#include "job/tile_dealer.h"
#include "mesh/mesh_order.h"
#include "render/annotate.h"
#include "scene/camera.h"
#include "util/error.h"
#include "util/log.h"
#include "util/memory.h"
#include "util/mpi.h"

namespace hpray::job {
namespace {

double Seconds(std::chrono::steady_clock::time_point since) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
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

/// The preparation's share of a frame's stats: accel time and bytes, non-conformity,
/// the isosurface fields' range.
void AddSetupStats(const RenderStats& setup, bool withTimes, RenderStats& stats) {
    if (withTimes) {
        stats.timing.load += setup.timing.load;
        stats.timing.accel += setup.timing.accel;
    }
    stats.accelBytes += setup.accelBytes;
    stats.accelBytesPerCell = setup.accelBytesPerCell;
    stats.traversal.nonConformingFaces += setup.traversal.nonConformingFaces;
    stats.traversal.nonConformingEdges += setup.traversal.nonConformingEdges;
    stats.traversal.nonConformity =
        std::max(stats.traversal.nonConformity, setup.traversal.nonConformity);
    stats.isoFieldRange = {std::min(stats.isoFieldRange[0], setup.isoFieldRange[0]),
                           std::max(stats.isoFieldRange[1], setup.isoFieldRange[1])};
}

/// Threads beyond the cores a rank may run on only share those cores: says so once, on
/// rank 0.
void WarnIfThreadsExceedBinding(int threads) {
    const int allowed = tbb::info::default_concurrency();
    if (threads <= allowed || !mpi::Root()) return;
    log::Warn("threads is " + std::to_string(threads) + " but this process may run on " +
              (allowed == 1 ? std::string("1 core, so its threads share it")
                            : std::to_string(allowed) + " cores, so its threads share them") +
              "; mpirun binds each rank to one core when it starts 2 ranks or fewer: add "
              "--bind-to none, or a binding that gives each rank as many cores as threads");
}

/// Seconds between progress lines of a long frame (rank 0, stderr).
constexpr double kProgressSeconds = 5.0;

}  // namespace

/// The cancellation of one frame across ranks. Rank 0 asks the request function; once it
/// answers true, rank 0 stops taking tiles and tells every other rank, with one message
/// each, sent from the thread that may call MPI (the one that started the frame, which
/// renders tiles too). Every other rank has a receive for that message posted and tests
/// it from its MPI thread before its tiles; its other threads read the flag. When all
/// ranks have stopped rendering (Finish), rank 0 sends "not cancelled" to the ranks it has
/// not told, so each posted receive is matched exactly once per frame, and every rank
/// then knows the same answer.
class FrameJob::FrameCancel {
  public:
    FrameCancel(std::function<bool()> request, MPI_Comm comm)
        : request_(std::move(request)), comm_(comm), mpiThread_(std::this_thread::get_id()) {
        if (comm_ != MPI_COMM_NULL && !mpi::Root())
            MPI_Irecv(&message_, 1, MPI_INT, 0, kTag, comm_, &receive_);
    }
    FrameCancel(const FrameCancel&) = delete;
    FrameCancel& operator=(const FrameCancel&) = delete;

    /// Whether the frame is cancelled; called before each tile, from any thread.
    bool operator()() {
        if (cancelled_.load(std::memory_order_relaxed)) {
            if (OnMpiThread()) Tell(1);
            return true;
        }
        if (comm_ == MPI_COMM_NULL || mpi::Root()) {
            if (request_()) {
                cancelled_ = true;
                if (OnMpiThread()) Tell(1);
            }
        } else if (OnMpiThread() && !received_) {
            int done = 0;
            MPI_Test(&receive_, &done, MPI_STATUS_IGNORE);
            if (done) {
                received_ = true;
                if (message_ == 1) cancelled_ = true;
            }
        }
        return cancelled_.load(std::memory_order_relaxed);
    }

    /// Collective, once every rank has rendered its part: waits for all ranks (rank 0
    /// still passing a cancellation on meanwhile), then settles the answer everywhere.
    /// Returns the seconds spent waiting for the slowest rank.
    double Finish() {
        const auto t0 = std::chrono::steady_clock::now();
        if (comm_ == MPI_COMM_NULL) return 0;
        MPI_Request barrier;
        MPI_Ibarrier(comm_, &barrier);
        for (int done = 0; !done;) {
            if (mpi::Root()) (*this)();
            MPI_Test(&barrier, &done, MPI_STATUS_IGNORE);
            if (!done) std::this_thread::sleep_for(std::chrono::microseconds(200));
        }
        const double waited = Seconds(t0);
        if (mpi::Root()) {
            Tell(cancelled_ ? 1 : 0);
        } else if (!received_) {
            MPI_Wait(&receive_, MPI_STATUS_IGNORE);
            received_ = true;
            cancelled_ = message_ == 1;
        }
        return waited;
    }

    bool Cancelled() const { return cancelled_; }

  private:
    static constexpr int kTag = 1;
    bool OnMpiThread() const { return std::this_thread::get_id() == mpiThread_; }
    /// Rank 0: sends `value` to every other rank, once per frame.
    void Tell(int value) {
        if (comm_ == MPI_COMM_NULL || !mpi::Root() || told_) return;
        told_ = true;
        for (int r = 1; r < mpi::WorldSize(); ++r) MPI_Send(&value, 1, MPI_INT, r, kTag, comm_);
    }

    std::function<bool()> request_;
    MPI_Comm comm_;
    std::thread::id mpiThread_;
    std::atomic<bool> cancelled_{false};
    bool told_ = false;
    MPI_Request receive_ = MPI_REQUEST_NULL;
    int message_ = 0;
    bool received_ = false;
};

FrameJob::FrameJob(const Scene& scene) : scene_(scene) {
    const int P = mpi::WorldSize();
    const bool isPartition = partition::IsPartitionDirectory(scene_.data.mesh);
    WarnIfThreadsExceedBinding(scene_.threads);
    if (P > 1 || isPartition) {
        // From here on the job uses collectives (a partition on one process included).
        mpi::EnsureInitialized();
        if (scene_.threads == 0 && P > 1) scene_.threads = DefaultThreads();
        hpray::Distribution mode = scene_.distribute;
        if (mode == hpray::Distribution::Auto)
            mode = isPartition ? hpray::Distribution::Space : hpray::Distribution::Image;
        if (mode == hpray::Distribution::Image && isPartition)
            throw InputError(scene_.data.mesh, "",
                             "is a partition directory, but distribute: image needs the "
                             "whole mesh on every rank; use distribute: space (or auto) "
                             "for a partition, or give the mesh file");
        split_ = mode == hpray::Distribution::Image ? Split::Image : Split::Space;
        MPI_Comm_dup(MPI_COMM_WORLD, &cancelComm_);
    }
    setupStats_ = StartStats(scene_);
    for (const std::string& name : scene_.FieldNames()) loadedFields_.insert(name);
    readOptions_.fields = loadedFields_;

    // The data: the partition's manifest, or the whole mesh on every rank (rendered
    // whole, split in image tiles, or split in space into one box per rank, each rank
    // clipping its rays to its own box).
    const auto t0 = std::chrono::steady_clock::now();
    // Reading and preparing the whole mesh free and allocate large arrays in turn.
    std::optional<ReuseFreedMemory> reuse;
    if (!isPartition) reuse.emplace();
    if (isPartition) {
        part_ = partition::ReadPartition(scene_.data.mesh);
        partitionPlan_ = PlanFromPartition(*part_);
        const int bricks = static_cast<int>(partitionPlan_.boxes.size());
        if (bricks < P)
            throw InputError(scene_.data.mesh, "",
                             "has " + std::to_string(bricks) + " bricks, fewer than the " +
                                 std::to_string(P) + " MPI ranks; partition it into at least " +
                                 std::to_string(P) + " bricks");
        AssignRanks(partitionPlan_, P);
        if (scene_.data.time)
            throw InputError(scene_.sourcePath.empty() ? "scene" : scene_.sourcePath,
                             "data.time",
                             scene_.data.mesh + " is a partition directory: a partition has "
                             "no time steps (time series of partitions are not supported)");
    } else {
        if (IsCollectionPath(scene_.data.mesh)) {
            collection_ = ReadCollection(scene_.data.mesh);
            timeStep_ = TimeStepOf(scene_);
        } else {
            TimeStepOf(scene_);  // data.time without a collection is an error
        }
        LoadWhole();
    }
    setupStats_.timing.load = Seconds(t0);
    ResolveColorMaps(scene_, [this](const std::string& f) { return FieldRange(f); },
                     DataSize());
    if (whole_) {
        prepared_ = std::make_unique<PreparedBrick>(*whole_, std::nullopt, scene_, setupStats_);
        if (mpi::Root()) prepared_->SetProgress(kProgressSeconds);
        const auto t1 = std::chrono::steady_clock::now();
        reuse.reset();  // the free memory back to the system
        setupStats_.timing.accel += Seconds(t1);
    }
    FitCamera(scene_.camera, DataBounds(), scene_.clip.box);
}

int ResolveTimeStep(const Scene& scene, const Collection* collection) {
    const std::string source = scene.sourcePath.empty() ? "scene" : scene.sourcePath;
    if (!scene.data.time) return 0;
    if (!collection)
        throw InputError(source, "data.time",
                         "data.mesh (" + scene.data.mesh + ") is not a .pvd collection: only "
                         "a collection has time steps");
    const SceneData::Time& t = *scene.data.time;
    const long long n = static_cast<long long>(collection->steps.size());
    const std::string steps = std::to_string(n) + " time step" + (n == 1 ? "" : "s");
    if (t.byValue) {
        const int k = collection->FindTime(t.value);
        if (k < 0) {
            char value[32];
            std::snprintf(value, sizeof value, "%.10g", t.value);
            throw InputError(source, "data.time",
                             std::string("no step of ") + collection->path + " is at time " +
                                 value + "; its " + steps + " are at " +
                                 collection->TimesText() +
                                 " (or give a step index: data.time: 0)");
        }
        return k;
    }
    if (t.index >= n)
        throw InputError(source, "data.time",
                         "step " + std::to_string(t.index) + " is past the last step of " +
                             collection->path + " (" + steps + ": 0 to " +
                             std::to_string(n - 1) + ", at times " + collection->TimesText() +
                             ")");
    return static_cast<int>(t.index);
}

void FrameJob::LoadWhole() {
    readOptions_.timeStep = timeStep_;
    whole_ = collection_ ? ReadCollectionStep(*collection_, timeStep_, readOptions_)
                         : ReadMesh(scene_.data.mesh, readOptions_);
    // Neighbouring cells near each other in memory: the rays' walks stay in cache.
    OrderSpatially(*whole_);
    if (!mpi::Root()) return;
    std::string what = scene_.data.mesh;
    if (collection_) {
        char time[48];
        std::snprintf(time, sizeof time, "%.10g", collection_->steps[timeStep_].time);
        what += " step " + std::to_string(timeStep_) + " (t = " + time + ")";
    }
    log::Info("loaded " + what + ": " + std::to_string(whole_->CellCount()) + " cells, " +
              std::to_string(whole_->PointCount()) + " points");
}

double FrameJob::DataSize() const {
    // Before the preparation the mesh's own points give the size; a partition's bricks.
    if (whole_) return whole_->Bounds().Diagonal();
    const Box box = DataBounds();
    return box.IsEmpty() ? 1.0 : box.Diagonal();
}

std::optional<std::array<double, 2>> FrameJob::FieldRange(const std::string& name) const {
    if (whole_) {
        const auto sel = SelectScalar(*whole_, name);
        if (!sel) return std::nullopt;
        return sel->field->Range(sel->component);
    }
    std::optional<std::array<double, 2>> range;
    if (part_)
        for (const partition::BrickInfo& b : part_->bricks) {
            const auto it = b.ranges.find(name);
            if (it == b.ranges.end()) continue;
            range = range ? std::array<double, 2>{std::min((*range)[0], it->second[0]),
                                                  std::max((*range)[1], it->second[1])}
                          : it->second;
        }
    return range;
}

Box FrameJob::DataBounds() const {
    if (prepared_) return prepared_->Geometry().bounds;
    Box box;
    for (int d = 0; d < 3; ++d) {
        box.lo[d] = std::numeric_limits<double>::infinity();
        box.hi[d] = -box.lo[d];
    }
    for (const Box& b : partitionPlan_.boxes)
        for (int d = 0; d < 3; ++d) {
            box.lo[d] = std::min(box.lo[d], b.lo[d]);
            box.hi[d] = std::max(box.hi[d], b.hi[d]);
        }
    return box;
}

FrameJob::~FrameJob() {
    if (cancelComm_ != MPI_COMM_NULL) MPI_Comm_free(&cancelComm_);
}

void FrameJob::AddWarnings(const Scene& scene, const Image& image, RenderStats& stats) const {
    auto warn = [&](const std::string& text) { stats.warnings.push_back(text); };
    for (std::size_t k = 0; k < scene.isosurfaces.size(); ++k) {
        const SceneIsosurface& iso = scene.isosurfaces[k];
        std::optional<std::array<double, 2>> range;
        if (whole_) {
            if (const auto sel = SelectScalar(*whole_, iso.field))
                range = sel->field->Range(sel->component);
        } else if (part_) {
            for (const partition::BrickInfo& b : part_->bricks) {
                const auto it = b.ranges.find(iso.field);
                if (it == b.ranges.end()) continue;
                range = range ? std::array<double, 2>{std::min((*range)[0], it->second[0]),
                                                      std::max((*range)[1], it->second[1])}
                              : it->second;
            }
        }
        if (range && (iso.value < (*range)[0] || iso.value > (*range)[1])) {
            char text[256];
            std::snprintf(text, sizeof text,
                          "isosurfaces.%zu: value %.6g is outside the range [%.6g, %.6g] of "
                          "field '%s' over the data: it draws nothing",
                          k, iso.value, (*range)[0], (*range)[1], iso.field.c_str());
            warn(text);
        }
    }
    // A bare vector field name means its magnitude: say so, once per field.
    for (const std::string& name : scene.FieldNames()) {
        int components = 1;
        if (whole_) {
            if (const Field* f = whole_->FindField(name)) components = f->components;
        } else if (part_) {
            const nlohmann::json& fields = part_->manifest.value("fields", nlohmann::json());
            if (fields.is_object() && fields.contains(name) && fields[name].is_object())
                components = fields[name].value("components", 1);
        }
        if (components > 1)
            warn("field '" + name + "' has " + std::to_string(components) +
                 " components: its magnitude is used; name one as '" + name + "[0]' (or " +
                 name + ".x), or write '" + name + ".magnitude' to keep the magnitude "
                 "without this warning");
    }
    bool drawn = false;
    for (std::size_t p = 0; p < image.PixelCount() && !drawn; ++p)
        drawn = image.a[p] > 0 || image.r[p] > 0 || image.g[p] > 0 || image.b[p] > 0 ||
                std::isfinite(image.z[p]);
    if (!drawn)
        warn("the image is empty: the camera sees none of the data (check camera.position "
             "and camera.look_at against the data's bounds, hpray info), or nothing in view "
             "contributes (isovalues, transfer functions, clip)");
    if (scene.legend) {
        const LegendLayout legend = LayOutLegend(scene);
        if (legend.bars.empty() && legend.omitted == 0)
            warn("legend: nothing in the scene is coloured by a field (isosurfaces.#."
                 "color_field, slices, volume): there is no legend to draw");
        if (legend.omitted > 0)
            warn("legend: " + std::to_string(legend.omitted) + " of " +
                 std::to_string(legend.omitted + legend.bars.size()) +
                 " colour bars do not fit the " + std::to_string(scene.camera.width) + "x" +
                 std::to_string(scene.camera.height) + " image and are left out");
    }
    const double segments = std::max(1.0, stats.counters.segments);
    if (stats.counters.inversionFailures > 1e-3 * segments) {
        char text[320];
        std::snprintf(text, sizeof text,
                      "%.0f mapping failures in %.0f segments: cells whose map from the "
                      "reference cell could not be inverted; for a VTU of Lagrange hexes, a "
                      "file version below 2.2 implies the pre-VTK-9 node order",
                      stats.counters.inversionFailures, stats.counters.segments);
        warn(text);
    }
    if (stats.counters.rootFailures > 1e-3 * segments) {
        char text[256];
        std::snprintf(text, sizeof text,
                      "%.0f root failures in %.0f segments: isosurface crossings neither "
                      "excluded nor resolved to the tolerances asked for",
                      stats.counters.rootFailures, stats.counters.segments);
        warn(text);
    }
    for (const std::string& w : stats.warnings) log::Warn(w);
}

Image FrameJob::Render(const std::optional<SceneCamera>& camera, RenderStats& stats) {
    Scene scene = scene_;
    if (camera) scene.camera = *camera;
    return Render(scene, Change::CameraOnly, stats);
}

Image FrameJob::Render(const Scene& frameScene, Change change, RenderStats& stats,
                       const std::function<bool()>& cancelRequest) {
    if (frameScene.data.mesh != scene_.data.mesh)
        throw InputError(frameScene.data.mesh, "",
                         "a job renders the data it loaded (" + scene_.data.mesh + ")");
    Scene scene = frameScene;
    const int step = TimeStepOf(scene);
    // Another time step, or a mesh whose reading failed in an earlier frame.
    const bool newStep = step != timeStep_ || (!part_ && !prepared_);
    if (newStep) change = Change::Scene;
    scene.threads = scene_.threads;
    scene.distribute = scene_.distribute;
    if (change == Change::Scene) {
        // The preparation of this frame is reported with it; what it keeps (the
        // traversal's bytes and findings) stays in the stats.
        const RenderStats kept = setupStats_;
        setupStats_ = StartStats(scene);
        setupStats_.accelBytes = kept.accelBytes;
        setupStats_.accelBytesPerCell = kept.accelBytesPerCell;
        setupStats_.traversal = kept.traversal;
        firstFrame_ = true;
        bool missing = false;
        for (const std::string& name : scene.FieldNames())
            missing |= loadedFields_.insert(name).second;
        readOptions_.fields = loadedFields_;
        if (!part_) {
            std::optional<ReuseFreedMemory> reuse;
            if (missing || newStep) {
                // Another time step, or fields not yet loaded: the mesh is read again (the
                // old one released first) and prepared anew. If the reading fails, the
                // next frame reads again.
                const auto t0 = std::chrono::steady_clock::now();
                reuse.emplace();
                prepared_.reset();
                whole_.reset();
                const int previous = timeStep_;
                timeStep_ = step;
                try {
                    LoadWhole();
                } catch (...) {
                    timeStep_ = previous;
                    throw;
                }
                setupStats_.timing.load = Seconds(t0);
            }
            // `range: auto` colour maps need the fields' ranges before the set-up.
            ResolveColorMaps(scene, [this](const std::string& f) { return FieldRange(f); },
                     DataSize());
            if (missing || newStep ||
                scene.accuracy.mappingTolerance != prepared_->MappingTolerance()) {
                prepared_.reset();
                setupStats_.accelBytes = 0;
                setupStats_.traversal = TraversalStats{};
                prepared_ = std::make_unique<PreparedBrick>(*whole_, std::nullopt, scene,
                                                            setupStats_);
                if (mpi::Root()) prepared_->SetProgress(kProgressSeconds);
                const auto t1 = std::chrono::steady_clock::now();
                reuse.reset();
                setupStats_.timing.accel += Seconds(t1);
            }
            else
                prepared_->Reconfigure(scene, setupStats_);
        }
    }
    // After any new step is prepared: an automatic camera fits the data's bounds.
    FitCamera(scene.camera, DataBounds(), scene.clip.box);
    ResolveColorMaps(scene, [this](const std::string& f) { return FieldRange(f); },
                     DataSize());
    scene_ = scene;
    std::optional<FrameCancel> cancel;
    if (cancelRequest) cancel.emplace(cancelRequest, cancelComm_);
    FrameCancel* c = cancel ? &*cancel : nullptr;
    if (prepared_)
        prepared_->SetCancel(c ? std::function<bool()>([c] { return (*c)(); })
                               : std::function<bool()>());
    Image image = split_ == Split::None ? RenderSingle(scene, stats, c)
                                        : RenderDistributed(scene, stats, c);
    if (prepared_) prepared_->SetCancel({});
    cancelled_ = c && c->Cancelled();
    if (cancelled_) {
        image = Image{};
        stats.warnings.clear();
    } else {
        firstFrame_ = false;
        if (collection_) {
            stats.timeStep = timeStep_;
            stats.time = collection_->steps[static_cast<std::size_t>(timeStep_)].time;
        }
    }
    return image;
}

Image FrameJob::RenderSingle(const Scene& scene, RenderStats& stats, FrameCancel* cancel) {
    const auto start = std::chrono::steady_clock::now();
    stats = StartStats(scene);
    AddSetupStats(setupStats_, firstFrame_, stats);
    stats.bricksLoaded = stats.bricksTotal = 1;
    Image image;
    prepared_->Render(scene, Camera(scene.camera), std::nullopt, image, stats);
    if (cancel) cancel->Finish();
    stats.timing.total = Seconds(start) + (firstFrame_ ? stats.timing.load + stats.timing.accel : 0);
    return image;
}

Image FrameJob::RenderDistributed(const Scene& scene, RenderStats& stats,
                                  FrameCancel* cancel) {
    const auto start = std::chrono::steady_clock::now();
    const int P = mpi::WorldSize(), rank = mpi::WorldRank();
    stats = StartStats(scene);
    AddSetupStats(setupStats_, firstFrame_, stats);
    stats.ranks = P;
    stats.distribute = split_ == Split::Image ? "image" : "space";
    BrickPlan plan = partitionPlan_;
    auto t0 = std::chrono::steady_clock::now();
    if (whole_ && split_ == Split::Space) {
        // Rank 0 renders a pre-pass at 1/8 of the resolution, measuring each segment's
        // cost where it lies, and splits space so that each rank's box holds an equal
        // share of the measured cost (the split follows the camera: every frame).
        if (mpi::Root()) {
            SceneCamera low = scene.camera;
            low.width = std::min(scene.camera.width, std::max(32, scene.camera.width / 8));
            low.height =
                std::min(scene.camera.height, std::max(32, scene.camera.height / 8));
            std::vector<SegmentCostSample> samples;
            Image preview;
            RenderStats ignored = StartStats(scene);
            // Never cancelled: the split needs every sample (the pre-pass is short).
            prepared_->SetCancel({});
            prepared_->Render(scene, Camera(low), std::nullopt, preview, ignored, &samples);
            if (cancel) prepared_->SetCancel([cancel] { return (*cancel)(); });
            plan = SplitMesh(*whole_, prepared_->Geometry(), P, samples);
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
        AssignRanks(plan, P);
        stats.timing.prepass = Seconds(t0);
    }

    const ViewOrigin view = ViewOriginOf(scene.camera);
    Image accumulated;
    accumulated.Resize(scene.camera.width, scene.camera.height);
    int loaded = 0;
    std::unique_ptr<TileDealer> dealer;
    KdTree rankTree;
    if (split_ == Split::Image) {
        // Every pixel is rendered by exactly one rank, exactly as on one rank; the others
        // leave it empty, which Over leaves unchanged, so any visibility order composites
        // the single-rank image bit for bit.
        const Camera cam(scene.camera);
        const int tiles = RenderTileCount(cam);
        const int chunk = std::max(1, std::min(8 * scene.threads, tiles / (16 * P)));
        dealer = std::make_unique<TileDealer>(tiles, chunk);
        int begin = 0, end = 0;
        // Progress from the dealer's counter: the tiles handed out to all ranks.
        double nextReport = kProgressSeconds;
        const auto dealt = std::chrono::steady_clock::now();
        while (!(cancel && (*cancel)()) && dealer->Next(begin, end)) {
            prepared_->RenderTiles(scene, cam, begin, end, accumulated, stats);
            const double elapsed = Seconds(dealt);
            if (mpi::Root() && elapsed >= nextReport) {
                nextReport = elapsed + kProgressSeconds;
                const double share = double(end) / tiles;
                char text[160];
                std::snprintf(text, sizeof text,
                              "rendering %dx%d on %d ranks: %.0f%% of the tiles dealt after "
                              "%.1f s, about %.0f s left",
                              cam.Width(), cam.Height(), P, 100 * share, elapsed,
                              elapsed * (1 - share) / share);
                log::Progress(text);
            }
        }
        log::EndProgress();
        loaded = mpi::Root() ? 1 : 0;
        stats.bricksTotal = 1;
        rankTree = RegularKdTree(P, prepared_->Geometry().bounds);
    } else {
        stats.bricksTotal = static_cast<int>(plan.boxes.size());
        for (int b : plan.tree.FrontToBack(view)) {
            if (plan.rank[b] != rank) continue;
            if (cancel && (*cancel)()) break;
            if (part_ && !BrickMayContribute(scene, part_->bricks[b], plan.boxes[b])) continue;
            Image image;
            if (part_) {
                t0 = std::chrono::steady_clock::now();
                Mesh mesh = partition::LoadBrick(*part_, b, readOptions_);
                OrderSpatially(mesh);
                stats.timing.load += Seconds(t0);
                RenderOneBrick(mesh, plan.boxes[b], scene, image, stats, nullptr,
                               &accumulated,
                               cancel ? std::function<bool()>([cancel] { return (*cancel)(); })
                                      : std::function<bool()>());
            } else {
                prepared_->Render(scene, Camera(scene.camera), plan.boxes[b], image, stats,
                                  nullptr, &accumulated);
            }
            ++loaded;
            CompositeOver(accumulated, image);
        }
        if (P > 1) rankTree = compositor::BuildRankTree(plan.tree, plan.rank, P);
    }

    // Waiting for the slowest rank is imbalance, not compositing: timed apart.
    if (cancel) {
        stats.timing.wait = cancel->Finish();
        if (cancel->Cancelled()) {
            // Every rank knows: nothing is composited or reduced.
            dealer.reset();
            return Image{};
        }
    } else {
        t0 = std::chrono::steady_clock::now();
        MPI_Barrier(MPI_COMM_WORLD);
        stats.timing.wait = Seconds(t0);
    }
    dealer.reset();
    t0 = std::chrono::steady_clock::now();
    compositor::CompositeStats cs;
    if (P > 1) cs = compositor::Composite(accumulated, rankTree, view, MPI_COMM_WORLD);
    stats.timing.composite = Seconds(t0);
    stats.timing.total =
        Seconds(start) + (firstFrame_ ? setupStats_.timing.load + setupStats_.timing.accel : 0);
    ReduceStats(stats, loaded, !part_.has_value());
    if (P > 1) {
        stats.composite.rounds = cs.rounds;
        stats.composite.bytesPerPixel = cs.bytesPerPixel;
        stats.composite.bytesSentMax = static_cast<double>(cs.bytesSentMax);
        stats.composite.bytesSentTotal = static_cast<double>(cs.bytesSentTotal);
        stats.composite.bytesGather = static_cast<double>(cs.bytesGather);
    }
    return accumulated;
}

}  // namespace hpray::job
