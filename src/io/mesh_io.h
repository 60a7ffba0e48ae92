// Reading meshes: one entry point that dispatches on the path (file extension or builtin:).
#pragma once

#include <optional>
#include <set>
#include <string>
#include <vector>

#include "mesh/mesh.h"

namespace hpray {

struct ReadOptions {
    /// Fields to load (point or cell, by array name); std::nullopt loads every field.
    /// Names of vector components ("u.x") select their whole array.
    std::optional<std::set<std::string>> fields;

    /// For a .pvd collection: the index of the time step to read (0: the first).
    int timeStep = 0;

    /// Whether the array `name` is to be loaded ("u", "u.x" or "u[0]" in the set selects
    /// "u").
    bool Wants(const std::string& name) const;
};

/// Reads `path`: builtin:NAME[?k=v&...], *.vtu, *.pvtu, *.vts, *.vtk (legacy), *.msh
/// (Gmsh 4.1), or one time step (options.timeStep) of a *.pvd collection. The result has
/// passed Mesh::Validate. Throws InputError naming the file and the position of the first
/// problem.
Mesh ReadMesh(const std::string& path, const ReadOptions& options = {});

/// One time step of a ParaView collection: its time and the files of its parts (the
/// DataSets of that timestep, by increasing `part`), absolute or relative to the working
/// directory as the .pvd's path is.
struct CollectionStep {
    double time = 0.0;
    std::vector<std::string> files;
};

/// A ParaView collection (.pvd): <VTKFile type="Collection"><Collection> with one
/// <DataSet timestep=".." part=".." file=".."/> per part of each step.
struct Collection {
    std::string path;
    std::vector<CollectionStep> steps;  ///< by increasing time, at least one

    /// "0, 0.1, 0.2" (at most `most` times, then "...").
    std::string TimesText(std::size_t most = 12) const;
    /// The index of the step at `time` (equal to within 1e-9 of the times' scale), or -1.
    int FindTime(double time) const;
};

/// Whether `path` names a .pvd collection (by its extension).
bool IsCollectionPath(const std::string& path);

/// Reads and checks a .pvd: the XML, a numeric `timestep` on every DataSet (or on none:
/// then all are parts of one step at time 0), distinct (timestep, part) pairs, and that
/// every file exists and is a mesh file (not a folder: a time series of partition
/// directories is not supported, nor a .pvd inside a .pvd). Steps are ordered by time;
/// the DataSets of one timestep are the parts of that step. Throws InputError naming the
/// .pvd and the DataSet.
Collection ReadCollection(const std::string& path);

/// Reads step `step` of `collection`: each part with ReadMesh, merged as pieces of one
/// mesh (as the pieces of a .pvtu: they must have the same fields).
Mesh ReadCollectionStep(const Collection& collection, int step, const ReadOptions& options);

// Format readers (each validates its result).
Mesh ReadVtkXml(const std::string& path, const ReadOptions& options);      // .vtu .pvtu .vts
Mesh ReadVtkLegacy(const std::string& path, const ReadOptions& options);   // .vtk
Mesh ReadGmsh(const std::string& path, const ReadOptions& options);        // .msh 4.1

}  // namespace hpray
