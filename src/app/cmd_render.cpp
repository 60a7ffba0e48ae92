// hpray render: one frame of a FrameJob (job/frame_job.h) on one process or many MPI
// ranks, a mesh or a partition directory; rank 0 writes the outputs.
#include <cstdio>

#include "app/commands.h"
#include "job/frame_job.h"
#include "render/render_job.h"
#include "scene/scene.h"
#include "util/error.h"
#include "util/log.h"
#include "util/mpi.h"

namespace hpray::app {

int RunRender(const RenderArgs& args) {
    const Scene scene = LoadScene(args.scene, args.overrides);
    if (mpi::Root()) CheckJobOutputs(scene);  // before any work
    job::FrameJob frameJob(scene);
    RenderStats stats;
    const Image image = frameJob.Render(std::nullopt, stats);
    if (!mpi::Root()) return 0;
    frameJob.AddWarnings(frameJob.GetScene(), image, stats);
    if (args.strict && !stats.warnings.empty())
        throw InputError(scene.sourcePath, "--strict", stats.warnings.front());
    WriteJobOutputs(frameJob.GetScene(), image, frameJob.DataBounds(), stats);
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
    log::Info(line);
    return 0;
}

}  // namespace hpray::app
