// hpray partition: argument checks, then the out-of-core k-d decomposition of partition/.
#include <cstdio>

#include "app/commands.h"
#include "partition.h"
#include "util/error.h"
#include "util/log.h"

namespace hpray::app {

int RunPartition(const PartitionArgs& args) {
    partition::PartitionOptions options;
    if (args.bricks < 1)
        throw InputError(
            "command line", "--bricks",
            std::to_string(args.bricks) + " is not a positive number of bricks");
    options.bricks = args.bricks;
    options.outDir = args.outDir;
    if (!args.memoryLimit.empty())
        options.memoryLimitBytes = partition::ParseMemorySize(args.memoryLimit);
    if (!args.fields.empty()) options.fields = args.fields;
    options.force = args.force;
    const partition::PartitionReport r = partition::PartitionMesh(args.mesh, options);
    char line[256];
    std::snprintf(
        line, sizeof line,
        "partition: %d bricks in %s: %lld cells (%lld stored with ghosts), balance "
        "%.4f, %.1f MiB written in %.2f s%s",
        args.bricks, args.outDir.c_str(), static_cast<long long>(r.inputCells),
        static_cast<long long>(r.storedCells), r.balance,
        static_cast<double>(r.bytesWritten) / (1024.0 * 1024.0), r.seconds,
        r.streamed ? "" : " (input read whole)");
    log::Info(line);
    return 0;
}

}  // namespace hpray::app
