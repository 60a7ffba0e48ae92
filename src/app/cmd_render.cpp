// hpray render: one frame of a FrameJob (job/frame_job.h) on one process or many MPI
// ranks, a mesh, a .pvd time step or a partition directory; or, with the scene key
// `frames`, several frames of one job (numbered outputs). Rank 0 writes the outputs.
#include <cstdio>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "app/commands.h"
#include "io/mesh_io.h"
#include "job/frame_job.h"
#include "render/render_job.h"
#include "scene/scene.h"
#include "util/error.h"
#include "util/log.h"
#include "util/mpi.h"

namespace hpray::app {
namespace {

/// The summary line of a frame ("frame 3 of 36: " in front in a run of several).
void LogFrame(const job::FrameJob& frameJob, const RenderStats& stats,
              const std::string& prefix) {
    char line[512];
    if (frameJob.Distribution() == job::Split::None) {
        std::snprintf(line, sizeof line,
                      "rendered %dx%d in %.3f s (load %.3f, accel %.3f, render %.3f, write "
                      "%.3f) on %d threads: %.0f hits, max residual %.3g (%.3g of the field "
                      "range), %.0f root failures, %.0f mapping failures",
                      stats.width, stats.height, stats.timing.total, stats.timing.load,
                      stats.timing.accel, stats.timing.render, stats.timing.write,
                      stats.threads, stats.counters.isoHits, stats.counters.isoResidualMax,
                      stats.counters.isoResidualRelMax, stats.counters.rootFailures,
                      stats.counters.inversionFailures);
    } else {
        char split[96];
        if (frameJob.Distribution() == job::Split::Image)
            std::snprintf(split, sizeof split, "the image split in tiles");
        else
            std::snprintf(split, sizeof split, "%d of %d bricks loaded", stats.bricksLoaded,
                          stats.bricksTotal);
        std::snprintf(line, sizeof line,
                      "rendered %dx%d on %d ranks x %d threads in %.3f s (render %.3f, "
                      "composite %.3f): %s, %.0f hits, max residual %.3g",
                      stats.width, stats.height, stats.ranks, stats.threads,
                      stats.timing.total, stats.timing.render, stats.timing.composite, split,
                      stats.counters.isoHits, stats.counters.isoResidualMax);
    }
    log::Info(prefix + line);
}

/// `path` with the frame number before its extension: out/x.png -> out/x_0007.png.
std::string NumberedPath(const std::string& path, int frame, int digits) {
    if (path.empty()) return path;
    const std::filesystem::path p(path);
    std::string number = std::to_string(frame);
    if (static_cast<int>(number.size()) < digits)
        number.insert(0, static_cast<std::size_t>(digits) - number.size(), '0');
    return (p.parent_path() / (p.stem().string() + "_" + number + p.extension().string()))
        .string();
}

/// The items of a frame that change more than the camera.
std::vector<std::string> NonCamera(const std::vector<std::string>& items) {
    std::vector<std::string> out;
    for (const std::string& item : items)
        if (item.rfind("camera.", 0) != 0 && item.rfind("camera=", 0) != 0) out.push_back(item);
    return out;
}

/// The scene key `frames`: every frame's scene is parsed (and its outputs checked) before
/// any is rendered; then one job renders them in order, reusing its data and preparation
/// as far as each frame allows (the camera only: everything; other keys: the mesh and
/// traversal; another time step: nothing but the job's ranks).
int RunFrames(const RenderArgs& args, const std::string& sceneText, const std::string& baseDir,
              const Scene& scene) {
    std::optional<Collection> collection;
    if (IsCollectionPath(scene.data.mesh)) collection = ReadCollection(scene.data.mesh);
    const int timeSteps = collection ? static_cast<int>(collection->steps.size()) : 0;
    const std::vector<std::vector<std::string>> frames = FrameOverrides(scene, timeSteps);
    const int count = static_cast<int>(frames.size());
    int digits = 4;
    for (int n = count - 1; n >= 10000; n /= 10) ++digits;
    std::vector<Scene> scenes;
    scenes.reserve(frames.size());
    for (int k = 0; k < count; ++k) {
        std::vector<std::string> overrides = args.overrides;
        overrides.insert(overrides.end(), frames[k].begin(), frames[k].end());
        Scene s;
        try {
            s = ParseScene(sceneText, args.scene, overrides, baseDir);
        } catch (const InputError& e) {
            throw InputError(e.source(), e.where(),
                             e.detail() + " (in frame " + std::to_string(k) + " of frames)");
        }
        s.sourcePath = args.scene;
        try {
            job::ResolveTimeStep(s, collection ? &*collection : nullptr);
        } catch (const InputError& e) {
            throw InputError(e.source(), e.where(),
                             e.detail() + " (in frame " + std::to_string(k) + " of frames)");
        }
        for (std::string* path : {&s.output.exr, &s.output.png, &s.output.stats,
                                  &s.output.hits, &s.output.rgba})
            *path = NumberedPath(*path, k, digits);
        if (mpi::Root()) CheckJobOutputs(s);
        scenes.push_back(std::move(s));
    }
    if (mpi::Root())
        log::Info("rendering " + std::to_string(count) + " frame" + (count == 1 ? "" : "s") +
                  (timeSteps > 0 ? " of " + scene.data.mesh : std::string()));

    std::unique_ptr<job::FrameJob> frameJob;
    for (int k = 0; k < count; ++k) {
        // A job is made for the first frame (it loads the data); later frames render on
        // it: the camera alone changes nothing else, other keys rebuild the set-up, and
        // another time step reads that step (FrameJob::Render).
        const bool first = !frameJob;
        if (first) frameJob = std::make_unique<job::FrameJob>(scenes[k]);
        const auto change = first || NonCamera(frames[k]) == NonCamera(frames[k - 1])
                                ? job::FrameJob::Change::CameraOnly
                                : job::FrameJob::Change::Scene;
        RenderStats stats;
        const Image image = frameJob->Render(scenes[k], change, stats);
        if (!mpi::Root()) continue;
        stats.frame = k;
        frameJob->AddWarnings(frameJob->GetScene(), image, stats);
        if (args.strict && !stats.warnings.empty())
            throw InputError(args.scene, "--strict",
                             "frame " + std::to_string(k) + ": " + stats.warnings.front());
        WriteJobOutputs(frameJob->GetScene(), image, frameJob->DataBounds(), stats);
        LogFrame(*frameJob, stats,
                 "frame " + std::to_string(k) + " of " + std::to_string(count) + ": ");
    }
    return 0;
}

}  // namespace

int RunRender(const RenderArgs& args) {
    const std::string sceneText = ReadSceneText(args.scene);
    const std::string baseDir =
        std::filesystem::absolute(std::filesystem::path(args.scene)).parent_path().string();
    Scene scene = ParseScene(sceneText, args.scene, args.overrides, baseDir);
    scene.sourcePath = args.scene;
    if (scene.frames) return RunFrames(args, sceneText, baseDir, scene);

    if (mpi::Root()) CheckJobOutputs(scene);  // before any work
    job::FrameJob frameJob(scene);
    RenderStats stats;
    const Image image = frameJob.Render(std::nullopt, stats);
    if (!mpi::Root()) return 0;
    frameJob.AddWarnings(frameJob.GetScene(), image, stats);
    if (args.strict && !stats.warnings.empty())
        throw InputError(scene.sourcePath, "--strict", stats.warnings.front());
    WriteJobOutputs(frameJob.GetScene(), image, frameJob.DataBounds(), stats);
    LogFrame(frameJob, stats, "");
    return 0;
}

}  // namespace hpray::app
