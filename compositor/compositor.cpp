// Image compositing across bricks and ranks (binary swap lands with the MPI renderer).
#include "compositor.h"

namespace hpray::compositor {
int LayoutVersion() { return 1; }
}  // namespace hpray::compositor
