// hpray info: cells by type and order, points, bounds, fields with ranges, memory.
#include <nlohmann/json.hpp>

#include <chrono>
#include <cstdio>
#include <iostream>
#include <map>
#include <optional>

#include "app/commands.h"
#include "elements/mesh_geometry.h"
#include "io/mesh_io.h"
#include "partition.h"
#include "util/log.h"

namespace hpray::app {

nlohmann::json MeshSummaryJson(const Mesh& mesh) {
    using nlohmann::json;
    json j;
    j["points"] = mesh.PointCount();
    j["cells"] = mesh.CellCount();
    std::map<std::string, std::int64_t> byType{{"tet", 0}, {"hex", 0}, {"wedge", 0}, {"pyramid", 0}};
    std::map<std::string, std::int64_t> byOrder;
    std::int64_t serendipity = 0, ghosts = 0;
    for (std::int64_t c = 0; c < mesh.CellCount(); ++c) {
        byType[ShapeName(mesh.cellShape[c])]++;
        byOrder[std::to_string(mesh.cellOrder[c])]++;
        serendipity += mesh.cellFamily[c] == CellFamily::Serendipity;
    }
    for (std::uint8_t g : mesh.ghost) ghosts += g != 0;
    j["cells_by_type"] = byType;
    j["orders"] = byOrder;
    j["serendipity_cells"] = serendipity;
    j["ghost_cells"] = ghosts;
    const auto b = mesh.Bounds();
    j["bounds"] = {b.lo, b.hi};
    {
        // How the cells map: affine (closed-form inversion), curved but of a lower map
        // order than their nodes (a trilinear cell with order-8 nodes), or curved.
        const MeshGeometry geometry = MeshGeometry::Build(mesh);
        const std::int64_t affine = geometry.AffineCells();
        j["geometry"] = {{"affine_cells", affine},
                         {"reduced_map_cells", geometry.reducedMapCells},
                         {"curved_cells", mesh.CellCount() - affine}};
    }
    json fields = json::object();
    auto addField = [&](const Field& f) {
        json e;
        e["association"] = f.association == Association::Point ? "point" : "cell";
        e["components"] = f.components;
        const auto r = f.Range(f.components == 1 ? 0 : -1);
        e["range"] = {r[0], r[1]};
        if (f.components > 1) {
            json comps = json::array();
            for (int c = 0; c < f.components; ++c) {
                const auto rc = f.Range(c);
                comps.push_back({rc[0], rc[1]});
            }
            e["component_ranges"] = comps;
        }
        fields[f.name] = e;
    };
    for (const Field& f : mesh.pointFields) addField(f);
    for (const Field& f : mesh.cellFields) addField(f);
    j["fields"] = fields;
    j["memory_bytes"] = mesh.MemoryBytes();
    return j;
}

namespace {
void PrintText(const std::string& name, const nlohmann::json& j, double seconds) {
    std::printf("%s\n", name.c_str());
    std::printf("  points   %lld\n", j["points"].get<long long>());
    std::printf("  cells    %lld", j["cells"].get<long long>());
    for (auto& [type, n] : j["cells_by_type"].items())
        std::printf("  %s: %lld", type.c_str(), n.get<long long>());
    std::printf("\n  orders  ");
    for (auto& [order, n] : j["orders"].items())
        std::printf("  p=%s: %lld", order.c_str(), n.get<long long>());
    if (j["serendipity_cells"].get<long long>() > 0)
        std::printf("  (serendipity: %lld)", j["serendipity_cells"].get<long long>());
    std::printf("\n");
    const auto& b = j["bounds"];
    std::printf("  bounds   [%.9g, %.9g] x [%.9g, %.9g] x [%.9g, %.9g]\n",
                b[0][0].get<double>(), b[1][0].get<double>(), b[0][1].get<double>(),
                b[1][1].get<double>(), b[0][2].get<double>(), b[1][2].get<double>());
    const auto& g = j["geometry"];
    std::printf("  geometry affine: %lld  curved: %lld (of a lower map order: %lld)\n",
                g["affine_cells"].get<long long>(), g["curved_cells"].get<long long>(),
                g["reduced_map_cells"].get<long long>());
    for (auto& [fname, f] : j["fields"].items())
        std::printf("  field    %-24s %-5s %d component%s  range [%.9g, %.9g]\n", fname.c_str(),
                    f["association"].get<std::string>().c_str(), f["components"].get<int>(),
                    f["components"].get<int>() == 1 ? " " : "s",
                    f["range"][0].get<double>(), f["range"][1].get<double>());
    if (j["ghost_cells"].get<long long>() > 0)
        std::printf("  ghosts   %lld\n", j["ghost_cells"].get<long long>());
    std::printf("  memory   %.1f MiB (read in %.3f s)\n",
                j["memory_bytes"].get<double>() / (1024.0 * 1024.0), seconds);
}
}  // namespace

int RunInfo(const InfoArgs& args) {
    if (partition::IsPartitionDirectory(args.mesh)) {  // a partition: summary of its bricks
        const nlohmann::json j = partition::SummarizePartition(args.mesh);
        if (args.json)
            std::cout << j.dump(2) << std::endl;
        else
            std::cout << partition::FormatPartitionSummary(j) << std::flush;
        return j["checksums_ok"].get<bool>() ? 0 : 2;
    }
    const auto start = std::chrono::steady_clock::now();
    const Mesh mesh = ReadMesh(args.mesh);
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    nlohmann::json j = MeshSummaryJson(mesh);
    j["source"] = args.mesh;
    j["read_seconds"] = seconds;
    // A time series: its steps' times; the summary is of the first step.
    std::optional<Collection> collection;
    if (IsCollectionPath(args.mesh)) {
        collection = ReadCollection(args.mesh);
        nlohmann::json times = nlohmann::json::array();
        for (const CollectionStep& step : collection->steps) times.push_back(step.time);
        j["time_steps"] = times;
    }
    if (args.json) {
        std::cout << j.dump(2) << std::endl;
    } else {
        PrintText(args.mesh, j, seconds);
        if (collection)
            std::printf("  steps    %zu (the summary is of the first), at times %s\n",
                        collection->steps.size(), collection->TimesText().c_str());
    }
    return 0;
}

}  // namespace hpray::app
