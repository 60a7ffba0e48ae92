// hpray render (its issue has not landed).
#include "app/commands.h"
#include "util/error.h"

namespace hpray::app {
int RunRender(const RenderArgs&) { throw NotImplementedError("'hpray render'"); }
}  // namespace hpray::app
