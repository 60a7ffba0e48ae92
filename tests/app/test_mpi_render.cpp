// hpray render on 1..5 MPI ranks, on a mesh and on a partition directory: the image must
// equal the single-rank, unpartitioned image to 1e-6 per channel,
// for cameras outside the data, inside it and looking along split planes.
#include <gtest/gtest.h>

#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>
#include <thread>
#include <sys/wait.h>
#include <unistd.h>

#include <fstream>
#include <nlohmann/json.hpp>

#include "app/process_util.h"
#include "io/image.h"

namespace hpray {
namespace {

// One folder per test process: ctest runs the tests of this binary in parallel processes.
const std::filesystem::path kDir = std::filesystem::temp_directory_path() /
                                   ("hpray_test_mpi_render_" + std::to_string(getpid()));

using test::Mpirun;
using test::MpiSessionOption;
using test::RunCommand;

struct Camera {
    const char* name;
    const char* settings;
};

const Camera kCameras[] = {
    {"outside", "--set camera.position=[2.6,1.8,3.4] --set camera.look_at=[0,0,0]"},
    {"inside", "--set camera.position=[0.1,-0.2,0.3] --set camera.look_at=[1,1,1] "
               "--set camera.fov_y=90"},
    // Along the x = 0 and y = 0 planes, where k-d splits of the symmetric ball lie.
    {"along_split", "--set camera.position=[0,0,3.5] --set camera.look_at=[0,0,0]"},
    {"ortho", "--set camera.position=[3,0.5,0.2] --set camera.look_at=[0,0,0] "
              "--set camera.fov_y=null --set camera.ortho_height=2.4"},
};

/// `extra`: further --set options (e.g. the distribution of the job).
std::vector<double> Render(const std::string& launcher, const std::string& mesh,
                           const Camera& camera, const std::string& tag,
                           const std::string& extra = "") {
    const std::string rgba = (kDir / (tag + ".rgba.npy")).string();
    const std::string hits = (kDir / (tag + ".hits.npy")).string();
    const std::string cmd = launcher + HPRAY_BINARY + " render " +
                            std::string(HPRAY_SOURCE_DIR) + "/configs/ball_p2.yaml -q" +
                            " --set data.mesh=" + mesh + " " + camera.settings +
                            " --set camera.width=40 --set camera.height=36" +
                            " --set output.exr=null --set output.png=null" +
                            " --set output.stats=" + (kDir / (tag + ".json")).string() +
                            " --set output.rgba=" + rgba + " --set output.hits=" + hits +
                            " " + extra;
    std::string out;
    EXPECT_EQ(RunCommand(cmd, &out), 0) << cmd << "\n" << out;
    std::vector<std::size_t> shape;
    std::vector<double> a = ReadNpy(rgba, shape);
    std::vector<double> h = ReadNpy(hits, shape);
    a.insert(a.end(), h.begin(), h.end());
    return a;
}

void ExpectSame(const std::vector<double>& ref, const std::vector<double>& got,
                const std::string& what) {
    ASSERT_EQ(ref.size(), got.size()) << what;
    double worst = 0;
    for (std::size_t i = 0; i < ref.size(); ++i) {
        if (std::isnan(ref[i]) || std::isnan(got[i])) {
            EXPECT_EQ(std::isnan(ref[i]), std::isnan(got[i])) << what << " entry " << i;
            continue;
        }
        if (std::isinf(ref[i]) || std::isinf(got[i])) {
            EXPECT_EQ(ref[i], got[i]) << what << " entry " << i;
            continue;
        }
        worst = std::max(worst, std::abs(ref[i] - got[i]));
    }
    EXPECT_LE(worst, 1e-6) << what;
}

/// Bit for bit equal (NaN equal to NaN): an image split renders every pixel exactly as one
/// rank does.
void ExpectIdentical(const std::vector<double>& ref, const std::vector<double>& got,
                     const std::string& what) {
    ASSERT_EQ(ref.size(), got.size()) << what;
    std::size_t differing = 0, first = ref.size();
    for (std::size_t i = 0; i < ref.size(); ++i) {
        const bool same = std::isnan(ref[i]) ? std::isnan(got[i]) : ref[i] == got[i];
        if (!same && differing++ == 0) first = i;
    }
    EXPECT_EQ(differing, 0u) << what << ": first at entry " << first;
}

/// A number of a stats file: the value after the first "key": (a flat search, enough for
/// the keys the tests read).
double StatsNumber(const std::filesystem::path& file, const std::string& key) {
    std::FILE* f = std::fopen(file.c_str(), "r");
    EXPECT_NE(f, nullptr) << file;
    if (!f) return -1;
    std::array<char, 1 << 16> buf{};
    const std::size_t n = std::fread(buf.data(), 1, buf.size() - 1, f);
    std::fclose(f);
    const std::string json(buf.data(), n);
    const auto at = json.find("\"" + key + "\": ");
    EXPECT_NE(at, std::string::npos) << key;
    return at == std::string::npos ? -1 : std::stod(json.substr(at + key.size() + 4));
}

class MpiRender : public ::testing::Test {
protected:
    static void TearDownTestSuite() { std::filesystem::remove_all(kDir); }
    static void SetUpTestSuite() {
        std::filesystem::remove_all(kDir);
        std::filesystem::create_directories(kDir);
        std::string out;
        const std::string cmd = std::string(HPRAY_BINARY) + " partition builtin:ball-p2 --bricks 6 --out " +
                                (kDir / "part6").string();
        ASSERT_EQ(RunCommand(cmd, &out), 0) << out;
    }
};

TEST_F(MpiRender, AnyRankCountGivesTheSingleRankImage) {
    for (const Camera& camera : kCameras) {
        const auto reference = Render("", "builtin:ball-p2", camera, std::string("ref_") + camera.name);
        // A mesh given directly: split in space (k-d boxes, binary swap in visibility
        // order) or split in image tiles (the default), which must give the same bits.
        for (int ranks : {2, 3}) {
            const std::string tag = std::string(camera.name) + "_np" + std::to_string(ranks);
            ExpectSame(reference,
                       Render(Mpirun(ranks), "builtin:ball-p2", camera, "mesh_" + tag,
                              "--set distribute=space"),
                       "mesh " + tag);
            ExpectIdentical(reference,
                            Render(Mpirun(ranks), "builtin:ball-p2", camera, "image_" + tag),
                            "image split " + tag);
        }
        // A partition on one rank (bricks loaded one at a time) and on 2, 4 and 5 ranks
        // (5 ranks own 6 bricks: one rank holds a subtree of two).
        for (int ranks : {1, 2, 4, 5}) {
            const std::string tag = std::string(camera.name) + "_np" + std::to_string(ranks);
            ExpectSame(reference,
                       Render(Mpirun(ranks), (kDir / "part6").string(), camera, "part_" + tag),
                       "partition " + tag);
        }
    }
}

TEST_F(MpiRender, TooFewBricksIsAClearError) {
    std::string out;
    const int code = RunCommand(Mpirun(2) + HPRAY_BINARY + " render " + std::string(HPRAY_SOURCE_DIR) +
                             "/configs/ball_p2.yaml --set data.mesh=builtin:cube-tets-1" +
                             " --set distribute=space --set output.exr=null --set output.png=null --set output.stats=null"
                             " --set output.hits=null --set camera.width=8 --set camera.height=8",
                         &out);
    // One cell is split into two boxes without trouble; fewer bricks than ranks only
    // arises for partitions: a 6-brick partition on 7 ranks.
    EXPECT_EQ(code, 0) << out;
    const int bad = RunCommand(Mpirun(7) + HPRAY_BINARY + " render " + std::string(HPRAY_SOURCE_DIR) +
                            "/configs/ball_p2.yaml --set data.mesh=" + (kDir / "part6").string() +
                            " --set output.exr=null --set output.png=null --set output.stats=null"
                            " --set output.hits=null --set camera.width=8 --set camera.height=8",
                        &out);
    EXPECT_NE(bad, 0);
    EXPECT_NE(out.find("fewer than the 7 MPI ranks"), std::string::npos) << out;
}

// More threads than the cores a rank is bound to only share those cores: the job says
// so (mpirun binds each of up to 2 ranks to one core unless told otherwise).
TEST_F(MpiRender, ThreadsBeyondTheBoundCoresAreReported) {
    const std::string render = std::string(HPRAY_BINARY) + " render " +
                               std::string(HPRAY_SOURCE_DIR) +
                               "/configs/ball_p2.yaml --set threads=2 --set output.exr=null"
                               " --set output.png=null --set output.stats=null"
                               " --set camera.width=8 --set camera.height=8";
    const std::string warning = "threads is 2 but this process may run on 1 core";
    std::string out;
    ASSERT_EQ(RunCommand(std::string(HPRAY_MPIEXEC) +
                             " -n 1 --allow-run-as-root --bind-to core" +
                             MpiSessionOption() + render,
                         &out),
              0)
        << out;
    EXPECT_NE(out.find(warning), std::string::npos) << out;
    if (std::thread::hardware_concurrency() >= 2) {
        ASSERT_EQ(RunCommand(Mpirun(1) + render, &out), 0) << out;  // --bind-to none
        EXPECT_EQ(out.find("threads is 2 but"), std::string::npos) << out;
    }
}

TEST_F(MpiRender, ImageSplitOfAPartitionIsAClearError) {
    std::string out;
    const int code = RunCommand(Mpirun(2) + HPRAY_BINARY + " render " + std::string(HPRAY_SOURCE_DIR) +
                             "/configs/ball_p2.yaml --set data.mesh=" + (kDir / "part6").string() +
                             " --set distribute=image --set output.exr=null --set output.png=null"
                             " --set output.stats=null --set output.hits=null"
                             " --set camera.width=8 --set camera.height=8",
                         &out);
    EXPECT_EQ(code, 2) << out;
    EXPECT_NE(out.find("part6: is a partition directory, but distribute: image"),
              std::string::npos)
        << out;
}

TEST_F(MpiRender, CorruptBrickEndsTheJobWithAClearMessage) {
    const auto part = kDir / "part6_corrupt";
    std::filesystem::remove_all(part);
    std::filesystem::copy(kDir / "part6", part, std::filesystem::copy_options::recursive);
    // Flip bytes in the middle of one brick file.
    for (const auto& e : std::filesystem::directory_iterator(part))
        if (e.path().extension() == ".vtu") {
            std::FILE* f = std::fopen(e.path().c_str(), "r+b");
            ASSERT_NE(f, nullptr);
            std::fseek(f, static_cast<long>(std::filesystem::file_size(e.path()) / 2), SEEK_SET);
            std::fputs("garbage", f);
            std::fclose(f);
            break;
        }
    std::string out;
    const auto start = std::chrono::steady_clock::now();
    const int code = RunCommand(Mpirun(3) + HPRAY_BINARY + " render " + std::string(HPRAY_SOURCE_DIR) +
                             "/configs/ball_p2.yaml --set data.mesh=" + part.string() +
                             " --set output.exr=null --set output.png=null --set output.stats=" +
                             (kDir / "corrupt.json").string() +
                             " --set output.hits=null --set camera.width=8 --set camera.height=8",
                         &out);
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    EXPECT_NE(code, 0);
    EXPECT_LT(seconds, 10.0);
    EXPECT_NE(out.find("brick-"), std::string::npos) << out;
    EXPECT_FALSE(std::filesystem::exists(kDir / "corrupt.json"));  // no stats of a failed job
}

}  // namespace
}  // namespace hpray

