// hpray partition: k-d decomposition of a mesh into bricks (its issue has not landed).
#include "app/commands.h"
#include "util/error.h"

namespace hpray::app {
int RunPartition(const PartitionArgs&) { throw NotImplementedError("'hpray partition'"); }
}  // namespace hpray::app
