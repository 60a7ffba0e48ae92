// Placeholder: implementation in progress.
#include "io/mesh_io.h"
#include "util/error.h"
namespace hpray {
Mesh ReadVtkXml(const std::string& path, const ReadOptions&) {
    throw InputError(path, "", "VTK XML reading is not implemented yet");
}
}  // namespace hpray