namespace hpray {
namespace {

// Bricks outside the view or the clip box, or whose field ranges hold no isovalue, are not
// read: fewer bricks loaded, the same image.
TEST_F(MpiRender, BricksThatCannotContributeAreNotRead) {
    const Camera corner{"corner", "--set camera.position=[0,0,3.5] --set camera.look_at=[0.6,0.6,0] "
                                  "--set camera.fov_y=20"};
    const auto reference = Render("", "builtin:ball-p2", corner, "ref_corner");
    const auto got = Render("", (kDir / "part6").string(), corner, "part_corner");
    ExpectSame(reference, got, "corner view");
    EXPECT_LT(StatsNumber(kDir / "part_corner.json", "bricks_loaded"), 6);
}

}  // namespace
}  // namespace hpray

namespace hpray {
namespace {

// A rank renders its bricks front to back; where the bricks in front are already opaque
// (the inner sphere), the bricks behind are not traced: the same image, and exactly the
// single-brick render's isosurface hits (hidden hits behind the opaque sphere used to be
// found and counted).
TEST_F(MpiRender, OccludedPixelsOfBackBricksAreNotTraced) {
    const Camera& camera = kCameras[0];
    const auto reference = Render("", "builtin:ball-p2", camera, "occl_ref");
    const auto got = Render("", (kDir / "part6").string(), camera, "occl_part");
    ExpectSame(reference, got, "occlusion");
    const double hits = StatsNumber(kDir / "occl_ref.json", "hits");
    EXPECT_GT(hits, 500);
    EXPECT_EQ(StatsNumber(kDir / "occl_part.json", "hits"), hits);
}

// A volume with embedded semi-transparent isosurfaces and a clip box: the integral is
// split at brick boxes and composited across ranks; up to 8 ranks (oversubscribed).
TEST_F(MpiRender, VolumeWithIsosurfacesOnUpToEightRanks) {
    for (const Camera& camera : {kCameras[0], kCameras[1]}) {
        auto render = [&](const std::string& launcher, const std::string& tag,
                          const std::string& extra = "") {
            const std::string rgba = (kDir / (tag + ".rgba.npy")).string();
            const std::string cmd = launcher + HPRAY_BINARY + " render " +
                                    std::string(HPRAY_SOURCE_DIR) +
                                    "/configs/volume_ball_p2_iso.yaml -q " + camera.settings +
                                    " " + extra +
                                    " --set camera.width=32 --set camera.height=32" +
                                    " --set output.exr=null --set output.png=null" +
                                    " --set output.stats=null --set output.rgba=" + rgba;
            std::string out;
            EXPECT_EQ(RunCommand(cmd, &out), 0) << cmd << "\n" << out;
            std::vector<std::size_t> shape;
            return ReadNpy(rgba, shape);
        };
        const auto reference = render("", std::string("vol_ref_") + camera.name);
        for (int ranks : {2, 3, 8}) {
            const std::string tag = std::string("vol_") + camera.name + "_np" + std::to_string(ranks);
            ExpectSame(reference, render(Mpirun(ranks), tag, "--set distribute=space"), tag);
        }
        const std::string tag = std::string("vol_image_") + camera.name;
        ExpectIdentical(reference, render(Mpirun(3), tag), tag);
    }
}

}  // namespace
}  // namespace hpray

