// hpray probe (its issue has not landed).
#include "app/commands.h"
#include "util/error.h"

namespace hpray::app {
int RunProbe(const ProbeArgs&) { throw NotImplementedError("'hpray probe'"); }
}  // namespace hpray::app
