// ReadMesh: dispatch by builtin: prefix or file extension.
#include "io/mesh_io.h"

#include <algorithm>
#include <cctype>
#include <filesystem>

#include "mesh/builtin.h"
#include "util/error.h"

namespace hpray {

namespace {
std::string LowerExtension(const std::string& path) {
    std::string ext = std::filesystem::path(path).extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(),
                   [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    return ext;
}
}  // namespace

bool IsCollectionPath(const std::string& path) {
    return path.rfind("builtin:", 0) != 0 && LowerExtension(path) == ".pvd";
}

bool ReadOptions::Wants(const std::string& name) const {
    if (!fields) return true;
    for (const std::string& want : *fields) {
        if (want == name) return true;
        if (want.size() > name.size() && want.compare(0, name.size(), name) == 0 &&
            (want[name.size()] == '.' || want[name.size()] == '['))
            return true;
    }
    return false;
}

Mesh ReadMesh(const std::string& path, const ReadOptions& options) {
    if (path.rfind("builtin:", 0) == 0) return MakeBuiltin(path);
    std::error_code ec;
    if (!std::filesystem::exists(path, ec))
        throw InputError(path, "", "no such file");
    if (std::filesystem::is_directory(path, ec))
        throw InputError(path, "", "is a directory, not a mesh file");
    const std::string ext = LowerExtension(path);
    if (ext == ".vtu" || ext == ".pvtu" || ext == ".vts" || ext == ".pvts")
        return ReadVtkXml(path, options);
    if (ext == ".vtk") return ReadVtkLegacy(path, options);
    if (ext == ".msh") return ReadGmsh(path, options);
    if (ext == ".pvd") return ReadCollectionStep(ReadCollection(path), options.timeStep, options);
    throw InputError(path, "", "unknown mesh format '" + ext +
                                   "' (expected .vtu, .pvtu, .vts, .pvts, .vtk, .msh, .pvd "
                                   "or builtin:NAME)");
}

}  // namespace hpray
