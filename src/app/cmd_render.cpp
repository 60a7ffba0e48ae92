// hpray render: one process (MPI ranks and partitions land with their issues).
#include <cstdio>

#include "app/commands.h"
#include "render/render_job.h"
#include "scene/scene.h"
#include "util/error.h"
#include "util/log.h"
#include "util/mpi.h"

namespace hpray::app {

int RunRender(const RenderArgs& args) {
    const Scene scene = LoadScene(args.scene, args.overrides);
    if (mpi::WorldSize() > 1)
        throw NotImplementedError("'hpray render' on more than one MPI rank");
    RenderStats stats;
    RunRenderJob(scene, stats);
    char line[512];
    std::snprintf(line, sizeof line,
                  "rendered %dx%d in %.3f s (load %.3f, accel %.3f, render %.3f, write %.3f) "
                  "on %d threads: %.0f hits, max residual %.3g (%.3g of the field range), "
                  "%.0f root failures, %.0f mapping failures",
                  stats.width, stats.height, stats.timing.total, stats.timing.load,
                  stats.timing.accel, stats.timing.render, stats.timing.write, stats.threads,
                  stats.counters.isoHits, stats.counters.isoResidualMax,
                  stats.counters.isoResidualRelMax, stats.counters.rootFailures,
                  stats.counters.inversionFailures);
    log::Info(line);
    return 0;
}

}  // namespace hpray::app
