// hpray serve: a FrameJob kept across requests. Every rank loads and prepares once; rank 0
// answers HTTP (cpp-httplib) on a thread of its own, validates each request completely
// (JSON, scene keys, field names) before any other rank sees it, and hands valid frames
// to the main thread, which broadcasts them to every rank, renders, composites and keeps
// the outputs of the last frames.
#include <mpi.h>
#include <httplib.h>
#include <yaml-cpp/yaml.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <deque>
#include <filesystem>
#include <fstream>
#include <future>
#include <map>
#include <mutex>
#include <optional>
#include <random>
#include <sstream>
#include <thread>

#include "app/commands.h"
#include "app/viewer_assets.h"
#include "job/frame_job.h"
#include "render/render_job.h"
#include "scene/scene.h"
#include "util/error.h"
#include "util/log.h"
#include "util/mpi.h"

namespace hpray::app {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

constexpr std::size_t kMaxBody = 1 << 20;  // 1 MiB
constexpr int kKeptFrames = 16;

std::atomic<bool> gStop{false};
extern "C" void OnSignal(int) { gStop = true; }

std::string RandomToken() {
    std::random_device rd;
    std::ostringstream os;
    for (int k = 0; k < 4; ++k) {
        char part[9];
        std::snprintf(part, sizeof part, "%08x", static_cast<unsigned>(rd()));
        os << part;
    }
    return os.str();
}

/// The overrides of a request body as `key.path=value` items (the --set form): objects
/// recurse, anything else (scalars, lists) is one item whose value is its JSON text, which
/// YAML reads as the same value. Later items win, so a body applied after the command
/// line's --set replaces what it names and keeps the rest.
void Flatten(const json& j, const std::string& path, std::vector<std::string>& out) {
    if (j.is_object() && !j.empty()) {
        for (const auto& [k, v] : j.items()) Flatten(v, path.empty() ? k : path + "." + k, out);
        return;
    }
    if (!path.empty()) out.push_back(path + "=" + j.dump());
}

/// A YAML node as JSON (scalars that read as numbers or booleans become those).
json ToJson(const YAML::Node& n) {
    if (n.IsMap()) {
        json j = json::object();
        for (const auto& kv : n) j[kv.first.as<std::string>()] = ToJson(kv.second);
        return j;
    }
    if (n.IsSequence()) {
        json j = json::array();
        for (const auto& v : n) j.push_back(ToJson(v));
        return j;
    }
    if (!n.IsDefined() || n.IsNull()) return nullptr;
    const std::string s = n.as<std::string>();
    if (s == "true" || s == "false") return s == "true";
    char* end = nullptr;
    const double v = std::strtod(s.c_str(), &end);
    if (!s.empty() && end == s.c_str() + s.size()) return v;
    return s;
}

/// One frame to render, or the end of the service; its answer when done.
struct Command {
    enum Kind { Render = 1, Shutdown = 2 } kind = Render;
    std::vector<std::string> overrides;  ///< --set items, then the body's (validated)
    std::promise<std::pair<int, json>> answer;  ///< HTTP status and body
};

class CommandQueue {
  public:
    void Push(std::shared_ptr<Command> c) {
        std::lock_guard<std::mutex> lock(mutex_);
        queue_.push_back(std::move(c));
        ready_.notify_one();
    }
    /// The next command, or nullptr after `timeout` without one.
    std::shared_ptr<Command> Pop(std::chrono::milliseconds timeout) {
        std::unique_lock<std::mutex> lock(mutex_);
        if (!ready_.wait_for(lock, timeout, [&] { return !queue_.empty(); })) return nullptr;
        auto c = queue_.front();
        queue_.pop_front();
        return c;
    }

