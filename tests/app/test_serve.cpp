// hpray serve on 2 ranks (oversubscribed), on a builtin and on a partition directory:
// frames for several cameras, isovalues and transfer functions equal `hpray render` of
// the merged scene to 1e-6; the token, bad requests (400, 413), evicted frames (404)
// and the service answering after each; a clean exit on /api/shutdown.
#include <gtest/gtest.h>
#include <httplib.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
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
    EXPECT_EQ(json::parse(withParam->body)["data"]["fields"].contains("u"), true);

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

    // Old frames are evicted: after 16 more, the first is gone, the last is there.
    int last = 0;
    for (int k = 0; k < 16; ++k) {
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

TEST_F(Serve, PartitionFramesEqualRenderAndBadRequestsAreAnswered) {
    std::string out;
    ASSERT_EQ(RunCommand(std::string(HPRAY_BINARY) + " partition builtin:ball-p2 --bricks 4 --out " +
                             (kDir / "part4").string(),
                         &out),
              0)
        << out;
    Exercise((kDir / "part4").string(), "partition");
}

}  // namespace
}  // namespace hpray
