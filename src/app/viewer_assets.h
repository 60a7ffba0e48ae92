// The browser viewer's files (src/app/viewer/), compiled into the executable.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

namespace hpray::app {

struct ViewerAsset {
    const char* name;  ///< file name, e.g. "index.html"
    const char* mime;  ///< Content-Type
    const char* bytes;
    std::size_t size;
};

/// Every file of src/app/viewer/, sorted by name.
const std::vector<ViewerAsset>& ViewerAssets();

}  // namespace hpray::app
