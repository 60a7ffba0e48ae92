// Running hpray as a process from tests: a command's exit code and output, and the
// mpirun prefix for a number of ranks (as root, oversubscribed, unbound).
#pragma once

#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <string>

namespace hpray::test {

/// Runs `cmd` through the shell with stderr joined to stdout; its exit code (-1 if it
/// did not exit normally), and its output in `out`.
inline int RunCommand(const std::string& cmd, std::string* out = nullptr) {
    FILE* pipe = popen((cmd + " 2>&1").c_str(), "r");
    if (!pipe) return -1;
    std::array<char, 4096> buf;
    std::string text;
    std::size_t n;
    while ((n = fread(buf.data(), 1, buf.size(), pipe)) > 0) text.append(buf.data(), n);
    const int status = pclose(pipe);
    if (out) *out = text;
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

/// "--mca orte_tmpdir_base DIR" with a directory of this test process's own for Open
/// MPI's session files: mpiruns that tests running in parallel (ctest -j) start at the
/// same moment race to create the default one (/tmp/ompi.HOST.UID), and the loser fails
/// ("mkdir ... File exists", orte_init failed). This process's mpiruns run one at a time.
inline const std::string& MpiSessionOption() {
    // Removed when the process ends (Open MPI leaves it empty).
    struct Dir {
        std::filesystem::path path;
        std::string option;
        ~Dir() {
            std::error_code ec;
            std::filesystem::remove_all(path, ec);
        }
    };
    static const Dir dir = [] {
        const auto path = std::filesystem::temp_directory_path() /
                          ("hpray-test-ompi-" + std::to_string(getpid()));
        return Dir{path, " --mca orte_tmpdir_base " + path.string() + " "};
    }();
    return dir.option;
}

/// "mpiexec -n RANKS ..." with the options a root, 2-core machine needs.
inline std::string Mpirun(int ranks) {
    return std::string(HPRAY_MPIEXEC) + " -n " + std::to_string(ranks) +
           " --allow-run-as-root --oversubscribe --bind-to none" + MpiSessionOption();
}

}  // namespace hpray::test
