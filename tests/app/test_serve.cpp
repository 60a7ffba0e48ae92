// hpray serve on 2 ranks (oversubscribed), on a builtin and on a partition directory:
// frames for several cameras, isovalues and transfer functions equal `hpray render` of
// the merged scene to 1e-6; the token, bad requests (400, 413), evicted frames (404)
// and the service answering after each; a clean exit on /api/shutdown. Progressive
// requests: each pass is the frame `hpray render` makes at its size; a newer request or a
// client that leaves cancels the pass under way on every rank.
#include <gtest/gtest.h>
#include <httplib.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <csignal>
#include <cstdlib>
#include <filesystem>
#include <future>
#include <thread>
#include <fstream>
#include <functional>
#include <iterator>
#include <optional>
#include <sstream>
#include <nlohmann/json.hpp>
#include <string>
#include <sys/wait.h>
#include <unistd.h>

#include "app/process_util.h"
#include "io/image.h"

namespace hpray {
namespace {

using nlohmann::json;
const std::filesystem::path kDir = std::filesystem::temp_directory_path() /
                                   ("hpray_test_serve_" + std::to_string(getpid()));
const std::string kToken = "test-token-123";
const std::string kFixed = " --set camera.width=40 --set camera.height=36";

using test::Mpirun;
using test::RunCommand;

/// A running service: started by the constructor, its port read from its first line.
class Service {
  public:
    explicit Service(const std::string& mesh) {
        const std::string cmd = Mpirun(2) + HPRAY_BINARY + " serve " +
                                std::string(HPRAY_SOURCE_DIR) + "/configs/ball_p2.yaml" +
                                " --port 0 --token " + kToken + " --set data.mesh=" + mesh +
                                kFixed;
        pipe_ = popen(cmd.c_str(), "r");
        char line[512] = {0};
        if (pipe_ && std::fgets(line, sizeof line, pipe_)) {
            const std::string text = line;
            const auto at = text.find("127.0.0.1:");
            if (text.rfind("hpray serve: listening on http://", 0) == 0 &&
                at != std::string::npos)
                port_ = std::stoi(text.substr(at + 10));
            token_ = text.substr(text.find(" token ") + 7);
            while (!token_.empty() && token_.back() == '\n') token_.pop_back();
        }
    }
    ~Service() {
        if (pipe_) pclose(pipe_);
    }
    int Port() const { return port_; }
    const std::string& Token() const { return token_; }
    /// Waits for the service to end; its exit code.
    int Close() {
        const int status = pclose(pipe_);
        pipe_ = nullptr;
        return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    }