namespace hpray {
namespace {

std::string Vector(const std::array<double, 3>& v) {
    char text[128];
    std::snprintf(text, sizeof text, "[%.17g,%.17g,%.17g]", v[0], v[1], v[2]);
    return text;
}

/// Camera settings for --set: an orthographic view along -axis `view` whose centre
/// column and row (odd image size: sx = sy = 0 exactly) lie in the planes
/// x[(view+1)%3] = at[(view+1)%3] and x[(view+2)%3] = at[(view+2)%3].
std::string OrthoThrough(const std::array<double, 3>& at, int view) {
    std::array<double, 3> position = at, lookAt = at, up{0, 0, 0};
    position[view] = 3;
    lookAt[view] = 2;
    up[(view + 2) % 3] = 1;
    return "--set camera.position=" + Vector(position) + " --set camera.look_at=" +
           Vector(lookAt) + " --set camera.up=" + Vector(up) +
           " --set camera.fov_y=null --set camera.ortho_height=2.8";
}

// Rays lying exactly in the split planes of a partition, along the edge where two planes
// meet, and from an eye on a split plane: a partition on 1, 2, 3 and 5 ranks gives the
// image of the unpartitioned mesh (a ray in a plane shared by two brick boxes used to be
// integrated by both: alpha 0.918 instead of 0.713 on one pixel column).
TEST_F(MpiRender, RaysInSplitPlanesOnOneToFiveRanks) {
    const std::string mesh = std::string(HPRAY_SHARED_DATA) + "/mfem_fichera_mixed16_linear.vtu";
    const auto part = kDir / "fichera7";
    std::string out;
    ASSERT_EQ(RunCommand(std::string(HPRAY_BINARY) + " partition " + mesh +
                             " --bricks 7 --out " + part.string(),
                         &out),
              0)
        << out;
    std::ifstream manifest(part / "manifest.json");
    const nlohmann::json m = nlohmann::json::parse(manifest);
    const nlohmann::json& root = m["tree"];
    const int a = root["axis"].get<int>();
    const double s = root["split"].get<double>();
    // A split of the root's low child along another axis, if there is one: the centre
    // ray then runs along the edge where the two planes meet.
    std::array<double, 3> at{0.1, 0.2, 0.3};
    at[a] = s;
    for (const char* child : {"low", "high"}) {
        const nlohmann::json& c = root[child];
        if (c.contains("axis") && c["axis"].get<int>() != a)
            at[c["axis"].get<int>()] = c["split"].get<double>();
    }
    std::vector<Camera> cameras;
    std::vector<std::string> settings;
    for (int view = 0; view < 3; ++view)
        if (view != a) settings.push_back(OrthoThrough(at, view));
    std::array<double, 3> eye{0.35, 0.45, 0.55}, target{0.05, 0.1, 0.15};
    eye[(a + 2) % 3] = 3.5;
    eye[a] = target[a] = s;
    settings.push_back("--set camera.position=" + Vector(eye) + " --set camera.look_at=" +
                       Vector(target) + " --set camera.fov_y=40");
    for (std::size_t k = 0; k < settings.size(); ++k) {
        const std::string name = "seam" + std::to_string(k);
        auto render = [&](const std::string& launcher, const std::string& data,
                          const std::string& tag) {
            const std::string rgba = (kDir / (tag + ".rgba.npy")).string();
            const std::string hits = (kDir / (tag + ".hits.npy")).string();
            const std::string cmd =
                launcher + HPRAY_BINARY + " render " + std::string(HPRAY_SOURCE_DIR) +
                "/configs/volume_fichera_mixed.yaml -q --set data.mesh=" + data + " " +
                settings[k] +
                " --set camera.width=15 --set camera.height=15 --set output.exr=null"
                " --set output.png=null --set output.stats=null --set output.rgba=" +
                rgba + " --set output.hits=" + hits;
            std::string log;
            EXPECT_EQ(RunCommand(cmd, &log), 0) << cmd << "\n" << log;
            std::vector<std::size_t> shape;
            std::vector<double> v = ReadNpy(rgba, shape);
            const std::vector<double> h = ReadNpy(hits, shape);
            v.insert(v.end(), h.begin(), h.end());
            return v;
        };
        const auto reference = render("", mesh, name + "_ref");
        double alpha = 0;
        for (std::size_t i = 3; i < 4 * 15 * 15; i += 4) alpha += reference[i];
        EXPECT_GT(alpha, 1.0) << settings[k];
        for (int ranks : {1, 2, 3, 5}) {
            const std::string tag = name + "_np" + std::to_string(ranks);
            ExpectSame(reference, render(Mpirun(ranks), part.string(), tag),
                       "partition " + tag + ": " + settings[k]);
        }
    }
}

}  // namespace
}  // namespace hpray
