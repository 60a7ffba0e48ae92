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
#include <functional>
#include <future>
#include <map>
#include <mutex>
#include <optional>
#include <random>
#include <sstream>
#include <stdexcept>
#include <thread>

#include <unistd.h>

#include "app/commands.h"
#include "app/viewer_assets.h"
#include "io/image.h"
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
constexpr int kKeptFrames = 32;  // a progressive request keeps one per pass

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

/// The server-sent events of a progressive request, from the render loop to the HTTP
/// thread that streams them.
class EventChannel {
  public:
    void Push(const std::string& event, const json& data) {
        std::lock_guard<std::mutex> lock(mutex_);
        events_.push_back("event: " + event + "\ndata: " + data.dump() + "\n\n");
        ready_.notify_one();
    }
    void Close() {
        std::lock_guard<std::mutex> lock(mutex_);
        closed_ = true;
        ready_.notify_one();
    }
    enum class Got { Event, Timeout, Closed };
    /// The next event's text; Closed once every event has been taken after Close.
    Got Pop(std::string& text, std::chrono::milliseconds timeout) {
        std::unique_lock<std::mutex> lock(mutex_);
        ready_.wait_for(lock, timeout, [&] { return !events_.empty() || closed_; });
        if (!events_.empty()) {
            text = std::move(events_.front());
            events_.pop_front();
            return Got::Event;
        }
        return closed_ ? Got::Closed : Got::Timeout;
    }

  private:
    std::mutex mutex_;
    std::condition_variable ready_;
    std::deque<std::string> events_;
    bool closed_ = false;
};

/// One frame to render, or the end of the service; its answer when done.
struct Command {
    enum Kind { Render = 1, Shutdown = 2 } kind = Render;
    std::vector<std::string> overrides;  ///< --set items, then the body's (validated)
    std::promise<std::pair<int, json>> answer;  ///< HTTP status and body
    /// Progressive: the scale divisors of the passes, coarsest first (the last is 1);
    /// each pass is a frame of its own, sent on `events`. Empty: one frame, `answer`.
    std::vector<int> passes;
    int width = 0, height = 0;  ///< the frame's full size
    EventChannel events;
    std::atomic<bool> abandoned{false};  ///< the client of a progressive request left
};

/// The passes of `?progressive=1&passes=8,2,1`: scale divisors from 1 to 64, each smaller
/// than the one before, ending with 1 (added when missing). Default 8, 1.
std::vector<int> ParsePasses(const httplib::Request& req) {
    if (!req.has_param("passes")) return {8, 1};
    std::vector<int> passes;
    std::istringstream in(req.get_param_value("passes"));
    for (std::string item; std::getline(in, item, ',');) {
        char* end = nullptr;
        const long v = std::strtol(item.c_str(), &end, 10);
        if (item.empty() || *end != '\0' || v < 1 || v > 64 ||
            (!passes.empty() && v >= passes.back()))
            throw std::invalid_argument(
                "passes: a comma-separated list of decreasing scale divisors from 64 to 1, "
                "e.g. 8,2,1");
        passes.push_back(static_cast<int>(v));
    }
    if (passes.empty() || passes.back() != 1) passes.push_back(1);
    return passes;
}

class CommandQueue {
  public:
    void Push(std::shared_ptr<Command> c) {
        std::lock_guard<std::mutex> lock(mutex_);
        queue_.push_back(std::move(c));
        waiting_ = true;
        ready_.notify_one();
    }
    /// The next command, or nullptr after `timeout` without one.
    std::shared_ptr<Command> Pop(std::chrono::milliseconds timeout) {
        std::unique_lock<std::mutex> lock(mutex_);
        if (!ready_.wait_for(lock, timeout, [&] { return !queue_.empty(); })) return nullptr;
        auto c = queue_.front();
        queue_.pop_front();
        waiting_ = !queue_.empty();
        return c;
    }
    /// Whether a command is waiting (any thread; lock-free): a newer request supersedes
    /// the passes of a progressive one.
    bool Waiting() const { return waiting_.load(std::memory_order_relaxed); }

