// Placeholder: implementation in progress.
#include "io/mesh_io.h"
#include "util/error.h"
namespace hpray {
Mesh ReadGmsh(const std::string& path, const ReadOptions&) {
    throw InputError(path, "", "Gmsh reading is not implemented yet");
}
}  // namespace hpray