  private:
    std::mutex mutex_;
    std::condition_variable ready_;
    std::deque<std::shared_ptr<Command>> queue_;
};

void SendText(const std::string& text) {
    long long n = static_cast<long long>(text.size());
    MPI_Bcast(&n, 1, MPI_LONG_LONG, 0, MPI_COMM_WORLD);
    if (n > 0)
        MPI_Bcast(const_cast<char*>(text.data()), static_cast<int>(n), MPI_CHAR, 0,
                  MPI_COMM_WORLD);
}

std::string ReceiveText() {
    long long n = 0;
    MPI_Bcast(&n, 1, MPI_LONG_LONG, 0, MPI_COMM_WORLD);
    std::string text(static_cast<std::size_t>(n), '\0');
    if (n > 0) MPI_Bcast(text.data(), static_cast<int>(n), MPI_CHAR, 0, MPI_COMM_WORLD);
    return text;
}

std::vector<std::string> SplitLines(const std::string& text) {
    std::vector<std::string> lines;
    std::istringstream in(text);
    for (std::string line; std::getline(in, line);) lines.push_back(line);
    return lines;
}

/// Field names a scene may use: those of the data (vector fields also as "name[i]").
std::set<std::string> DataFields(const json& info) {
    std::set<std::string> names;
    if (!info.contains("fields")) return names;
    for (const auto& [name, f] : info["fields"].items()) {
        names.insert(name);
        const int components = f.contains("components") ? f["components"].get<int>() : 1;
        for (int c = 0; c < components; ++c)
            names.insert(name + "[" + std::to_string(c) + "]");
    }
    return names;
}


}  // namespace