  private:
    FILE* pipe_ = nullptr;
    int port_ = -1;
    std::string token_;
};

httplib::Headers Auth() { return {{"Authorization", "Bearer " + kToken}}; }

/// The `--set` items of a JSON body (objects recurse, other values as JSON text).
void Flatten(const json& j, const std::string& path, std::string& out) {
    if (j.is_object()) {
        for (const auto& [k, v] : j.items()) Flatten(v, path.empty() ? k : path + "." + k, out);
        return;
    }
    out += " --set '" + path + "=" + j.dump() + "'";
}

std::vector<double> ReadBoth(const std::string& rgba, const std::string& hits) {
    std::vector<std::size_t> shape;
    std::vector<double> a = ReadNpy(rgba, shape);
    const std::vector<double> h = ReadNpy(hits, shape);
    a.insert(a.end(), h.begin(), h.end());
    return a;
}

double WorstDifference(const std::vector<double>& a, const std::vector<double>& b) {
    if (a.size() != b.size()) return INFINITY;
    double worst = 0;
    for (std::size_t i = 0; i < a.size(); ++i) {
        if (std::isnan(a[i]) || std::isnan(b[i]) || std::isinf(a[i]) || std::isinf(b[i])) {
            if (!(std::isnan(a[i]) ? std::isnan(b[i]) : a[i] == b[i])) return INFINITY;
            continue;
        }
        worst = std::max(worst, std::abs(a[i] - b[i]));
    }
    return worst;
}

void Exercise(const std::string& mesh, const std::string& tag) {
    Service service(mesh);
    ASSERT_GT(service.Port(), 0) << "no start-up line";
    EXPECT_EQ(service.Token(), kToken);
    httplib::Client client("127.0.0.1", service.Port());
    client.set_read_timeout(120, 0);
    auto alive = [&] {
        auto r = client.Get("/api/info", Auth());
        ASSERT_TRUE(r);
        EXPECT_EQ(r->status, 200);
    };
    // The token.
    auto noToken = client.Get("/api/info");
    ASSERT_TRUE(noToken);
    EXPECT_EQ(noToken->status, 401);
    auto withParam = client.Get(("/api/info?token=" + kToken).c_str());
    ASSERT_TRUE(withParam);
    EXPECT_EQ(withParam->status, 200);
    const json info = json::parse(withParam->body);
    EXPECT_EQ(info["data"]["fields"].contains("u"), true);
    // The scene as loaded: the file with the command line's --set items applied.
    EXPECT_EQ(info["scene"]["camera"]["width"], 40);
    EXPECT_EQ(info["scene"]["camera"]["height"], 36);
    EXPECT_EQ(info["scene"]["data"]["mesh"], mesh);

    // Frames against hpray render of the merged scene.
    const std::vector<json> bodies = {
        json::object(),
        {{"camera", {{"position", {0.1, -0.2, 0.3}}, {"look_at", {1, 1, 1}}, {"fov_y", 90}}}},
        {{"isosurfaces", {{{"field", "u"}, {"value", 0.5}, {"opacity", 0.6}}}}},
        {{"camera", {{"position", {3, 0.5, 0.2}}, {"fov_y", nullptr}, {"ortho_height", 2.4}}},
         {"volume",
          {{"color_field", "u"},
           {"color_tf", {{0, 0.1, 0.2, 0.9}, {3, 1, 0.4, 0.1}}},
           {"extinction_tf", {{0, 0.5}, {3, 2.0}}}}}},
        {{"camera", {{"position", {2, 2, 2}}}}},
    };
    for (std::size_t k = 0; k < bodies.size(); ++k) {
        auto r = client.Post("/api/render", Auth(), bodies[k].dump(), "application/json");
        ASSERT_TRUE(r);
        ASSERT_EQ(r->status, 200) << r->body;
        const json answer = json::parse(r->body);
        const int frame = answer["frame"].get<int>();
        EXPECT_TRUE(answer["stats"].contains("timing_s"));
        const std::string base = (kDir / (tag + std::to_string(k))).string();
        for (const char* name : {"rgba.npy", "hits.npy"}) {
            auto f = client.Get(("/api/frames/" + std::to_string(frame) + "/" + name).c_str(),
                                Auth());
            ASSERT_TRUE(f);
            ASSERT_EQ(f->status, 200);
            std::FILE* out = std::fopen((base + "." + name).c_str(), "wb");
            std::fwrite(f->body.data(), 1, f->body.size(), out);
            std::fclose(out);
        }
        std::string sets;
        Flatten(bodies[k], "", sets);
        std::string log;
        const std::string cmd = std::string(HPRAY_BINARY) + " render " +
                                std::string(HPRAY_SOURCE_DIR) + "/configs/ball_p2.yaml -q" +
                                " --set data.mesh=" + mesh + kFixed + sets +
                                " --set output.exr=null --set output.png=null"
                                " --set output.stats=null --set output.rgba=" + base +
                                ".ref_rgba.npy --set output.hits=" + base + ".ref_hits.npy";
        ASSERT_EQ(RunCommand(cmd, &log), 0) << cmd << "\n" << log;
        EXPECT_LE(WorstDifference(ReadBoth(base + ".ref_rgba.npy", base + ".ref_hits.npy"),
                                  ReadBoth(base + ".rgba.npy", base + ".hits.npy")),
                  1e-6)
            << tag << " frame " << k << ": " << bodies[k].dump();
    }

    // Bad requests: 400 with the key named, and the service still answers.
    const std::vector<std::pair<std::string, std::string>> bad = {
        {"{not json", "malformed JSON"},
        {"[1, 2]", "JSON object"},
        {R"({"bogus": 1})", "bogus"},
        {R"({"camera": {"width": "wide"}})", "camera.width"},
        {R"({"data": {"mesh": "builtin:cube-tets-1"}})", "data"},
        {R"({"isosurfaces": [{"field": "nope", "value": 1}]})", "nope"},
    };
    for (const auto& [body, expected] : bad) {
        auto r = client.Post("/api/render", Auth(), body, "application/json");
        ASSERT_TRUE(r);
        EXPECT_EQ(r->status, 400) << body;
        EXPECT_NE(json::parse(r->body)["error"].get<std::string>().find(expected),
                  std::string::npos)
            << body << " -> " << r->body;
        alive();
    }
    auto big = client.Post("/api/render", Auth(), std::string((1 << 20) + 16, ' '),
                           "application/json");
    ASSERT_TRUE(big);
    EXPECT_EQ(big->status, 413);
    alive();
    auto unknown = client.Get("/api/nothing", Auth());
    ASSERT_TRUE(unknown);
    EXPECT_EQ(unknown->status, 404);

    // Old frames are evicted: after 32 more, the first is gone, the last is there.
    int last = 0;
    for (int k = 0; k < 32; ++k) {
        auto r = client.Post("/api/render", Auth(), R"({"camera": {"width": 8, "height": 8}})",
                             "application/json");
        ASSERT_TRUE(r);
        ASSERT_EQ(r->status, 200);
        last = json::parse(r->body)["frame"].get<int>();
    }
    auto evicted = client.Get("/api/frames/1/image.png", Auth());
    ASSERT_TRUE(evicted);
    EXPECT_EQ(evicted->status, 404);
    auto kept = client.Get(("/api/frames/" + std::to_string(last) + "/image.png").c_str(),
                           Auth());
    ASSERT_TRUE(kept);
    EXPECT_EQ(kept->status, 200);
    EXPECT_EQ(kept->body.substr(1, 3), "PNG");

    auto stop = client.Post("/api/shutdown", Auth(), "", "application/json");
    ASSERT_TRUE(stop);
    EXPECT_EQ(stop->status, 200);
    EXPECT_EQ(service.Close(), 0);
}

/// The server-sent events of a progressive request, as (event, data) pairs, collected as
/// they arrive; `onEvent` may end the stream early by returning false (the client leaves).
struct EventStream {
    std::vector<std::pair<std::string, json>> events;
    std::string pending;
    std::function<bool(const std::string&, const json&)> onEvent;

