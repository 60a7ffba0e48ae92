// hpray probe / render / partition: entry points of subcommands whose issues are open.
#include "app/commands.h"
#include "util/error.h"

namespace hpray::app {
int RunProbe(const ProbeArgs&) { throw NotImplementedError("'hpray probe'"); }
int RunRender(const RenderArgs&) { throw NotImplementedError("'hpray render'"); }
int RunPartition(const PartitionArgs&) { throw NotImplementedError("'hpray partition'"); }
}  // namespace hpray::app