int RunServe(const ServeArgs& args) {
    const bool root = mpi::WorldRank() == 0;
    // The scene file once, as text: every frame merges its overrides into it.
    std::string sceneText;
    {
        std::ifstream in(args.scene, std::ios::binary);
        if (!in) throw InputError(args.scene, "", "cannot open scene file");
        std::ostringstream text;
        text << in.rdbuf();
        sceneText = text.str();
    }
    const std::string baseDir = fs::absolute(fs::path(args.scene)).parent_path().string();
    Scene scene = ParseScene(sceneText, args.scene, args.overrides, baseDir);
    scene.sourcePath = args.scene;
    const std::string dataPath = scene.data.mesh;
    mpi::EnsureInitialized();
    std::signal(SIGINT, OnSignal);
    std::signal(SIGTERM, OnSignal);
    job::FrameJob frameJob(scene);

    if (!root) {
        // Follow rank 0's commands until it says to stop.
        while (true) {
            int kind = 0;
            MPI_Bcast(&kind, 1, MPI_INT, 0, MPI_COMM_WORLD);
            if (kind == Command::Shutdown) return 0;
            int cameraOnly = 0;
            MPI_Bcast(&cameraOnly, 1, MPI_INT, 0, MPI_COMM_WORLD);
            const std::vector<std::string> overrides = SplitLines(ReceiveText());
            try {
                Scene s = ParseScene(sceneText, args.scene, overrides, baseDir);
                RenderStats stats;
                frameJob.Render(s, cameraOnly ? job::FrameJob::Change::CameraOnly
                                              : job::FrameJob::Change::Scene,
                                stats);
            } catch (const InputError&) {
                // Rank 0 reports it; every rank fails the same way on the same data.
            }
        }
    }

    // Rank 0: what /api/info answers, and the folder of the kept frames.
    json info;
    info["data"] = frameJob.WholeMesh()
                       ? MeshSummaryJson(*frameJob.WholeMesh())
                       : partition::SummarizePartition(dataPath);
    YAML::Node sceneRoot = YAML::Load(sceneText);
    if (!sceneRoot.IsMap()) sceneRoot = YAML::Node(YAML::NodeType::Map);
    info["scene"] = ToJson(sceneRoot);
    info["overrides"] = args.overrides;
    const std::set<std::string> fields = DataFields(info["data"]);
    const fs::path frames =
        fs::temp_directory_path() / ("hpray-serve-" + std::to_string(::getpid()));
    fs::create_directories(frames);

    std::string token = args.token;
    if (token.empty() && std::getenv("HPRAY_TOKEN")) token = std::getenv("HPRAY_TOKEN");
    if (token.empty()) token = RandomToken();
    if (args.bind != "127.0.0.1" && args.bind != "localhost" && args.bind != "::1")
        log::Warn("hpray serve listens on " + args.bind +
                  ", not only on this machine: anyone who can reach it and has the token "
                  "can render with this job's data");

    CommandQueue queue;
    // The kept frames: their files are written on a thread of their own while the next
    // frame renders; a request for a file waits for its frame's writing.
    std::mutex framesMutex;
    std::map<int, std::shared_future<std::string>> written;  // "" or the write's error
    int lastFrame = 0;

    httplib::Server server;
    server.set_payload_max_length(kMaxBody);
    auto fail = [](httplib::Response& res, int status, const std::string& message) {
        res.status = status;
        res.set_content(json{{"error", message}}.dump(), "application/json");
    };
    server.set_pre_routing_handler([&](const httplib::Request& req, httplib::Response& res) {
        if (req.path.rfind("/api/", 0) != 0) return httplib::Server::HandlerResponse::Unhandled;
        const std::string bearer = req.get_header_value("Authorization");
        const bool ok = bearer == "Bearer " + token ||
                        (req.has_param("token") && req.get_param_value("token") == token);
        if (ok) return httplib::Server::HandlerResponse::Unhandled;
        fail(res, 401, "missing or wrong token");
        return httplib::Server::HandlerResponse::Handled;
    });
    // The viewer: its files as compiled in (src/app/viewer/); "/" is index.html.
    for (const ViewerAsset& asset : ViewerAssets()) {
        const std::string name = asset.name;
        auto serveAsset = [&asset](const httplib::Request&, httplib::Response& res) {
            res.set_content(asset.bytes, asset.size, asset.mime);
        };
        server.Get("/" + name, serveAsset);
        if (name == "index.html") server.Get("/", serveAsset);
    }
    server.Get("/api/info", [&](const httplib::Request&, httplib::Response& res) {
        res.set_content(info.dump(), "application/json");
    });
    server.Post("/api/render", [&](const httplib::Request& req, httplib::Response& res) {
        json body;
        try {
            body = req.body.empty() ? json::object() : json::parse(req.body);
        } catch (const json::parse_error& e) {
            return fail(res, 400, std::string("malformed JSON: ") + e.what());
        }
        if (!body.is_object()) return fail(res, 400, "the body must be a JSON object");
        for (const char* fixed : {"data", "output", "threads", "distribute"})
            if (body.contains(fixed))
                return fail(res, 400,
                            std::string(fixed) +
                                ": is fixed when the service starts; it cannot change per "
                                "frame");
        auto command = std::make_shared<Command>();
        command->overrides = args.overrides;
        Flatten(body, "", command->overrides);
        for (const std::string& item : command->overrides)
            if (item.find('\n') != std::string::npos)
                return fail(res, 400, "a key holds a line break");
        try {
            // The whole validation the YAML path does, and the fields the data has.
            const Scene s = ParseScene(sceneText, args.scene, command->overrides, baseDir);
            for (const std::string& name : s.FieldNames())
                if (!fields.count(name))
                    return fail(res, 400, "field '" + name + "' is not in " + dataPath);
        } catch (const InputError& e) {
            return fail(res, 400, e.what());
        }
        auto answer = command->answer.get_future();
        queue.Push(command);
        const auto [status, reply] = answer.get();
        res.status = status;
        res.set_content(reply.dump(), "application/json");
    });
    server.Get(R"(/api/frames/(\d+)/(image\.png|image\.exr|rgba\.npy|hits\.npy))",
               [&](const httplib::Request& req, httplib::Response& res) {
                   const std::string id = req.matches[1], name = req.matches[2];
                   std::shared_future<std::string> done;
                   {
                       std::lock_guard<std::mutex> lock(framesMutex);
                       const auto it = written.find(std::atoi(id.c_str()));
                       if (it == written.end())
                           return fail(res, 404, "frame " + id + " is not kept");
                       done = it->second;
                   }
                   const std::string error = done.get();
                   if (!error.empty()) return fail(res, 500, error);
                   std::ifstream in(frames / id / name, std::ios::binary);
                   if (!in) return fail(res, 404, "frame " + id + " is not kept");
                   std::ostringstream bytes;
                   bytes << in.rdbuf();
                   res.set_content(bytes.str(), name.size() > 4 &&
                                                        name.substr(name.size() - 4) == ".png"
                                                    ? "image/png"
                                                    : "application/octet-stream");
               });
    server.Post("/api/shutdown", [&](const httplib::Request&, httplib::Response& res) {
        gStop = true;
        res.set_content("{}", "application/json");
    });

    const int port = args.port == 0 ? server.bind_to_any_port(args.bind)
                                    : (server.bind_to_port(args.bind, args.port) ? args.port : -1);
    if (port < 0) {
        fs::remove_all(frames);
        throw InputError("command line", "--port",
                         "cannot listen on " + args.bind + ":" + std::to_string(args.port));
    }
    std::thread http([&] { server.listen_after_bind(); });
    std::printf("hpray serve: listening on http://%s:%d/ token %s\n", args.bind.c_str(), port,
                token.c_str());
    std::fflush(stdout);

    // What the job's current scene is made of, camera aside: a frame that changes only
    // the camera reuses all preparation.
    auto nonCamera = [](const std::vector<std::string>& items) {
        std::vector<std::string> out;
        for (const std::string& item : items)
            if (item.rfind("camera.", 0) != 0 && item.rfind("camera=", 0) != 0)
                out.push_back(item);
        return out;
    };
    std::optional<std::vector<std::string>> current = nonCamera(args.overrides);

    // The main thread: one frame at a time, in arrival order, on every rank.
    while (true) {
        std::shared_ptr<Command> command = queue.Pop(std::chrono::milliseconds(50));
        if (!command && !gStop) continue;
        if (!command) {
            int kind = Command::Shutdown;
            MPI_Bcast(&kind, 1, MPI_INT, 0, MPI_COMM_WORLD);
            break;
        }
        const std::vector<std::string> scenePart = nonCamera(command->overrides);
        int kind = Command::Render, cameraOnly = current && *current == scenePart ? 1 : 0;
        current = scenePart;
        MPI_Bcast(&kind, 1, MPI_INT, 0, MPI_COMM_WORLD);
        MPI_Bcast(&cameraOnly, 1, MPI_INT, 0, MPI_COMM_WORLD);
        std::string joined;
        for (const std::string& item : command->overrides) joined += item + "\n";
        SendText(joined);
        try {
            Scene s = ParseScene(sceneText, args.scene, command->overrides, baseDir);
            RenderStats stats;
            Image image = frameJob.Render(
                s, cameraOnly ? job::FrameJob::Change::CameraOnly : job::FrameJob::Change::Scene,
                stats);
            const int id = ++lastFrame;
            const fs::path dir = frames / std::to_string(id);
            fs::create_directories(dir);
            Scene out = frameJob.GetScene();
            out.output.exr = (dir / "image.exr").string();
            out.output.png = (dir / "image.png").string();
            out.output.rgba = (dir / "rgba.npy").string();
            out.output.hits = (dir / "hits.npy").string();
            out.output.stats.clear();
            frameJob.AddWarnings(frameJob.GetScene(), image, stats);
            // Answered before the files are written: the stats say so (timing_s.write 0).
            const json statsJson = json::parse(StatsToJson(stats));
            auto write = std::async(std::launch::async,
                                    [out, image = std::move(image), stats]() mutable {
                                        try {
                                            WriteJobOutputs(out, image, stats);
                                            return std::string();
                                        } catch (const std::exception& e) {
                                            return std::string(e.what());
                                        }
                                    })
                             .share();
            std::shared_future<std::string> evicted;
            {
                std::lock_guard<std::mutex> lock(framesMutex);
                written[id] = write;
                const auto old = written.find(id - kKeptFrames);
                if (old != written.end()) {
                    evicted = old->second;
                    written.erase(old);
                }
            }
            if (evicted.valid()) {
                evicted.wait();
                std::error_code ec;
                fs::remove_all(frames / std::to_string(id - kKeptFrames), ec);
            }
            command->answer.set_value({200, json{{"frame", id}, {"stats", statsJson}}});
        } catch (const InputError& e) {
            current.reset();  // the next frame prepares again
            command->answer.set_value({400, json{{"error", e.what()}}});
        }
    }
    server.stop();
    http.join();
    for (auto& [id, done] : written) done.wait();
    std::error_code ec;
    fs::remove_all(frames, ec);
    return 0;
}

}  // namespace hpray::app
