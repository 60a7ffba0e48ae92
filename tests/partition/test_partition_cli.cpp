// `hpray partition` as a process: peak memory against --memory-limit on an input 4x
// larger, interrupted runs and reruns, malformed arguments, `hpray info DIR`.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "io/vtu_writer.h"
#include "mesh/builtin.h"
#include "partition.h"
#include "partition_test_util.h"
#include "util/error.h"

namespace hpray {
namespace {

namespace fs = std::filesystem;
using test::ScratchDir;

struct ChildResult {
    int code = -1;       ///< exit code, or -signal
    long maxRssKiB = 0;  ///< ru_maxrss of the child
    std::string output;  ///< stdout + stderr
};

/// Runs hpray with `args` (and extra environment entries), waits, and reports the exit
/// status and the child's peak resident set size. `killWhen`, if set, is polled every
/// 20 ms; when it returns true the child gets SIGKILL.
ChildResult RunChild(const std::vector<std::string>& args,
                     const std::vector<std::string>& env,
                     const std::function<bool()>& killWhen = nullptr) {
    const std::string log = fs::temp_directory_path() /
                            ("hpray_test_child_" + std::to_string(::getpid()) + ".log");
    const pid_t pid = ::fork();
    if (pid == 0) {
        const int fd = ::open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
        ::dup2(fd, 1);
        ::dup2(fd, 2);
        for (const std::string& e : env) ::putenv(const_cast<char*>(e.c_str()));
        std::vector<char*> argv{const_cast<char*>(HPRAY_BINARY)};
        for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
        argv.push_back(nullptr);
        ::execv(HPRAY_BINARY, argv.data());
        ::_exit(127);
    }
    ChildResult r;
    int status = 0;
    struct rusage usage {};
    while (true) {
        const pid_t done = ::wait4(pid, &status, killWhen ? WNOHANG : 0, &usage);
        if (done == pid) break;
        if (killWhen && killWhen()) {
            ::kill(pid, SIGKILL);
            ::wait4(pid, &status, 0, &usage);
            break;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -WTERMSIG(status);
    r.maxRssKiB = usage.ru_maxrss;
    std::ifstream in(log);
    r.output.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
    fs::remove(log);
    return r;
}

/// A valid, complete partition of `bricks` bricks: manifest, tree, every checksum.
void ExpectCompletePartition(const std::string& dir, int bricks, std::int64_t cells) {
    const partition::Partition p = partition::ReadPartition(dir);
    ASSERT_EQ(static_cast<int>(p.bricks.size()), bricks);
    std::int64_t owned = 0;
    for (int b = 0; b < bricks; ++b) {
        EXPECT_NO_THROW(partition::VerifyBrick(p, b)) << b;
        owned += p.bricks[b].cells - p.bricks[b].ghosts;
    }
    EXPECT_EQ(owned, cells);
    // Nothing else of ours is left: no spill folders, temporaries or extra bricks.
    for (const auto& e : fs::directory_iterator(dir)) {
        const std::string name = e.path().filename().string();
        EXPECT_EQ(name.find(".spill-"), std::string::npos) << name;
        EXPECT_EQ(name.find(".tmp"), std::string::npos) << name;
        if (name.rfind("brick-", 0) == 0) {
            const int index = std::stoi(name.substr(6));
            EXPECT_LT(index, bricks) << name;
        }
    }
}

TEST(PartitionCli, PeakMemoryStaysWithinTheLimit) {
    ScratchDir dir("partition_rss");
    // cube-tets-66: 1.44M tets in an appended raw .vtu of about 65 MiB (Float64, Int64;
    // linear tets are written as VTK_TETRA, without HigherOrderDegrees).
    const std::string input = dir / "cube.vtu";
    std::int64_t cells = 0;
    {
        const Mesh mesh = MakeBuiltin("builtin:cube-tets-66");
        cells = mesh.CellCount();
        WriteVtu(input, mesh);
    }
    const std::size_t limit = std::size_t(16) << 20;
    ASSERT_GE(fs::file_size(input), 4 * limit);
    const ChildResult r = RunChild({"partition", input, "--bricks", "16", "--out",
                                    dir / "p", "--memory-limit", "16M"},
                                   {});
    ASSERT_EQ(r.code, 0) << r.output;
    const double peakMiB = r.maxRssKiB / 1024.0;
    RecordProperty("peak_rss_mib", std::to_string(peakMiB));
    EXPECT_LE(peakMiB, 16.0 + 64.0) << r.output;
    ExpectCompletePartition(dir / "p", 16, cells);
    // A partition's own index streams back in: the ghost copies are dropped.
    const ChildResult again =
        RunChild({"partition", dir / "p/bricks.pvtu", "--bricks", "12", "--out",
                  dir / "q", "--memory-limit", "16M"},
                 {});
    ASSERT_EQ(again.code, 0) << again.output;
    ExpectCompletePartition(dir / "q", 12, cells);
}

TEST(PartitionCli, InterruptedRunsAreRerunCleanly) {
    ScratchDir dir("partition_kill");
    const std::string input = dir / "cube.vtu";
    std::int64_t cells = 0;
    {
        const Mesh mesh = MakeBuiltin("builtin:cube-tets-20");
        cells = mesh.CellCount();
        WriteVtu(input, mesh);
    }
    const std::string out = dir / "p";
    // An earlier complete partition with more bricks is in the folder.
    ASSERT_EQ(RunChild({"partition", input, "--bricks", "9", "--out", out}, {}).code, 0);
    ExpectCompletePartition(out, 9, cells);

    // Dies after writing 2 of 6 bricks: no manifest may survive.
    const ChildResult dead = RunChild({"partition", input, "--bricks", "6", "--out", out},
                                      {"HPRAY_PARTITION_TEST_EXIT_AFTER_BRICKS=2"});
    EXPECT_EQ(dead.code, 75) << dead.output;
    EXPECT_FALSE(fs::exists(out + "/manifest.json"));
    EXPECT_THROW(partition::ReadPartition(out), InputError);
    // The rerun starts clean: 6 bricks, no stale brick-0006..8, no spills.
    ASSERT_EQ(RunChild({"partition", input, "--bricks", "6", "--out", out}, {}).code, 0);
    ExpectCompletePartition(out, 6, cells);

    // kill -9 at the moment the first brick appears.
    const ChildResult killed =
        RunChild({"partition", input, "--bricks", "4", "--out", out}, {}, [&] {
            return !fs::exists(out + "/manifest.json") &&
                   fs::exists(out + "/brick-0000.vtu");
        });
    if (killed.code == -SIGKILL) {
        EXPECT_FALSE(fs::exists(out + "/manifest.json"));
    }
    ASSERT_EQ(RunChild({"partition", input, "--bricks", "4", "--out", out}, {}).code, 0);
    ExpectCompletePartition(out, 4, cells);
}

TEST(PartitionCli, MalformedArgumentsExit2) {
    ScratchDir dir("partition_args");
    const std::string out = dir / "p";
    struct Case {
        std::vector<std::string> args;
        std::string message;
    };
    const std::vector<Case> cases = {
        {{"partition", "builtin:cube-tets-2", "--bricks", "0", "--out", out}, "--bricks"},
        {{"partition", "builtin:cube-tets-2", "--bricks", "-3", "--out", out},
         "--bricks"},
        {{"partition", "builtin:cube-tets-1", "--bricks", "6", "--out", out}, "5 cells"},
        {{"partition", "builtin:cube-tets-2", "--bricks", "2", "--out", out,
          "--memory-limit", "lots"},
         "--memory-limit"},
        {{"partition", "builtin:cube-tets-2", "--bricks", "2", "--out", out,
          "--memory-limit", "1K"},
         "too small"},
        {{"partition", "builtin:cube-tets-2", "--bricks", "2", "--out", out, "--fields",
          "nope"},
         "nope"},
        {{"partition", dir / "missing.vtu", "--bricks", "2", "--out", out},
         "missing.vtu"},
        {{"partition", "builtin:cube-tets-2", "--bricks", "two", "--out", out}, "bricks"},
    };
    for (const Case& c : cases) {
        const ChildResult r = RunChild(c.args, {});
        EXPECT_EQ(r.code, 2) << c.args[3] << ": " << r.output;
        EXPECT_NE(r.output.find(c.message), std::string::npos) << r.output;
        EXPECT_FALSE(fs::exists(out + "/manifest.json"));
    }
}

TEST(PartitionCli, InfoSummarisesAPartition) {
    ScratchDir dir("partition_info");
    const std::string out = dir / "p";
    ASSERT_EQ(
        RunChild({"partition", "builtin:cube-tets-5", "--bricks", "5", "--out", out}, {})
            .code,
        0);
    const ChildResult r = RunChild({"info", "--json", "-q", out}, {});
    ASSERT_EQ(r.code, 0) << r.output;
    const nlohmann::json j = nlohmann::json::parse(r.output);
    EXPECT_EQ(j["bricks"], 5);
    EXPECT_EQ(j["owned_cells"], 5 * 125);  // builtin cube-tets-N has 5 N^3 tets
    EXPECT_EQ(j["cells"].get<std::int64_t>(),
              j["owned_cells"].get<std::int64_t>() + j["ghosts"].get<std::int64_t>());
    EXPECT_LE(j["balance"].get<double>(), 1.05);
    EXPECT_GE(j["balance"].get<double>(), 1.0);
    EXPECT_TRUE(j["checksums_ok"].get<bool>());
    std::uint64_t bytes = 0;
    for (const auto& e : fs::directory_iterator(out))
        if (e.is_regular_file() && e.path().filename().string()[0] != '.')
            bytes += e.file_size();
    EXPECT_EQ(j["bytes"].get<std::uint64_t>(), bytes);
    EXPECT_EQ(j["bounds"], nlohmann::json({{0.0, 0.0, 0.0}, {1.0, 1.0, 1.0}}));

    const ChildResult text = RunChild({"info", out}, {});
    EXPECT_EQ(text.code, 0);
    EXPECT_NE(text.output.find("balance"), std::string::npos) << text.output;
    EXPECT_NE(text.output.find("ghosts"), std::string::npos) << text.output;
    // A corrupted brick: info reports it and exits 2.
    {
        std::fstream f(out + "/brick-0002.vtu",
                       std::ios::in | std::ios::out | std::ios::binary);
        f.seekp(-50, std::ios::end);
        f.put('#');
    }
    const ChildResult bad = RunChild({"info", out}, {});
    EXPECT_EQ(bad.code, 2);
    EXPECT_NE(bad.output.find("MISMATCH"), std::string::npos) << bad.output;
}

}  // namespace
}  // namespace hpray