  private:
    std::mutex mutex_;
    std::condition_variable ready_;
    std::deque<std::shared_ptr<Command>> queue_;
    std::atomic<bool> waiting_{false};
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

/// Field names a scene may use: those of the data (vector fields also as name[i], name.i,
/// name.x/y/z and name.magnitude, as the renderer reads them).
std::set<std::string> DataFields(const json& info) {
    std::set<std::string> names;
    if (!info.contains("fields")) return names;
    for (const auto& [name, f] : info["fields"].items()) {
        names.insert(name);
        const int components = f.contains("components") ? f["components"].get<int>() : 1;
        for (int c = 0; c < components; ++c) {
            names.insert(name + "[" + std::to_string(c) + "]");
            names.insert(name + "." + std::to_string(c));
            if (c < 3) names.insert(name + "." + "xyz"[c]), names.insert(name + "." + "XYZ"[c]);
        }
        if (components > 1) names.insert(name + ".magnitude");
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
    if (scene.frames && root)
        log::Warn(args.scene + ": frames is for hpray render; hpray serve renders one frame "
                  "per request and ignores it");
    const std::string dataPath = scene.data.mesh;
    mpi::EnsureInitialized();
    std::signal(SIGINT, OnSignal);
    std::signal(SIGTERM, OnSignal);
    job::FrameJob frameJob(scene);

    // Every rank's process id and host, for /api/info (whom to look at when one fails).
    constexpr int kHostChars = 64;
    struct RankId {
        long long pid;
        char host[kHostChars];
    } self{static_cast<long long>(::getpid()), {}};
    ::gethostname(self.host, kHostChars - 1);
    std::vector<RankId> rankIds(root ? mpi::WorldSize() : 0);
    MPI_Gather(&self, sizeof self, MPI_BYTE, rankIds.data(), sizeof self, MPI_BYTE, 0,
               MPI_COMM_WORLD);

    if (!root) {
        // Follow rank 0's commands until it says to stop.
        while (true) {
            int kind = 0;
            MPI_Bcast(&kind, 1, MPI_INT, 0, MPI_COMM_WORLD);
            if (kind == Command::Shutdown) return 0;
            int flags[2] = {0, 0};  // camera only, cancellable
            MPI_Bcast(flags, 2, MPI_INT, 0, MPI_COMM_WORLD);
            const std::vector<std::string> overrides = SplitLines(ReceiveText());
            try {
                Scene s = ParseScene(sceneText, args.scene, overrides, baseDir);
                RenderStats stats;
                frameJob.Render(s, flags[0] ? job::FrameJob::Change::CameraOnly
                                            : job::FrameJob::Change::Scene,
                                stats,
                                flags[1] ? std::function<bool()>([] { return false; })
                                         : std::function<bool()>());
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
    // The scene as loaded: the file with the command line's --set items applied.
    YAML::Node sceneRoot = YAML::Load(MergeSceneOverrides(sceneText, args.scene, args.overrides));
    if (!sceneRoot.IsMap()) sceneRoot = YAML::Node(YAML::NodeType::Map);
    info["scene"] = ToJson(sceneRoot);
    info["overrides"] = args.overrides;
    info["ranks"] = json::array();
    for (int r = 0; r < static_cast<int>(rankIds.size()); ++r)
        info["ranks"].push_back(
            {{"rank", r}, {"pid", rankIds[r].pid}, {"host", std::string(rankIds[r].host)}});
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
        const bool progressive = req.has_param("progressive") &&
                                 req.get_param_value("progressive") != "0";
        if (progressive) {
            try {
                command->passes = ParsePasses(req);
            } catch (const std::invalid_argument& e) {
                return fail(res, 400, e.what());
            }
        }
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
            command->width = s.camera.width;
            command->height = s.camera.height;
        } catch (const InputError& e) {
            return fail(res, 400, e.what());
        }
        if (progressive) {
            // Server-sent events on the answer: one `pass` per finished pass, then `end`.
            // A client that leaves cancels the passes not yet rendered.
            queue.Push(command);
            res.set_header("Cache-Control", "no-cache");
            res.set_chunked_content_provider(
                "text/event-stream",
                [command](std::size_t, httplib::DataSink& sink) {
                    std::string text;
                    while (true) {
                        switch (command->events.Pop(text, std::chrono::seconds(1))) {
                            case EventChannel::Got::Closed:
                                sink.done();
                                return true;
                            case EventChannel::Got::Timeout:
                                text = ":\n\n";  // a comment: finds a client that left
                                [[fallthrough]];
                            case EventChannel::Got::Event:
                                if (!sink.write(text.data(), text.size())) {
                                    command->abandoned = true;
                                    return false;
                                }
                        }
                    }
                },
                [command](bool success) {
                    if (!success) command->abandoned = true;
                });
            return;
        }
        auto answer = command->answer.get_future();
        queue.Push(command);
        const auto [status, reply] = answer.get();
        res.status = status;
        res.set_content(reply.dump(), "application/json");
    });
    server.Get(R"(/api/frames/(\d+)/(image\.png|image\.exr|rgba\.npy|hits\.npy|errors\.npy))",
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

    // One frame on every rank: broadcasts it, renders, keeps its files (written on a
    // thread of their own) and returns its id and stats; 0 when it was cancelled.
    auto renderFrame = [&](const std::vector<std::string>& overrides,
                           const std::function<bool()>& cancel) -> std::pair<int, json> {
        const std::vector<std::string> scenePart = nonCamera(overrides);
        int kind = Command::Render;
        int flags[2] = {current && *current == scenePart ? 1 : 0, cancel ? 1 : 0};
        current = scenePart;
        MPI_Bcast(&kind, 1, MPI_INT, 0, MPI_COMM_WORLD);
        MPI_Bcast(flags, 2, MPI_INT, 0, MPI_COMM_WORLD);
        std::string joined;
        for (const std::string& item : overrides) joined += item + "\n";
        SendText(joined);
        try {
            Scene s = ParseScene(sceneText, args.scene, overrides, baseDir);
            RenderStats stats;
            Image image = frameJob.Render(
                s, flags[0] ? job::FrameJob::Change::CameraOnly : job::FrameJob::Change::Scene,
                stats, cancel);
            if (frameJob.Cancelled()) return {0, json()};
            const int id = ++lastFrame;
            const fs::path dir = frames / std::to_string(id);
            fs::create_directories(dir);
            Scene out = frameJob.GetScene();
            out.output.exr = (dir / "image.exr").string();
            out.output.png = (dir / "image.png").string();
            out.output.rgba = (dir / "rgba.npy").string();
            out.output.hits = (dir / "hits.npy").string();
            out.output.stats.clear();
            out.output.errors.clear();  // written below as errors.npy
            frameJob.AddWarnings(frameJob.GetScene(), image, stats);
            // Answered before the files are written: the stats say so (timing_s.write 0).
            json statsJson = json::parse(StatsToJson(stats));
            auto write = std::async(std::launch::async,
                                    [out, dir, image = std::move(image), stats,
                                     bounds = frameJob.DataBounds()]() mutable {
                                        try {
                                            WriteJobOutputs(out, image, bounds, stats);
                                            WriteNpyFloat32((dir / "errors.npy").string(),
                                                     ErrorArray(image),
                                                     {std::size_t(image.height),
                                                      std::size_t(image.width), 2});
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
            return {id, std::move(statsJson)};
        } catch (const InputError&) {
            current.reset();  // the next frame prepares again
            throw;
        }
    };

    // The main thread: one request at a time, in arrival order, on every rank.
    while (true) {
        std::shared_ptr<Command> command = queue.Pop(std::chrono::milliseconds(50));
        if (!command && !gStop) continue;
        if (!command) {
            int kind = Command::Shutdown;
            MPI_Bcast(&kind, 1, MPI_INT, 0, MPI_COMM_WORLD);
            break;
        }
        if (command->passes.empty()) {
            try {
                const auto [id, stats] = renderFrame(command->overrides, {});
                command->answer.set_value({200, json{{"frame", id}, {"stats", stats}}});
            } catch (const InputError& e) {
                command->answer.set_value({400, json{{"error", e.what()}}});
            }
            continue;
        }
        // Progressive: the passes coarsest first, each a frame of the same view at 1/s of
        // the width and height. A newer request, a client that left or the end of the
        // service cancels the passes still to come and the one under way, on every rank;
        // the first (coarse, cheap) pass is always delivered, so a client gets a picture
        // even when requests keep arriving.
        const std::function<bool()> superseded = [&queue, command] {
            return queue.Waiting() || command->abandoned.load() || gStop.load();
        };
        bool cancelled = false;
        int lastId = 0;
        const int n = static_cast<int>(command->passes.size());
        for (int k = 0; k < n && !cancelled; ++k) {
            if (k > 0 && superseded()) {
                cancelled = true;
                break;
            }
            const int s = command->passes[k];
            std::vector<std::string> overrides = command->overrides;
            const int w = (command->width + s - 1) / s, h = (command->height + s - 1) / s;
            if (s > 1) {
                overrides.push_back("camera.width=" + std::to_string(w));
                overrides.push_back("camera.height=" + std::to_string(h));
            }
            try {
                const auto [id, stats] =
                    renderFrame(overrides, k > 0 ? superseded : std::function<bool()>());
                if (id == 0) {
                    cancelled = true;
                    break;
                }
                lastId = id;
                command->events.Push("pass", json{{"frame", id},
                                                  {"pass", k},
                                                  {"passes", n},
                                                  {"scale", s},
                                                  {"final", k + 1 == n},
                                                  {"width", w},
                                                  {"height", h},
                                                  {"stats", stats}});
            } catch (const InputError& e) {
                command->events.Push("error", json{{"error", e.what()}});
                break;
            }
        }
        command->events.Push("end", json{{"cancelled", cancelled}, {"frame", lastId}});
        command->events.Close();
    }
    server.stop();
    http.join();
    for (auto& [id, done] : written) done.wait();
    std::error_code ec;
    fs::remove_all(frames, ec);
    return 0;
}

}  // namespace hpray::app
