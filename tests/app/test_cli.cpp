// The hpray executable end to end: exit codes, messages and `info --json` on known data.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <sys/wait.h>

namespace {

struct RunResult {
    int code = -1;
    std::string out;  ///< stdout and stderr together
};

RunResult RunHpray(const std::string& args) {
    RunResult r;
    const std::string cmd = std::string(HPRAY_BINARY) + " " + args + " 2>&1";
    FILE* pipe = popen(cmd.c_str(), "r");
    if (!pipe) return r;
    std::array<char, 4096> buf;
    std::size_t n;
    while ((n = fread(buf.data(), 1, buf.size(), pipe)) > 0) r.out.append(buf.data(), n);
    const int status = pclose(pipe);
    r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    return r;
}

nlohmann::json InfoJson(const std::string& mesh) {
    RunResult r = RunHpray("info --json -q " + mesh);
    EXPECT_EQ(r.code, 0) << r.out;
    // -q keeps stderr quiet, so the output is the JSON alone.
    return nlohmann::json::parse(r.out);
}

TEST(Cli, InfoOnBuiltins) {
    auto j = InfoJson("builtin:cube-tets-3");
    EXPECT_EQ(j["cells"], 135);
    EXPECT_EQ(j["points"], 64);
    EXPECT_EQ(j["cells_by_type"]["tet"], 135);
    EXPECT_EQ(j["orders"]["1"], 135);
    EXPECT_EQ(j["fields"]["u"]["association"], "point");
    // u = x + 2y + 3z on the unit cube ranges over [0, 6].
    EXPECT_EQ(j["fields"]["u"]["range"], nlohmann::json({0.0, 6.0}));
    EXPECT_EQ(j["bounds"], nlohmann::json({{0.0, 0.0, 0.0}, {1.0, 1.0, 1.0}}));

    j = InfoJson("builtin:nk-sinc");
    EXPECT_EQ(j["cells_by_type"]["hex"], 125);
    EXPECT_EQ(j["orders"]["8"], 125);
    j = InfoJson("builtin:nk-quartic");
    EXPECT_EQ(j["cells_by_type"]["hex"], 8);
    j = InfoJson("builtin:ball-p2");
    EXPECT_EQ(j["orders"]["2"], 320);
    // u = x^2 + y^2 + z^2 over [-1,1]^3: the nodes include the origin and the corners.
    EXPECT_EQ(j["fields"]["u"]["range"], nlohmann::json({0.0, 3.0}));
}

TEST(Cli, BadInputExitsTwoNamingTheFile) {
    RunResult r = RunHpray("info /nonexistent/mesh.vtu");
    EXPECT_EQ(r.code, 2);
    EXPECT_NE(r.out.find("/nonexistent/mesh.vtu"), std::string::npos) << r.out;

    const auto dir = std::filesystem::temp_directory_path() / "hpray_test_cli";
    std::filesystem::create_directories(dir);
    const auto odd = dir / "mesh.xyz";
    std::ofstream(odd) << "nothing\n";
    r = RunHpray("info " + odd.string());
    EXPECT_EQ(r.code, 2);
    EXPECT_NE(r.out.find("mesh.xyz"), std::string::npos) << r.out;

    r = RunHpray("info builtin:nope");
    EXPECT_EQ(r.code, 2);
    EXPECT_NE(r.out.find("builtin:nope"), std::string::npos) << r.out;

    EXPECT_EQ(RunHpray("frobnicate").code, 2);
    EXPECT_EQ(RunHpray("").code, 2);
    EXPECT_EQ(RunHpray("info").code, 2);
}

TEST(Cli, UnfinishedSubcommandsSaySo) {
    RunResult r = RunHpray("partition builtin:cube-tets-2 --bricks 2 --out /tmp/hpray_no_partition");
    EXPECT_EQ(r.code, 2);
    EXPECT_NE(r.out.find("not implemented"), std::string::npos) << r.out;
}

TEST(Cli, HelpExitsZero) { EXPECT_EQ(RunHpray("--help").code, 0); }

}  // namespace
