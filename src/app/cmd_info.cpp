// hpray info (placeholder).
#include "app/commands.h"
#include "util/error.h"
namespace hpray::app {
int RunInfo(const InfoArgs&) { throw NotImplementedError("'hpray info'"); }
}  // namespace hpray::app
