// Subcommand entry points of the hpray executable; each returns the process exit code.
#pragma once

#include <string>
#include <vector>

namespace hpray::app {

struct InfoArgs {
    std::string mesh;
    bool json = false;
};
int RunInfo(const InfoArgs& args);

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
};
int RunRender(const RenderArgs& args);

struct PartitionArgs {
    std::string mesh;
    int bricks = 0;
    std::string outDir;
    std::string memoryLimit;
    std::vector<std::string> fields;
};
int RunPartition(const PartitionArgs& args);

}  // namespace hpray::app
