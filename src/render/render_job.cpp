// A render job on one process (see render_job.h).
#include "render/render_job.h"

#include <tbb/info.h>
#include <tbb/task_group.h>

#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <filesystem>
#include <cstdio>
#include <limits>
#include <set>

#include "elements/mesh_geometry.h"
#include "io/image.h"
#include "render/annotate.h"
#include "render/brick_renderer.h"
#include "trace/brick_traverser.h"
#include "util/error.h"
#include "util/log.h"

namespace hpray {
namespace {
double Seconds(std::chrono::steady_clock::time_point since) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

/// Adds the walk events between two readings of a traverser's counters.
void AddTraceCounters(const TraceCounters& before, const TraceCounters& after,
                      TraversalStats& out) {
    out.walkRepairs += static_cast<double>(after.walkRepairs - before.walkRepairs);
    out.walkFailures += static_cast<double>(after.walkFailures - before.walkFailures);
    out.faceNewtonFailures +=
        static_cast<double>(after.newtonFailures - before.newtonFailures);
}
}  // namespace

std::vector<double> HitsArray(const Image& image) {
    std::vector<double> out(image.PixelCount() * 5);
    for (std::size_t p = 0; p < image.PixelCount(); ++p) {
        out[5 * p] = image.z[p];
        out[5 * p + 1] = image.nx[p];
        out[5 * p + 2] = image.ny[p];
        out[5 * p + 3] = image.nz[p];
        out[5 * p + 4] = image.isoResidual[p];
    }
    return out;
}

std::vector<float> ErrorArray(const Image& image) {
    std::vector<float> out(image.PixelCount() * 2);
    for (std::size_t p = 0; p < image.PixelCount(); ++p) {
        out[2 * p] = static_cast<float>(image.isoResidual[p]);
        out[2 * p + 1] = static_cast<float>(image.volError[p]);
    }
    return out;
}

std::vector<double> RgbaArray(const Image& image) {
    std::vector<double> out(image.PixelCount() * 4);
    for (std::size_t p = 0; p < image.PixelCount(); ++p) {
        out[4 * p] = image.r[p];
        out[4 * p + 1] = image.g[p];
        out[4 * p + 2] = image.b[p];
        out[4 * p + 3] = image.a[p];
    }
    return out;
}

RenderStats StartStats(const Scene& scene) {
    RenderStats stats;
    stats.scene = scene.sourcePath;
    stats.mesh = scene.data.mesh;
    stats.threads = scene.threads > 0 ? scene.threads : tbb::info::default_concurrency();
    stats.width = scene.camera.width;
    stats.height = scene.camera.height;
    stats.cameraPosition = scene.camera.position;
    stats.cameraLookAt = scene.camera.lookAt;
    stats.cameraUp = scene.camera.up;
    stats.cameraOrthographic = scene.camera.orthographic;
    stats.cameraFovY = scene.camera.fovYDegrees;
    stats.cameraOrthoHeight = scene.camera.orthoHeight;
    if (scene.volume) {
        const SceneVolume& v = *scene.volume;
        stats.hasVolume = true;
        stats.volumeColorField = v.colorField;
        stats.volumeExtinctionField =
            v.extinctionField.empty() ? v.colorField : v.extinctionField;
        for (const ColorControlPoint& p : v.colorTf)
            stats.volumeColorTf.push_back({p.scalar, p.rgb[0], p.rgb[1], p.rgb[2]});
        for (const ExtinctionControlPoint& p : v.extinctionTf)
            stats.volumeExtinctionTf.push_back({p.scalar, p.extinction});
    }
    stats.isoFieldRange = {std::numeric_limits<double>::infinity(),
                           -std::numeric_limits<double>::infinity()};
    return stats;
}

struct PreparedBrick::Impl {
    const Mesh* mesh = nullptr;
    double mappingTolerance = 0;
    MeshGeometry geometry;
    std::unique_ptr<BrickTraverser> traverser;
    BrickSetup setup;
    std::optional<FieldCache> fields;  ///< per-field data kept across Reconfigure
    std::function<bool()> cancel;
    double progressSeconds = 0;
};

PreparedBrick::PreparedBrick(const Mesh& mesh, const std::optional<Box>& box,
                             const Scene& scene, RenderStats& stats)
    : impl_(std::make_unique<Impl>()) {
    const auto t0 = std::chrono::steady_clock::now();
    impl_->mesh = &mesh;
    impl_->mappingTolerance = scene.accuracy.mappingTolerance;
    impl_->geometry = MeshGeometry::Build(mesh);
    const MeshGeometry& geometry = impl_->geometry;
    Brick brick{&mesh, {}};
    if (box) {
        brick.box = *box;
    } else {
        // The guaranteed boxes of the cells: curved cells may bulge beyond their nodes.
        brick.box = geometry.bounds;
    }
    TraceOptions traceOptions;
    traceOptions.mappingTolerance = scene.accuracy.mappingTolerance;
    impl_->traverser = std::make_unique<BrickTraverser>(brick, traceOptions);
    impl_->fields.emplace(mesh, impl_->geometry);
    impl_->setup = MakeBrickSetup(mesh, geometry, *impl_->traverser, scene, &*impl_->fields);
    stats.timing.accel += Seconds(t0);
    const TraverserStats& ts = impl_->traverser->Stats();
    // Mismatches at the rounding level of single-precision files (deal.II writes
    // Float32; copies of one node may differ by an ulp) are in the stats only.
    if (ts.nonConformity > 1e-6) {
        char text[160];
        std::snprintf(text, sizeof text,
                      "%lld shared faces and %lld edges are given different nodes by the "
                      "cells that share them (up to %.3g of their size)",
                      static_cast<long long>(ts.nonConformingFaces),
                      static_cast<long long>(ts.nonConformingEdges), ts.nonConformity);
        log::Warn(scene.data.mesh + ": " + text +
                  ": the mesh is not conforming; the traversal uses one version of each, "
                  "so points in the gaps between the versions are evaluated just outside "
                  "the cell the ray is walking");
    }
    stats.traversal.nonConformingFaces += static_cast<double>(ts.nonConformingFaces);
    stats.traversal.nonConformingEdges += static_cast<double>(ts.nonConformingEdges);
    stats.traversal.nonConformity = std::max(stats.traversal.nonConformity, ts.nonConformity);
    stats.accelBytes += static_cast<double>(ts.Bytes());
    stats.accelBytesPerCell = ts.BytesPerCell();
    for (const ScalarSelector& f : impl_->setup.fields) {
        const auto r = f.field->Range(f.component);
        stats.isoFieldRange = {std::min(stats.isoFieldRange[0], r[0]),
                               std::max(stats.isoFieldRange[1], r[1])};
    }
}

PreparedBrick::~PreparedBrick() = default;

void PreparedBrick::Reconfigure(const Scene& scene, RenderStats& stats) {
    const auto t0 = std::chrono::steady_clock::now();
    impl_->setup = MakeBrickSetup(*impl_->mesh, impl_->geometry, *impl_->traverser, scene,
                                  &*impl_->fields);
    for (const ScalarSelector& f : impl_->setup.fields) {
        const auto r = f.field->Range(f.component);
        stats.isoFieldRange = {std::min(stats.isoFieldRange[0], r[0]),
                               std::max(stats.isoFieldRange[1], r[1])};
    }
    stats.timing.accel += Seconds(t0);
}

double PreparedBrick::MappingTolerance() const { return impl_->mappingTolerance; }

void PreparedBrick::SetCancel(std::function<bool()> cancelled) {
    impl_->cancel = std::move(cancelled);
}

void PreparedBrick::SetProgress(double seconds) { impl_->progressSeconds = seconds; }

const MeshGeometry& PreparedBrick::Geometry() const { return impl_->geometry; }

void PreparedBrick::Render(const Scene& scene, const Camera& camera,
                           const std::optional<Box>& clip, Image& image,
                           RenderStats& stats, std::vector<SegmentCostSample>* costSamples,
                           const Image* front) {
    const auto t0 = std::chrono::steady_clock::now();
    BrickSetup& setup = impl_->setup;
    const std::optional<Box> sceneClip = setup.clipBox;
    if (clip) {
        // The points of the leaf box that the scene's clip box keeps (the ownership rule
        // of geom/box.h: an upper face stays open where the leaf's is).
        const Box box = sceneClip ? clip->Intersect(*sceneClip) : *clip;
        if (box.IsEmpty()) {
            image.Resize(camera.Width(), camera.Height());
            stats.timing.render += Seconds(t0);
            return;
        }
        setup.clipBox = box;
    }
    const TraceCounters before = impl_->traverser->Counters();
    setup.cancelled = impl_->cancel;
    // Pre-passes that measure cost are short and not the frame the user waits for.
    setup.progressSeconds = costSamples ? 0.0 : impl_->progressSeconds;
    RenderBrick(setup, camera, scene.threads, image, stats.counters, costSamples, front);
    AddTraceCounters(before, impl_->traverser->Counters(), stats.traversal);
    setup.clipBox = sceneClip;
    stats.timing.render += Seconds(t0);
}

void PreparedBrick::RenderTiles(const Scene& scene, const Camera& camera, int begin,
                                int end, Image& image, RenderStats& stats) {
    const auto t0 = std::chrono::steady_clock::now();
    const TraceCounters before = impl_->traverser->Counters();
    impl_->setup.cancelled = impl_->cancel;
    impl_->setup.progressSeconds = 0;  // a chunk of a frame: the job reports its progress
    RenderBrickTiles(impl_->setup, camera, scene.threads, begin, end, image, stats.counters);
    AddTraceCounters(before, impl_->traverser->Counters(), stats.traversal);
    stats.timing.render += Seconds(t0);
}

void RenderOneBrick(const Mesh& mesh, const std::optional<Box>& box, const Scene& scene,
                    Image& image, RenderStats& stats,
                    std::vector<SegmentCostSample>* costSamples, const Image* front,
                    const std::function<bool()>& cancelled) {
    PreparedBrick brick(mesh, box, scene, stats);
    brick.SetCancel(cancelled);
    brick.Render(scene, Camera(scene.camera), std::nullopt, image, stats, costSamples, front);
}

void CheckJobOutputs(const Scene& scene) {
    namespace fs = std::filesystem;
    const SceneOutput& o = scene.output;
    const std::string source = scene.sourcePath.empty() ? "scene" : scene.sourcePath;
    const struct {
        const char* key;
        const std::string* path;
        const char* extension;
    } outputs[] = {{"output.exr", &o.exr, ".exr"},     {"output.png", &o.png, ".png"},
                   {"output.stats", &o.stats, ".json"}, {"output.hits", &o.hits, ".npy"},
                   {"output.rgba", &o.rgba, ".npy"}, {"output.errors", &o.errors, ".npy"}};
    const std::set<std::string> known = {".exr",  ".png", ".jpg", ".jpeg", ".tif", ".tiff",
                                         ".bmp",  ".gif", ".webp", ".ppm", ".npy", ".npz",
                                         ".json", ".vtk", ".vtu", ".vti"};
    for (const auto& out : outputs) {
        if (out.path->empty()) continue;
        const fs::path path(*out.path);
        std::string ext = path.extension().string();
        for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
        if (known.count(ext) && ext != out.extension)
            throw InputError(source, out.key,
                             "'" + *out.path + "' ends in " + ext + ", but this output is " +
                                 "written as " + std::string(out.extension + 1) +
                                 "; name it *" + out.extension);
        std::error_code ec;
        if (fs::is_directory(path, ec))
            throw InputError(source, out.key, "'" + *out.path + "' is a folder");
        // The nearest folder that exists must be one this process can write in.
        fs::path folder = fs::absolute(path, ec).parent_path();
        while (!folder.empty() && !fs::exists(folder, ec) && folder != folder.parent_path())
            folder = folder.parent_path();
        if (!fs::is_directory(folder, ec))
            throw InputError(source, out.key,
                             "cannot write '" + *out.path + "': '" + folder.string() +
                                 "' is not a folder");
        if (::access(folder.c_str(), W_OK | X_OK) != 0)
            throw InputError(source, out.key,
                             "cannot write '" + *out.path + "': no permission to write in '" +
                                 folder.string() + "'");
    }
}

void WriteJobOutputs(const Scene& scene, const Image& image, const Box& dataBounds,
                     RenderStats& stats) {
    if (!(stats.isoFieldRange[0] <= stats.isoFieldRange[1])) stats.isoFieldRange = {0, 0};
    const double range = stats.isoFieldRange[1] - stats.isoFieldRange[0];
    stats.counters.isoResidualRelMax = range > 0 ? stats.counters.isoResidualMax / range : 0;
    const auto t0 = std::chrono::steady_clock::now();
    const SceneOutput& out = scene.output;
    const std::size_t H = image.height, W = image.width;
    // The files are independent: written side by side (the first error is rethrown
    // once all have finished; each writer leaves no partial file).
    tbb::task_group writers;
    if (!out.exr.empty()) writers.run([&] { WriteExr(out.exr, image); });
    if (!out.png.empty())
        writers.run([&] {
            // The annotated picture holds the image once more in linear RGB: only when
            // there is something to draw on it.
            if (scene.outline.enabled || scene.legend)
                WritePng(out.png, AnnotatedPicture(scene, image, dataBounds));
            else
                WritePng(out.png, image, scene.background);
        });
    if (!out.hits.empty())
        writers.run([&] { WriteNpy(out.hits, HitsArray(image), {H, W, 5}); });
    if (!out.rgba.empty())
        writers.run([&] { WriteNpy(out.rgba, RgbaArray(image), {H, W, 4}); });
    if (!out.errors.empty())
        writers.run([&] { WriteNpyFloat32(out.errors, ErrorArray(image), {H, W, 2}); });
    writers.wait();
    stats.timing.write = Seconds(t0);
    stats.timing.total += stats.timing.write;
    if (!out.stats.empty()) WriteStats(out.stats, stats);
}

Image RenderMeshJob(const Mesh& mesh, const Scene& sceneIn, RenderStats& stats,
                    double loadSeconds) {
    const auto start = std::chrono::steady_clock::now();
    Scene scene = sceneIn;
    // The guaranteed bounds (curved cells may bulge beyond their nodes) cost a pass over
    // the cells: only when a fitted camera or the outline needs them.
    const Box bounds = scene.camera.autoFit || scene.outline.enabled
                           ? MeshGeometry::Build(mesh).bounds
                           : mesh.Bounds();
    FitCamera(scene.camera, bounds, scene.clip.box);
    ResolveColorMaps(scene, [&mesh](const std::string& f) {
        const auto sel = SelectScalar(mesh, f);
        return sel ? std::optional<std::array<double, 2>>(sel->field->Range(sel->component))
                   : std::nullopt;
    }, mesh.Bounds().Diagonal());
    stats = StartStats(scene);
    stats.timing.load = loadSeconds;
    stats.bricksLoaded = stats.bricksTotal = 1;
    Image image;
    RenderOneBrick(mesh, std::nullopt, scene, image, stats);
    stats.timing.total = Seconds(start) + loadSeconds;
    WriteJobOutputs(scene, image, bounds, stats);
    return image;
}

}  // namespace hpray
