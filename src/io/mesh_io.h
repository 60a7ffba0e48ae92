// Reading meshes: one entry point that dispatches on the path (file extension or builtin:).
#pragma once

#include <optional>
#include <set>
#include <string>

#include "mesh/mesh.h"

namespace hpray {

struct ReadOptions {
    /// Fields to load (point or cell, by array name); std::nullopt loads every field.
    /// Names of vector components ("u.x") select their whole array.
    std::optional<std::set<std::string>> fields;

    /// Whether the array `name` is to be loaded ("u", "u.x" or "u[0]" in the set selects
    /// "u").
    bool Wants(const std::string& name) const;
};

/// Reads `path`: builtin:NAME[?k=v&...], *.vtu, *.pvtu, *.vts, *.vtk (legacy), *.msh
/// (Gmsh 4.1). The result has passed Mesh::Validate. Throws InputError naming the file and
/// the position of the first problem.
Mesh ReadMesh(const std::string& path, const ReadOptions& options = {});

// Format readers (each validates its result).
Mesh ReadVtkXml(const std::string& path, const ReadOptions& options);      // .vtu .pvtu .vts
Mesh ReadVtkLegacy(const std::string& path, const ReadOptions& options);   // .vtk
Mesh ReadGmsh(const std::string& path, const ReadOptions& options);        // .msh 4.1

}  // namespace hpray
