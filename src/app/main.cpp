// hpray command line: parses arguments, dispatches to a subcommand, maps errors to exit codes.
#include <CLI/CLI.hpp>

#include <algorithm>
#include <cstdio>
#include <exception>
#include <string>
#include <vector>

#include "app/commands.h"
#include "scene/scene.h"
#include "util/error.h"
#include "util/log.h"
#include "util/mpi.h"
#include "util/text.h"

int main(int argc, char** argv) {
    using namespace hpray;
    mpi::Session session(&argc, &argv);

    CLI::App cli{"hpray: pixel-exact, distributed rendering of finite element data"};
    cli.require_subcommand(1);
    cli.fallthrough();  // -v and -q may follow the subcommand
    bool verbose = false, quiet = false;
    cli.add_flag("-v,--verbose", verbose, "print debug messages");
    cli.add_flag("-q,--quiet", quiet, "print errors only");
    cli.set_version_flag("--version", std::string("hpray ") + HPRAY_VERSION);

    app::InfoArgs info;
    auto* infoCmd = cli.add_subcommand("info", "summarise a mesh, builtin or partition");
    infoCmd->add_option("mesh", info.mesh, "mesh file, builtin:NAME or partition directory")
        ->required();
    infoCmd->add_flag("--json", info.json, "print JSON");

    app::ProbeArgs probe;
    auto* probeCmd = cli.add_subcommand("probe", "evaluate fields at points");
    probeCmd->add_option("mesh", probe.mesh, "mesh file or builtin:NAME")->required();
    probeCmd->add_option("--points", probe.pointsCsv, "CSV file, one x,y,z per line")
        ->required();
    probeCmd->add_option("--fields", probe.fields, "fields to evaluate (default: all)")
        ->delimiter(',');
    probeCmd->add_flag("--gradient", probe.gradient, "also report world gradients");
    probeCmd->add_flag("--json", probe.json, "print JSON");

    app::RenderArgs render;
    auto* renderCmd = cli.add_subcommand("render", "render a scene");
    renderCmd->add_option("scene", render.scene, "scene YAML file")->required();
    renderCmd->add_option("--set", render.overrides, "override a scene key: key.path=value");
    renderCmd->add_flag("--strict", render.strict,
                        "treat every warning as an error (exit 2, no outputs)");
    {
        // The scene keys, so that --set can be written without the docs at hand.
        std::string keys;
        for (const std::string& path : SceneKeyPaths())
            if (path.find('.') != std::string::npos || path == "background" ||
                path == "outline" || path == "legend" || path == "threads" ||
                path == "distribute")
                keys += "  " + path + "\n";
        renderCmd->footer("\nScene keys (docs/scene.md gives their types, defaults and "
                          "meaning; # is a list index):\n" + keys);
    }

    app::ServeArgs serve;
    auto* serveCmd = cli.add_subcommand(
        "serve", "load a scene's data once and render frames on request over HTTP");
    serveCmd->add_option("scene", serve.scene, "scene YAML file")->required();
    serveCmd->add_option("--set", serve.overrides, "override a scene key: key.path=value");
    serveCmd->add_option("--port", serve.port, "TCP port (0: any free port)")
        ->check(CLI::Range(0, 65535));
    serveCmd->add_option("--bind", serve.bind, "address to listen on (default 127.0.0.1)");
    serveCmd->add_option("--token", serve.token,
                         "access token (default: $HPRAY_TOKEN, else a random one)");

    app::PartitionArgs part;
    auto* partCmd = cli.add_subcommand("partition", "split a mesh into k-d bricks");
    partCmd->add_option("mesh", part.mesh, "mesh file")->required();
    partCmd->add_option("--bricks", part.bricks, "number of bricks")->required();
    partCmd->add_option("--out", part.outDir, "output directory")->required();
    partCmd->add_option("--memory-limit", part.memoryLimit, "e.g. 512M, 4G");
    partCmd->add_option("--fields", part.fields, "fields to keep")->delimiter(',');
    partCmd->add_flag("--force", part.force,
                      "write into a folder that holds other files too");

    // The first word that is not an option names the subcommand: `hpray help` is --help,
    // and a misspelt one gets the nearest name instead of "a subcommand is required".
    for (int i = 1; i < argc; ++i) {
        const std::string word = argv[i];
        if (word.empty() || word[0] == '-') continue;
        if (word == "help") {
            std::printf("%s", cli.help().c_str());
            return 0;
        }
        std::vector<std::string> names;
        for (const CLI::App* sub : cli.get_subcommands({})) names.push_back(sub->get_name());
        if (std::find(names.begin(), names.end(), word) != names.end()) break;
        std::string nearest;
        std::size_t best = std::string::npos;
        for (const std::string& name : names) {
            const std::size_t d = EditDistance(word, name);
            if (d < best) best = d, nearest = name;
        }
        std::fprintf(stderr, "hpray: unknown subcommand '%s'%s (hpray --help lists them)\n",
                     word.c_str(),
                     best <= 2 ? ("; did you mean '" + nearest + "'?").c_str() : "");
        return 2;
    }
    try {
        cli.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        int code = cli.exit(e);
        return code == 0 ? 0 : 2;
    }
    log::SetLevel(quiet ? log::Level::Error : verbose ? log::Level::Debug : log::Level::Info);

    try {
        if (*infoCmd) return app::RunInfo(info);
        if (*probeCmd) return app::RunProbe(probe);
        if (*renderCmd) return app::RunRender(render);
        if (*serveCmd) return app::RunServe(serve);
        if (*partCmd) return app::RunPartition(part);
        return 2;
    } catch (const InputError& e) {
        log::Error(e.what());
        if (mpi::WorldSize() > 1) mpi::Abort(e.what(), 2);
        return 2;
    } catch (const std::bad_alloc&) {
        log::Error("out of memory");
        if (mpi::WorldSize() > 1) mpi::Abort("out of memory", 1);
        return 1;
    } catch (const std::exception& e) {
        log::Error(std::string("internal error: ") + e.what());
        if (mpi::WorldSize() > 1) mpi::Abort(e.what(), 1);
        return 1;
    }
}