    bool Feed(const char* data, std::size_t size) {
        pending.append(data, size);
        for (std::size_t end; (end = pending.find("\n\n")) != std::string::npos;) {
            const std::string block = pending.substr(0, end);
            pending.erase(0, end + 2);
            std::string event, payload;
            std::istringstream lines(block);
            for (std::string line; std::getline(lines, line);) {
                if (line.rfind("event: ", 0) == 0) event = line.substr(7);
                if (line.rfind("data: ", 0) == 0) payload = line.substr(6);
            }
            if (event.empty()) continue;  // a keep-alive comment
            events.emplace_back(event, json::parse(payload));
            if (onEvent && !onEvent(event, events.back().second)) return false;
        }
        return true;
    }
};

/// The events received, for failure messages.
std::string Dump(const EventStream& stream) {
    std::string out;
    for (const auto& [event, data] : stream.events) out += event + " " + data.dump() + "\n";
    return out + "(pending: " + stream.pending + ")";
}

httplib::Result PostStream(httplib::Client& client, const std::string& path,
                           const std::string& body, EventStream& stream) {
    httplib::Request req;
    req.method = "POST";
    req.path = path;
    req.headers = Auth();
    req.body = body;
    req.set_header("Content-Type", "application/json");
    req.content_receiver = [&](const char* data, std::size_t size, std::uint64_t,
                               std::uint64_t) { return stream.Feed(data, size); };
    return client.send(req);
}

/// The frame's rgba.npy and hits.npy against `hpray render` of `sets` at 1e-6, and its
/// errors.npy (float32) against the render's residuals.
void ExpectFrameEqualsRender(httplib::Client& client, int frame, const std::string& mesh,
                             const std::string& sets, const std::string& base) {
    for (const char* name : {"rgba.npy", "hits.npy", "errors.npy"}) {
        auto f = client.Get(("/api/frames/" + std::to_string(frame) + "/" + name).c_str(),
                            Auth());
        ASSERT_TRUE(f);
        ASSERT_EQ(f->status, 200) << name;
        std::FILE* out = std::fopen((base + "." + name).c_str(), "wb");
        std::fwrite(f->body.data(), 1, f->body.size(), out);
        std::fclose(out);
    }
    std::string log;
    const std::string cmd = std::string(HPRAY_BINARY) + " render " +
                            std::string(HPRAY_SOURCE_DIR) + "/configs/ball_p2.yaml -q" +
                            " --set data.mesh=" + mesh + kFixed + sets +
                            " --set output.exr=null --set output.png=null"
                            " --set output.stats=null --set output.rgba=" + base +
                            ".ref_rgba.npy --set output.hits=" + base + ".ref_hits.npy";
    ASSERT_EQ(RunCommand(cmd, &log), 0) << cmd << "\n" << log;
    EXPECT_LE(WorstDifference(ReadBoth(base + ".ref_rgba.npy", base + ".ref_hits.npy"),
                              ReadBoth(base + ".rgba.npy", base + ".hits.npy")),
              1e-6)
        << sets;
    // errors.npy: (H, W, 2) float32, the residual and the volume error of each pixel.
    std::ifstream in(base + ".errors.npy", std::ios::binary);
    std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    ASSERT_GT(bytes.size(), 10u);
    const std::size_t headerLength =
        10 + static_cast<unsigned char>(bytes[8]) + 256 * static_cast<unsigned char>(bytes[9]);
    const std::string header = bytes.substr(10, headerLength - 10);
    EXPECT_NE(header.find("'<f4'"), std::string::npos) << header;
    std::vector<std::size_t> shape;
    const std::vector<double> hits = ReadNpy(base + ".ref_hits.npy", shape);
    ASSERT_EQ(shape.size(), 3u);
    EXPECT_NE(header.find("(" + std::to_string(shape[0]) + ", " + std::to_string(shape[1]) +
                          ", 2)"),
              std::string::npos)
        << header;
    const std::size_t pixels = shape[0] * shape[1];
    ASSERT_EQ(bytes.size(), headerLength + pixels * 2 * sizeof(float));
    std::vector<float> errors(pixels * 2);
    std::memcpy(errors.data(), bytes.data() + headerLength, errors.size() * sizeof(float));
    for (std::size_t p = 0; p < pixels; ++p) {
        const double residual = hits[5 * p + 4];
        if (std::isnan(residual)) {
            EXPECT_TRUE(std::isnan(errors[2 * p])) << p;
        } else {
            EXPECT_NEAR(errors[2 * p], residual, 1e-6 * std::abs(residual) + 1e-30) << p;
        }
        EXPECT_GE(errors[2 * p + 1], 0.0f);
    }
}

/// Progressive requests on 2 ranks: the passes (a quarter of the width and height, then
/// the full frame) are the frames `hpray render` makes at those sizes; a newer request
/// sent while the last pass of a slow frame renders cancels it on every rank (no final
/// pass, `cancelled` in the end event, the frames that follow still exact); so does a
/// client that leaves.
void ExerciseProgressive(const std::string& mesh, const std::string& tag) {
    Service service(mesh);
    ASSERT_GT(service.Port(), 0) << "no start-up line";
    httplib::Client client("127.0.0.1", service.Port());
    client.set_read_timeout(300, 0);

    const json body = {{"isosurfaces", {{{"field", "u"}, {"value", 0.7}, {"opacity", 0.6}}}},
                       {"volume",
                        {{"color_field", "u"},
                         {"color_tf", {{0, 0.1, 0.2, 0.9}, {3, 1, 0.4, 0.1}}},
                         {"extinction_tf", {{0, 0.5}, {3, 2.0}}}}}};
    std::string sets;
    Flatten(body, "", sets);
    {
        EventStream stream;
        auto r = PostStream(client, "/api/render?progressive=1&passes=4,1", body.dump(), stream);
        ASSERT_TRUE(r);
        ASSERT_EQ(r->status, 200);
        EXPECT_EQ(r->get_header_value("Content-Type"), "text/event-stream");
        ASSERT_EQ(stream.events.size(), 3u) << Dump(stream);
        const json& coarse = stream.events[0].second;
        const json& fine = stream.events[1].second;
        EXPECT_EQ(stream.events[0].first, "pass");
        EXPECT_EQ(coarse["pass"], 0);
        EXPECT_EQ(coarse["passes"], 2);
        EXPECT_EQ(coarse["scale"], 4);
        EXPECT_EQ(coarse["final"], false);
        EXPECT_EQ(coarse["width"], 10);  // 40 / 4
        EXPECT_EQ(coarse["height"], 9);  // 36 / 4
        EXPECT_EQ(coarse["stats"]["image"], json::array({10, 9}));
        EXPECT_EQ(fine["final"], true);
        EXPECT_EQ(fine["width"], 40);
        EXPECT_EQ(stream.events[2].first, "end");
        EXPECT_EQ(stream.events[2].second["cancelled"], false);
        EXPECT_EQ(stream.events[2].second["frame"], fine["frame"]);
        ExpectFrameEqualsRender(client, coarse["frame"].get<int>(), mesh,
                                sets + " --set camera.width=10 --set camera.height=9",
                                (kDir / (tag + "_coarse")).string());
        ExpectFrameEqualsRender(client, fine["frame"].get<int>(), mesh, sets,
                                (kDir / (tag + "_fine")).string());
    }
    // A slow last pass (the volume at 2048^2), superseded by a small frame once the coarse
    // pass has arrived: the slow pass stops on every rank and is never delivered.
    const json slow = {{"camera", {{"width", 2048}, {"height", 2048}}},
                       {"volume", body["volume"]}};
    {
        EventStream stream;
        httplib::Client other("127.0.0.1", service.Port());
        other.set_read_timeout(300, 0);
        std::optional<httplib::Result> newer;
        stream.onEvent = [&](const std::string& event, const json&) {
            if (event == "pass" && !newer)
                newer = other.Post("/api/render", Auth(), R"({"camera": {"position": [2, 2, 2]}})",
                                   "application/json");
            return true;
        };
        auto r = PostStream(client, "/api/render?progressive=1&passes=64,1", slow.dump(), stream);
        ASSERT_TRUE(r);
        ASSERT_TRUE(newer && *newer);
        EXPECT_EQ((*newer)->status, 200);
        ASSERT_EQ(stream.events.size(), 2u) << Dump(stream);
        EXPECT_EQ(stream.events[0].first, "pass");
        EXPECT_EQ(stream.events[0].second["final"], false);
        EXPECT_EQ(stream.events[1].first, "end");
        EXPECT_EQ(stream.events[1].second["cancelled"], true) << Dump(stream);
        // The newer frame took the next id: the cancelled pass kept none.
        EXPECT_EQ(json::parse((*newer)->body)["frame"].get<int>(),
                  stream.events[0].second["frame"].get<int>() + 1);
    }
    // A client that leaves after the coarse pass: the slow pass is cancelled too (the next
    // frame again takes the next id), and the service goes on with exact frames.
    int coarseId = 0;
    {
        EventStream stream;
        stream.onEvent = [&](const std::string& event, const json& data) {
            if (event == "pass") coarseId = data["frame"].get<int>();
            return false;  // leave
        };
        PostStream(client, "/api/render?progressive=1&passes=64,1", slow.dump(), stream);
        ASSERT_EQ(stream.events.size(), 1u) << Dump(stream);
    }
    httplib::Client after("127.0.0.1", service.Port());
    after.set_read_timeout(300, 0);
    auto r = after.Post("/api/render", Auth(), body.dump(), "application/json");
    ASSERT_TRUE(r);
    ASSERT_EQ(r->status, 200) << r->body;
    const int id = json::parse(r->body)["frame"].get<int>();
    EXPECT_EQ(id, coarseId + 1);
    ExpectFrameEqualsRender(after, id, mesh, sets, (kDir / (tag + "_after")).string());
    // Bad passes are a 400.
    auto bad = after.Post("/api/render?progressive=1&passes=1,8", Auth(), "{}",
                          "application/json");
    ASSERT_TRUE(bad);
    EXPECT_EQ(bad->status, 400);
    auto stop = after.Post("/api/shutdown", Auth(), "", "application/json");
    ASSERT_TRUE(stop);
    EXPECT_EQ(service.Close(), 0);
}

class Serve : public ::testing::Test {
  protected:
    static void SetUpTestSuite() {
        std::filesystem::remove_all(kDir);
        std::filesystem::create_directories(kDir);
    }
    static void TearDownTestSuite() { std::filesystem::remove_all(kDir); }
};

TEST_F(Serve, BuiltinFramesEqualRenderAndBadRequestsAreAnswered) {
    Exercise("builtin:ball-p2", "builtin");
}

/// Partitions builtin:ball-p2 into 4 bricks under kDir / `name`; returns the directory.
std::string PartitionBall(const std::string& name) {
    const std::string dir = (kDir / name).string();
    std::string out;
    EXPECT_EQ(RunCommand(std::string(HPRAY_BINARY) +
                             " partition builtin:ball-p2 --bricks 4 --out " + dir,
                         &out),
              0)
        << out;
    return dir;
}

TEST_F(Serve, PartitionFramesEqualRenderAndBadRequestsAreAnswered) {
    Exercise(PartitionBall("part4"), "partition");
}

TEST_F(Serve, ProgressivePassesAreFramesAndNewerRequestsCancelThemOnEveryRank) {
    ExerciseProgressive("builtin:ball-p2", "progressive_builtin");
}

TEST_F(Serve, ProgressiveCancelOnAPartition) {
    ExerciseProgressive(PartitionBall("part4p"), "progressive_partition");
}

// A rank that dies (SIGKILL, as on a node failure) ends the whole job within 10 s with a
// non-zero exit and a message naming the rank (the launcher's own report).
TEST_F(Serve, ADeadRankEndsTheJobWithinTenSecondsNamingIt) {
    const std::string log = (kDir / "dead_rank.log").string();
    // In a session of its own: the launcher ends its whole process group on an abort.
    const std::string cmd = "setsid " + Mpirun(2) + HPRAY_BINARY + " serve " +
                            std::string(HPRAY_SOURCE_DIR) + "/configs/ball_p2.yaml" +
                            " --port 0 --token " + kToken + kFixed + " > " + log + " 2>&1";
    auto status = std::async(std::launch::async, [cmd] { return std::system(cmd.c_str()); });
    int port = -1;
    for (int k = 0; k < 600 && port < 0; ++k) {
        std::ifstream in(log);
        for (std::string line; std::getline(in, line);) {
            const auto at = line.find("http://127.0.0.1:");
            if (line.rfind("hpray serve: listening", 0) == 0 && at != std::string::npos)
                port = std::stoi(line.substr(at + 17));
        }
        if (port < 0) std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    ASSERT_GT(port, 0) << "the service did not start";
    httplib::Client client("127.0.0.1", port);
    auto info = client.Get("/api/info", Auth());
    ASSERT_TRUE(info);
    const json ranks = json::parse(info->body)["ranks"];
    ASSERT_EQ(ranks.size(), 2u);
    const pid_t rank0 = ranks[0]["pid"].get<pid_t>(), rank1 = ranks[1]["pid"].get<pid_t>();
    EXPECT_EQ(ranks[1]["rank"], 1);
    ASSERT_EQ(kill(rank1, SIGKILL), 0);
    const bool ended = status.wait_for(std::chrono::seconds(10)) == std::future_status::ready;
    if (!ended) kill(rank0, SIGKILL);  // never leave a job behind
    EXPECT_TRUE(ended) << "the job still runs 10 s after rank 1 died";
    const int code = status.get();
    EXPECT_NE(code, 0);
    std::ifstream in(log);
    const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    EXPECT_NE(text.find("rank 1"), std::string::npos) << text;
}

}  // namespace
}  // namespace hpray
