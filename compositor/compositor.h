// Image compositing across bricks and ranks.
#pragma once

namespace hpray::compositor {
/// The compositor's version of the image layout it expects (bumped on layout changes).
int LayoutVersion();
}  // namespace hpray::compositor
