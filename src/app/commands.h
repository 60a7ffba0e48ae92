// Subcommand entry points of the hpray executable; each returns the process exit code.
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "mesh/mesh.h"

namespace hpray::app {

struct InfoArgs {
    std::string mesh;
    bool json = false;
};
int RunInfo(const InfoArgs& args);
/// The JSON of `hpray info --json` for a mesh in memory.
nlohmann::json MeshSummaryJson(const Mesh& mesh);

struct ProbeArgs {
    std::string mesh;
    std::string pointsCsv;
    std::vector<std::string> fields;
    bool gradient = false;
    bool json = false;
};
int RunProbe(const ProbeArgs& args);

struct RenderArgs {
    std::string scene;
    std::vector<std::string> overrides;  ///< "key.path=value"
    bool strict = false;                 ///< every warning is an error (exit 2)
};
int RunRender(const RenderArgs& args);

struct ServeArgs {
    std::string scene;
    std::vector<std::string> overrides;  ///< "key.path=value"
    int port = 8080;                     ///< 0: any free port
    std::string bind = "127.0.0.1";
    std::string token;                   ///< empty: $HPRAY_TOKEN, else random
};
int RunServe(const ServeArgs& args);

struct PartitionArgs {
    std::string mesh;
    int bricks = 0;
    std::string outDir;
    std::string memoryLimit;
    std::vector<std::string> fields;
    bool force = false;
};
int RunPartition(const PartitionArgs& args);

}  // namespace hpray::app
