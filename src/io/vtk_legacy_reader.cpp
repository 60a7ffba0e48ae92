// Placeholder: implementation in progress.
#include "io/mesh_io.h"
#include "util/error.h"
namespace hpray {
Mesh ReadVtkLegacy(const std::string& path, const ReadOptions&) {
    throw InputError(path, "", "legacy VTK reading is not implemented yet");
}
}  // namespace hpray
