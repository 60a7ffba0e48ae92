// The hpray executable end to end: exit codes, messages and `info --json` on known data.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <random>
#include <vector>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iterator>
#include <string>
#include <sys/wait.h>

#include "io/image.h"
#include "scene/colormaps.h"

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

TEST(Cli, PartitionWritesAManifest) {  // the partition tests are in tests/partition
    const auto dir = std::filesystem::temp_directory_path() / "hpray_test_cli_partition";
    RunResult r = RunHpray("partition builtin:cube-tets-2 --bricks 2 --out " + dir.string());
    EXPECT_EQ(r.code, 0) << r.out;
    EXPECT_TRUE(std::filesystem::is_regular_file(dir / "manifest.json"));
    std::filesystem::remove_all(dir);
}

TEST(Cli, HelpExitsZero) { EXPECT_EQ(RunHpray("--help").code, 0); }

// Warnings say what went wrong, on a result that is probably not what the user wanted; the
// stats list them; --strict makes them errors (exit 2, no outputs).
TEST(Cli, WarningsForSuspiciousResultsAndStrict) {
    namespace fs = std::filesystem;
    const fs::path dir = fs::temp_directory_path() / "hpray_test_cli_warnings";
    fs::remove_all(dir);
    fs::create_directories(dir);
    const std::string scene = std::string(HPRAY_SOURCE_DIR) + "/configs/ball_p2.yaml";
    const std::string small = " --set camera.width=24 --set camera.height=24 --set "
                              "output.exr=null --set output.hits=null --set output.png=";
    const std::string outside =
        "isosurfaces.0: value 5 is outside the range [0, 3] of field 'u' over the data";
    // An isovalue outside the field's range (u = r^2 on [-1,1]^3 spans [0, 3]).
    RunResult r = RunHpray("render " + scene + " --set isosurfaces.0.value=5" + small +
                           (dir / "a.png").string() + " --set output.stats=" +
                           (dir / "a.json").string());
    EXPECT_EQ(r.code, 0) << r.out;
    EXPECT_NE(r.out.find("warning: " + outside), std::string::npos) << r.out;
    std::ifstream stats(dir / "a.json");
    const nlohmann::json j = nlohmann::json::parse(stats);
    ASSERT_EQ(j["warnings"].size(), 1u) << j["warnings"];
    EXPECT_NE(j["warnings"][0].get<std::string>().find(outside), std::string::npos);
    // The same with --strict: exit 2 naming the cause, and no output.
    r = RunHpray("render " + scene + " --strict --set isosurfaces.0.value=5" + small +
                 (dir / "b.png").string() + " --set output.stats=" + (dir / "b.json").string());
    EXPECT_EQ(r.code, 2) << r.out;
    EXPECT_NE(r.out.find("--strict: " + outside), std::string::npos) << r.out;
    EXPECT_FALSE(fs::exists(dir / "b.png"));
    EXPECT_FALSE(fs::exists(dir / "b.json"));
    // A camera that looks away from the data: an empty image.
    r = RunHpray("render " + scene + " --set camera.look_at=[9,9,9]" + small +
                 (dir / "c.png").string() + " --set output.stats=null");
    EXPECT_EQ(r.code, 0) << r.out;
    EXPECT_NE(r.out.find("warning: the image is empty"), std::string::npos) << r.out;
    // A good scene: no warning, --strict passes.
    r = RunHpray("render " + scene + " --strict" + small + (dir / "d.png").string() +
                 " --set output.stats=null");
    EXPECT_EQ(r.code, 0) << r.out;
    EXPECT_EQ(r.out.find("warning"), std::string::npos) << r.out;
    fs::remove_all(dir);
}

// A scene without a camera position is fitted to the data: the picture shows the data,
// the stats give the camera it used, and rendering with that camera written out gives the
// same image (what a user copies into a scene to keep the view).
TEST(Cli, AutomaticCameraIsReportedAndReusable) {
    namespace fs = std::filesystem;
    const fs::path dir = fs::temp_directory_path() / "hpray_test_cli_auto_camera";
    fs::remove_all(dir);
    fs::create_directories(dir);
    const fs::path scene = dir / "auto.yaml";
    {
        std::ofstream out(scene);
        out << "data: {mesh: builtin:ball-p2}\n"
               "camera: {width: 40, height: 32, view: -z, azimuth: 20, elevation: 15}\n"
               "isosurfaces: [{field: u, value: 0.5}]\n";
    }
    const std::string common = " --set output.exr=null --set output.png=null";
    RunResult r = RunHpray("render " + scene.string() + common + " --set output.stats=" +
                           (dir / "a.json").string() + " --set output.rgba=" +
                           (dir / "a.npy").string());
    ASSERT_EQ(r.code, 0) << r.out;
    std::ifstream in(dir / "a.json");
    const nlohmann::json cam = nlohmann::json::parse(in)["camera"];
    ASSERT_TRUE(cam.contains("position")) << cam;
    // -z side: the eye is below z = -1 (the ball's box is [-1, 1]^3), looking at 0.
    EXPECT_LT(cam["position"][2].get<double>(), -1.0) << cam;
    for (int d = 0; d < 3; ++d) EXPECT_NEAR(cam["look_at"][d].get<double>(), 0.0, 1e-12);
    auto vec = [](const nlohmann::json& v) {
        return "[" + v[0].dump() + "," + v[1].dump() + "," + v[2].dump() + "]";
    };
    r = RunHpray("render " + scene.string() + common + " --set output.stats=null" +
                 " --set camera.view=null --set camera.azimuth=null --set camera.elevation=null" +
                 " --set camera.position=" + vec(cam["position"]) +
                 " --set camera.look_at=" + vec(cam["look_at"]) + " --set camera.up=" +
                 vec(cam["up"]) + " --set camera.fov_y=" + cam["fov_y"].dump() +
                 " --set output.rgba=" + (dir / "b.npy").string());
    ASSERT_EQ(r.code, 0) << r.out;
    std::vector<std::size_t> shape;
    const std::vector<double> a = hpray::ReadNpy((dir / "a.npy").string(), shape);
    const std::vector<double> b = hpray::ReadNpy((dir / "b.npy").string(), shape);
    ASSERT_EQ(a.size(), b.size());
    double worst = 0, alpha = 0;
    for (std::size_t i = 0; i < a.size(); ++i) worst = std::max(worst, std::abs(a[i] - b[i]));
    for (std::size_t i = 3; i < a.size(); i += 4) alpha = std::max(alpha, a[i]);
    EXPECT_LE(worst, 1e-9);  // the JSON's decimal camera, read back
    EXPECT_EQ(alpha, 1.0);   // the sphere is in the picture
    fs::remove_all(dir);
}

// A slice coloured by a named map over the field's range found in the data: through the
// centre of the ball (u = |x|^2 = 0 there, the bottom of u's range [0, 3]) the pixel is
// the map's first colour, in linear RGB.
TEST(Cli, NamedColorMapWithAutomaticRange) {
    namespace fs = std::filesystem;
    const fs::path dir = fs::temp_directory_path() / "hpray_test_cli_colormap";
    fs::remove_all(dir);
    fs::create_directories(dir);
    const fs::path scene = dir / "slice.yaml";
    {
        std::ofstream out(scene);
        out << "data: {mesh: builtin:ball-p2}\n"
               "camera: {position: [0, 0, 5], look_at: [0, 0, 0], up: [0, 1, 0], "
               "ortho_height: 2.5, width: 9, height: 9}\n"
               "slices: [{point: [0, 0, 0], normal: [0, 0, 1], field: u, opacity: 1, "
               "color_tf: {map: viridis, range: auto}}]\n";
    }
    RunResult r = RunHpray("render " + scene.string() +
                           " --set output.exr=null --set output.png=null --set output.stats=null"
                           " --set output.rgba=" + (dir / "a.npy").string());
    ASSERT_EQ(r.code, 0) << r.out;
    std::vector<std::size_t> shape;
    const std::vector<double> a = hpray::ReadNpy((dir / "a.npy").string(), shape);
    ASSERT_EQ(a.size(), 9u * 9u * 4u);
    const std::size_t centre = 4 * (4 * 9 + 4);
    const auto viridis = hpray::ExpandColorMap("viridis", 0.0, 3.0);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(a[centre + c], viridis[0].rgb[c], 1e-9) << c;
    EXPECT_EQ(a[centre + 3], 1.0);
    fs::remove_all(dir);
}

// The outline and the legend go into the PNG only: the EXR and the arrays are the same
// bytes as without them. A bad annotation key exits 2 naming it; a legend with nothing
// to show is a warning.
TEST(Cli, AnnotationsGoIntoThePngOnly) {
    namespace fs = std::filesystem;
    const fs::path dir = fs::temp_directory_path() / "hpray_test_cli_annotations";
    fs::remove_all(dir);
    fs::create_directories(dir);
    const std::string scene = std::string(HPRAY_SOURCE_DIR) + "/configs/ball_p2.yaml";
    auto render = [&](const std::string& name, const std::string& extra) {
        return RunHpray("render " + scene + " --set camera.width=96 --set camera.height=80" +
                        " --set output.stats=null --set output.hits=null" +
                        " --set output.exr=" + (dir / (name + ".exr")).string() +
                        " --set output.png=" + (dir / (name + ".png")).string() +
                        " --set output.rgba=" + (dir / (name + ".npy")).string() + extra);
    };
    auto bytes = [&](const std::string& file) {
        std::ifstream in(dir / file, std::ios::binary);
        return std::string(std::istreambuf_iterator<char>(in), {});
    };
    RunResult r = render("plain", "");
    ASSERT_EQ(r.code, 0) << r.out;
    r = render("marked", " --set outline=true --set slices.0.point=[0,0,0]"
                         " --set slices.0.normal=[0,0,1]"
                         " --set 'slices.0.color_tf={map: viridis}' --set legend=true");
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_EQ(r.out.find("warning"), std::string::npos) << r.out;
    r = render("outlined", " --set outline.color=[0,0,0]");
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_EQ(bytes("plain.npy"), bytes("outlined.npy"));
    EXPECT_EQ(bytes("plain.exr"), bytes("outlined.exr"));
    EXPECT_NE(bytes("plain.png"), bytes("outlined.png"));
    EXPECT_NE(bytes("plain.png"), bytes("marked.png"));

    r = RunHpray("render " + scene + " --set outline.widht=2");
    EXPECT_EQ(r.code, 2) << r.out;
    EXPECT_NE(r.out.find("outline.widht"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("did you mean 'width'"), std::string::npos) << r.out;
    r = RunHpray("render " + scene + " --set legend=maybe");
    EXPECT_EQ(r.code, 2) << r.out;
    EXPECT_NE(r.out.find("legend"), std::string::npos) << r.out;
    r = render("empty", " --set legend=true --strict");
    EXPECT_EQ(r.code, 2) << r.out;
    EXPECT_NE(r.out.find("there is no legend to draw"), std::string::npos) << r.out;
    fs::remove_all(dir);
}

// A bare vector field name is its magnitude: a warning says so and how to choose; naming
// the magnitude explicitly keeps quiet.
TEST(Cli, VectorFieldUsedAsItsMagnitudeIsAWarning) {
    namespace fs = std::filesystem;
    const std::string mesh = std::string(HPRAY_SOURCE_DIR) +
                             "/../shared/data/dealii_step44_hex_q2.vtu";
    if (!fs::exists(mesh)) GTEST_SKIP() << "no shared data";
    const fs::path dir = fs::temp_directory_path() / "hpray_test_cli_vector";
    fs::remove_all(dir);
    fs::create_directories(dir);
    for (const char* field : {"displacement", "displacement.magnitude"}) {
        const fs::path scene = dir / "v.yaml";
        {
            std::ofstream out(scene);
            out << "data: {mesh: " << mesh << "}\ncamera: {width: 32, height: 32}\n"
                << "isosurfaces: [{field: " << field << ", value: 0.0004}]\n";
        }
        const RunResult r = RunHpray("render " + scene.string() +
                                     " --set output.exr=null --set output.png=null"
                                     " --set output.stats=null");
        EXPECT_EQ(r.code, 0) << r.out;
        const bool warned =
            r.out.find("warning: field 'displacement' has 3 components: its magnitude is "
                       "used") != std::string::npos;
        EXPECT_EQ(warned, std::string(field) == "displacement") << field << "\n" << r.out;
    }
    fs::remove_all(dir);
}

// A volume given only its field is visible and not opaque: the default transfer functions
// put an optical depth of about 1 to 3 through the data where the field is high.
TEST(Cli, DefaultVolumeIsNeitherInvisibleNorOpaque) {
    namespace fs = std::filesystem;
    const fs::path dir = fs::temp_directory_path() / "hpray_test_cli_default_volume";
    fs::remove_all(dir);
    fs::create_directories(dir);
    const RunResult r = RunHpray(
        "render " + std::string(HPRAY_SOURCE_DIR) + "/configs/ball_p2.yaml" +
        " --set isosurfaces=null --set 'volume={color_field: u}'" +
        " --set 'camera={width: 96, height: 96}'" +
        " --set output.exr=null --set output.png=null --set output.stats=null" +
        " --set output.rgba=" + (dir / "v.npy").string());
    ASSERT_EQ(r.code, 0) << r.out;
    std::vector<std::size_t> shape;
    const std::vector<double> a = hpray::ReadNpy((dir / "v.npy").string(), shape);
    double most = 0, sum = 0;
    std::size_t covered = 0;
    for (std::size_t i = 3; i < a.size(); i += 4) {
        most = std::max(most, a[i]);
        if (a[i] > 0) sum += a[i], ++covered;
    }
    ASSERT_GT(covered, 0u);
    EXPECT_GT(most, 0.2);
    EXPECT_LT(most, 0.99);
    EXPECT_GT(sum / covered, 0.05);
    fs::remove_all(dir);
}

TEST(Cli, VersionHelpAndMisspeltSubcommands) {
    RunResult r = RunHpray("--version");
    EXPECT_EQ(r.code, 0);
    EXPECT_EQ(r.out.rfind("hpray ", 0), 0u) << r.out;
    r = RunHpray("help");
    EXPECT_EQ(r.code, 0);
    EXPECT_NE(r.out.find("render"), std::string::npos) << r.out;
    r = RunHpray("rendr x.yaml");
    EXPECT_EQ(r.code, 2);
    EXPECT_NE(r.out.find("unknown subcommand 'rendr'; did you mean 'render'?"),
              std::string::npos)
        << r.out;
    r = RunHpray("-q partiton builtin:cube-tets-1");
    EXPECT_EQ(r.code, 2);
    EXPECT_NE(r.out.find("did you mean 'partition'?"), std::string::npos) << r.out;
}

// Outputs are checked before any work: a folder, or an extension of another format, is
// an input error naming the key, and nothing is written.
TEST(Cli, BadOutputPathsFailBeforeRendering) {
    namespace fs = std::filesystem;
    const fs::path dir = fs::temp_directory_path() / "hpray_test_cli_outputs";
    fs::remove_all(dir);
    fs::create_directories(dir / "folder");
    const std::string scene = std::string(HPRAY_SOURCE_DIR) + "/configs/quickstart.yaml";
    const std::string stats = (dir / "stats.json").string();
    RunResult r = RunHpray("render " + scene + " --set output.png=" + (dir / "folder").string() +
                           " --set output.exr=null --set output.stats=" + stats);
    EXPECT_EQ(r.code, 2) << r.out;
    EXPECT_NE(r.out.find("output.png: '" + (dir / "folder").string() + "' is a folder"),
              std::string::npos)
        << r.out;
    EXPECT_FALSE(fs::exists(stats));
    EXPECT_EQ(r.out.find("rendered"), std::string::npos) << r.out;
    r = RunHpray("render " + scene + " --set output.png=" + (dir / "frame.jpg").string() +
                 " --set output.exr=null --set output.stats=null");
    EXPECT_EQ(r.code, 2) << r.out;
    EXPECT_NE(r.out.find("output.png"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("ends in .jpg"), std::string::npos) << r.out;
    r = RunHpray("render " + scene + " --set output.exr=" + (dir / "frame.png").string() +
                 " --set output.png=null --set output.stats=null");
    EXPECT_EQ(r.code, 2) << r.out;
    EXPECT_NE(r.out.find("output.exr"), std::string::npos) << r.out;
    EXPECT_FALSE(fs::exists(dir / "frame.png"));
    fs::remove_all(dir);
}

// hpray partition never writes into a folder of other files unless told to, and leaves no
// lock file behind.
TEST(Cli, PartitionRefusesAForeignFolderAndLeavesNoLock) {
    namespace fs = std::filesystem;
    const fs::path dir = fs::temp_directory_path() / "hpray_test_cli_foreign";
    fs::remove_all(dir);
    fs::create_directories(dir);
    std::ofstream(dir / "notes.txt") << "not a partition\n";
    RunResult r = RunHpray("partition builtin:cube-tets-2 --bricks 2 --out " + dir.string());
    EXPECT_EQ(r.code, 2) << r.out;
    EXPECT_NE(r.out.find("notes.txt"), std::string::npos) << r.out;
    EXPECT_FALSE(fs::exists(dir / "manifest.json"));
    EXPECT_FALSE(fs::exists(dir / ".hpray-partition.lock"));
    r = RunHpray("partition builtin:cube-tets-2 --bricks 2 --force --out " + dir.string());
    EXPECT_EQ(r.code, 0) << r.out;
    EXPECT_TRUE(fs::exists(dir / "manifest.json"));
    EXPECT_TRUE(fs::exists(dir / "notes.txt"));
    EXPECT_FALSE(fs::exists(dir / ".hpray-partition.lock"));
    // A partition directory may be written again without --force.
    const fs::path part = dir / "part";
    EXPECT_EQ(RunHpray("partition builtin:cube-tets-2 --bricks 2 --out " + part.string()).code, 0);
    r = RunHpray("partition builtin:cube-tets-2 --bricks 3 --out " + part.string());
    EXPECT_EQ(r.code, 0) << r.out;
    EXPECT_FALSE(fs::exists(part / ".hpray-partition.lock"));
    fs::remove_all(dir);
}

}  // namespace

namespace {

std::string WritePoints(const std::string& name, const std::vector<std::array<double, 3>>& pts) {
    const auto dir = std::filesystem::temp_directory_path() / "hpray_test_cli";
    std::filesystem::create_directories(dir);
    const auto path = dir / name;
    std::ofstream out(path);
    out << "x,y,z\n";
    out.precision(17);
    for (const auto& p : pts) out << p[0] << "," << p[1] << "," << p[2] << "\n";
    return path.string();
}

std::vector<std::array<double, 3>> RandomPoints(int n, double lo, double hi, unsigned seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> u(lo, hi);
    std::vector<std::array<double, 3>> pts(n);
    for (auto& p : pts) p = {u(rng), u(rng), u(rng)};
    return pts;
}

TEST(CliProbe, BallP2ReproducesTheQuadraticExactly) {
    auto pts = RandomPoints(300, -1.0, 1.0, 7);
    pts.push_back({2.0, 0.0, 0.0});  // outside
    pts.push_back({1.0, 1.0, 1.0});  // a corner vertex
    pts.push_back({0.0, 0.0, 0.0});  // an interior vertex shared by many cells
    const std::string csv = WritePoints("ball.csv", pts);
    RunResult r = RunHpray("probe builtin:ball-p2 --points " + csv + " --gradient --json -q");
    ASSERT_EQ(r.code, 0) << r.out;
    const auto j = nlohmann::json::parse(r.out);
    ASSERT_EQ(j.size(), pts.size());
    for (std::size_t i = 0; i < pts.size(); ++i) {
        const auto& e = j[i];
        const double x = pts[i][0], y = pts[i][1], z = pts[i][2];
        if (i == 300) {
            EXPECT_TRUE(e["cell"].is_null());
            EXPECT_TRUE(e["ref"].is_null());
            EXPECT_TRUE(e["values"].empty());
            continue;
        }
        ASSERT_FALSE(e["cell"].is_null()) << i;
        const double u = e["values"]["u"].get<double>();
        EXPECT_NEAR(u, x * x + y * y + z * z, 1e-13) << i;
        const auto& g = e["gradients"]["u"];
        EXPECT_NEAR(g[0].get<double>(), 2 * x, 1e-12) << i;
        EXPECT_NEAR(g[1].get<double>(), 2 * y, 1e-12) << i;
        EXPECT_NEAR(g[2].get<double>(), 2 * z, 1e-12) << i;
    }
}

TEST(CliProbe, CubeTetsReproducesTheLinearField) {
    auto pts = RandomPoints(300, 0.0, 1.0, 11);
    pts.push_back({0.25, 0.5, 0.75});  // on grid planes
    pts.push_back({1.0 + 1e-9, 0.5, 0.5});  // just outside
    const std::string csv = WritePoints("cube.csv", pts);
    RunResult r = RunHpray("probe builtin:cube-tets-4 --points " + csv + " --json -q");
    ASSERT_EQ(r.code, 0) << r.out;
    const auto j = nlohmann::json::parse(r.out);
    ASSERT_EQ(j.size(), pts.size());
    for (std::size_t i = 0; i + 1 < pts.size(); ++i) {
        ASSERT_FALSE(j[i]["cell"].is_null()) << i;
        const double expect = pts[i][0] + 2 * pts[i][1] + 3 * pts[i][2];
        EXPECT_NEAR(j[i]["values"]["u"].get<double>(), expect, 1e-14) << i;
        // Affine tets: the reference point lies in the unit simplex.
        const auto& ref = j[i]["ref"];
        const double r0 = ref[0].get<double>(), r1 = ref[1].get<double>(), r2 = ref[2].get<double>();
        EXPECT_GE(std::min({r0, r1, r2}), -1e-12);
        EXPECT_LE(r0 + r1 + r2, 1 + 1e-12);
    }
    EXPECT_TRUE(j.back()["cell"].is_null());
}

// deal.II step-65: the exact solution is known (u = r^2 inside r < 0.5, 0.1 r^2 + 0.225
// outside); the file's Q3 solution on curved cells, read with the legacy hex order, must
// interpolate it to the discretisation error (~1e-6), which also checks ordering and the
// inversion of curved cells on real data.
TEST(CliProbe, DealiiStep65MatchesTheExactSolution) {
    const std::string mesh = std::string(HPRAY_SHARED_DATA) + "/dealii_step65_hex_q3.vtu";
    if (!std::filesystem::exists(mesh)) GTEST_SKIP() << "no shared data";
    auto pts = RandomPoints(400, -0.999, 0.999, 3);
    const std::string csv = WritePoints("step65.csv", pts);
    RunResult r = RunHpray("probe " + mesh + " --points " + csv + " --fields solution --json -q");
    ASSERT_EQ(r.code, 0) << r.out.substr(0, 2000);
    const auto j = nlohmann::json::parse(r.out);
    double maxErr = 0;
    for (std::size_t i = 0; i < pts.size(); ++i) {
        ASSERT_FALSE(j[i]["cell"].is_null()) << i;
        const double r2 = pts[i][0] * pts[i][0] + pts[i][1] * pts[i][1] + pts[i][2] * pts[i][2];
        const double exact = r2 < 0.25 ? r2 : 0.1 * r2 + 0.225;
        maxErr = std::max(maxErr, std::abs(j[i]["values"]["solution"].get<double>() - exact));
    }
    EXPECT_LT(maxErr, 2e-6);
}

TEST(CliProbe, BadPointsFileIsInputError) {
    const auto dir = std::filesystem::temp_directory_path() / "hpray_test_cli";
    std::filesystem::create_directories(dir);
    std::ofstream(dir / "bad.csv") << "x,y,z\n0,0,0\n1,2\n";
    RunResult r = RunHpray("probe builtin:cube-tets-1 --points " + (dir / "bad.csv").string());
    EXPECT_EQ(r.code, 2);
    EXPECT_NE(r.out.find("bad.csv: line 3"), std::string::npos) << r.out;
    std::ofstream(dir / "nan.csv") << "0,0,nan\n";
    r = RunHpray("probe builtin:cube-tets-1 --points " + (dir / "nan.csv").string());
    EXPECT_EQ(r.code, 2);
    r = RunHpray("probe builtin:cube-tets-1 --points " + (dir / "nan.csv").string() + " --fields nope");
    EXPECT_EQ(r.code, 2);
}

}  // namespace

namespace {

// `hpray info` on every mesh of the shared data, against the counts of its README.
struct SharedMesh {
    const char* file;
    long long points;
    long long tet, hex, wedge, pyramid;
    int order;
    std::vector<std::string> fields;
};

TEST(CliInfo, EverySharedMeshMatchesItsDocumentedCounts) {
    const std::vector<SharedMesh> meshes = {
        {"gmsh_boolean_tet_p4.vtu", 16460, 1170, 0, 0, 0, 4, {"analytic", "region"}},
        {"mfem_escher_tet_p3.vtu", 103825, 21504, 0, 0, 0, 3, {"analytic", "u", "attribute"}},
        {"mfem_toroid_wedge_p3.vtu", 6552, 0, 0, 384, 0, 3, {"analytic", "u", "attribute"}},
        {"mfem_toroid_hex_p3.vtu", 12168, 0, 384, 0, 0, 3, {"analytic", "u", "attribute"}},
        {"mfem_spiral_hex_p9.vtu", 6859, 0, 8, 0, 0, 9, {"analytic", "u", "attribute"}},
        {"mfem_fichera_mixed_p3.vtu", 1946, 40, 24, 48, 0, 3, {"analytic", "u", "attribute"}},
        {"mfem_escher_quadtet_p2.vtu", 117, 42, 0, 0, 0, 2, {"analytic", "material"}},
        {"dealii_step65_hex_q3.vtu", 425984, 0, 6656, 0, 0, 3, {"solution", "material_ids"}},
        {"dealii_step44_hex_q2.vtu", 13824, 0, 512, 0, 0, 2,
         {"displacement", "pressure", "dilatation"}},
        {"mfem_beam_hex_elasticity_p3.vtu", 16393, 0, 512, 0, 0, 3,
         {"displacement", "displacement_magnitude", "attribute"}},
        {"mfem_fichera_mixed16_linear.vtu", 31841, 50400, 4096, 24576, 11664, 1,
         {"u", "analytic", "attribute"}},
        {"mfem_gmsh_t16_tets_1M.vtu", 212956, 1251511, 0, 0, 0, 1, {"u", "analytic", "attribute"}},
        {"gmsh_hybrid_pyr_p3.msh", 19609, 1779, 324, 0, 36, 3, {"analytic"}},
        {"gmsh_pripyrtet_p2.msh", 805, 12, 0, 135, 15, 2, {"analytic"}},
    };
    for (const SharedMesh& m : meshes) {
        const std::string path = std::string(HPRAY_SHARED_DATA) + "/" + m.file;
        if (!std::filesystem::exists(path)) GTEST_SKIP() << "no shared data";
        const auto j = InfoJson(path);
        EXPECT_EQ(j["points"], m.points) << m.file;
        EXPECT_EQ(j["cells_by_type"]["tet"], m.tet) << m.file;
        EXPECT_EQ(j["cells_by_type"]["hex"], m.hex) << m.file;
        EXPECT_EQ(j["cells_by_type"]["wedge"], m.wedge) << m.file;
        EXPECT_EQ(j["cells_by_type"]["pyramid"], m.pyramid) << m.file;
        EXPECT_EQ(j["cells"], m.tet + m.hex + m.wedge + m.pyramid) << m.file;
        EXPECT_EQ(j["orders"].size(), 1u) << m.file;
        EXPECT_EQ(j["orders"][std::to_string(m.order)], m.tet + m.hex + m.wedge + m.pyramid)
            << m.file;
        for (const std::string& f : m.fields) EXPECT_TRUE(j["fields"].contains(f)) << m.file << " " << f;
        EXPECT_EQ(j["fields"].size(), m.fields.size()) << m.file;
        // Bounds are finite and ordered.
        for (int d = 0; d < 3; ++d)
            EXPECT_LT(j["bounds"][0][d].get<double>(), j["bounds"][1][d].get<double>()) << m.file;
    }
}

// deal.II step-44 was written with DataOut's default curved_boundary patches: cells at
// the boundary place their edge and face nodes on the curved mapping, interior cells on
// straight lines, so 216 of the 1344 shared faces (counted independently with VTK's reader:
// face-centre nodes that differ between the two cells) carry two versions. A volume render
// must still walk every ray without repairs or failed inversions, and say what it found.
TEST(CliRender, NonConformingDealiiOutputRendersCleanly) {
    const std::string mesh = std::string(HPRAY_SHARED_DATA) + "/dealii_step44_hex_q2.vtu";
    if (!std::filesystem::exists(mesh)) GTEST_SKIP() << "no shared data";
    const auto dir = std::filesystem::temp_directory_path() / "hpray_test_cli";
    std::filesystem::create_directories(dir);
    const auto scene = dir / "step44.yaml";
    const auto stats = dir / "step44.json";
    std::ofstream(scene) << "data: {mesh: " << mesh << "}\n"
                         << "camera: {position: [0.004, 0.003, 0.0035], look_at: [0.0006, "
                            "0.0005, 0.0006], up: [0, 1, 0], fov_y: 30, width: 40, height: 40}\n"
                            "volume: {color_field: dilatation, color_tf: [[0.9989, 0, 0, 1], "
                            "[1.0003, 1, 0, 0]], extinction_tf: [[0.9989, 1000], [1.0003, 3000]]}\n"
                         << "output: {stats: " << stats.string() << "}\n";
    const RunResult r = RunHpray("render " + scene.string());
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_NE(r.out.find("216 shared faces"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("not conforming"), std::string::npos) << r.out;
    std::ifstream in(stats);
    const auto j = nlohmann::json::parse(in);
    EXPECT_EQ(j["traversal"]["nonconforming_faces"], 216);
    EXPECT_GT(j["traversal"]["nonconforming_edges"].get<double>(), 0);
    EXPECT_EQ(j["traversal"]["walk_repairs"], 0);
    EXPECT_EQ(j["traversal"]["walk_failures"], 0);
    EXPECT_GT(j["mapping"]["inversions"].get<double>(), 10000);
    EXPECT_EQ(j["mapping"]["failures"], 0);
    EXPECT_GT(j["segments"].get<double>(), 1000);
}

// Every curved and mixed mesh of the shared data (all but the 1.25M-tet one), with every
// scalar point field, rendered as a volume spanning the field's range with a
// semi-transparent isosurface at its middle and transfer-function breakpoints at its
// extremes: every inversion converges, every ray walks without repair, no root window is
// left unresolved, and every hit has a residual at the rounding level of the field. This
// is what caught step-44's non-conforming faces, the order-9 spiral's inversions and
// step-65's material_ids (constant per cell, equal to the breakpoints), which ran for
// minutes.
TEST(CliRender, EverySharedMeshAndFieldRendersCleanly) {
    const std::vector<std::string> files = {
        "gmsh_boolean_tet_p4.vtu",       "mfem_escher_tet_p3.vtu",
        "mfem_toroid_wedge_p3.vtu",      "mfem_toroid_hex_p3.vtu",
        "mfem_spiral_hex_p9.vtu",        "mfem_fichera_mixed_p3.vtu",
        "mfem_escher_quadtet_p2.vtu",    "dealii_step65_hex_q3.vtu",
        "dealii_step44_hex_q2.vtu",      "mfem_beam_hex_elasticity_p3.vtu",
        "mfem_fichera_mixed16_linear.vtu", "gmsh_hybrid_pyr_p3.msh",
        "gmsh_pripyrtet_p2.msh"};
    const auto dir = std::filesystem::temp_directory_path() / "hpray_test_cli";
    std::filesystem::create_directories(dir);
    int renders = 0;
    for (const std::string& file : files) {
        const std::string path = std::string(HPRAY_SHARED_DATA) + "/" + file;
        if (!std::filesystem::exists(path)) GTEST_SKIP() << "no shared data";
        const auto info = InfoJson(path);
        std::array<double, 3> lo, hi, centre;
        double size = 0;
        for (int d = 0; d < 3; ++d) {
            lo[d] = info["bounds"][0][d].get<double>();
            hi[d] = info["bounds"][1][d].get<double>();
            centre[d] = 0.5 * (lo[d] + hi[d]);
            size = std::max(size, hi[d] - lo[d]);
        }
        for (const auto& [name, field] : info["fields"].items()) {
            if (field["association"] != "point" || field["components"] != 1) continue;
            const double f0 = field["range"][0].get<double>(), f1 = field["range"][1].get<double>();
            if (!(f1 > f0)) continue;
            const auto scene = dir / "shared.yaml";
            const auto stats = dir / "shared.json";
            std::ofstream(scene) << std::setprecision(17) << "data: {mesh: " << path << "}\n"
                                 << "camera: {position: [" << centre[0] + 1.7 * size << ", "
                                 << centre[1] + 1.3 * size << ", " << centre[2] + 2.1 * size
                                 << "], look_at: [" << centre[0] << ", " << centre[1] << ", "
                                 << centre[2] << "], up: [0, 1, 0], fov_y: 35, width: 20, "
                                 << "height: 20}\n"
                                 << "isosurfaces: [{field: " << name << ", value: "
                                 << 0.5 * (f0 + f1) << ", opacity: 0.6}]\n"
                                 << "volume: {color_field: " << name << ", color_tf: [[" << f0
                                 << ", 0, 0, 1], [" << f1 << ", 1, 0, 0]], extinction_tf: [["
                                 << f0 << ", " << 1 / size << "], [" << f1 << ", " << 4 / size
                                 << "]]}\n"
                                 << "output: {stats: " << stats.string() << "}\nthreads: 2\n";
            const RunResult r = RunHpray("render " + scene.string() + " -q");
            ASSERT_EQ(r.code, 0) << file << " " << name << "\n" << r.out;
            std::ifstream in(stats);
            const auto j = nlohmann::json::parse(in);
            const std::string what = file + " " + name;
            EXPECT_EQ(j["mapping"]["failures"], 0) << what;
            EXPECT_EQ(j["traversal"]["walk_repairs"], 0) << what;
            EXPECT_EQ(j["traversal"]["walk_failures"], 0) << what;
            EXPECT_EQ(j["iso"]["root_failures"], 0) << what;
            EXPECT_LE(j["iso"]["max_residual_relative"].get<double>(), 1e-11) << what;
            EXPECT_GT(j["segments"].get<double>(), 0) << what;
            ++renders;
        }
    }
    EXPECT_GE(renders, 20);
}

TEST(CliInfo, VectorFieldsReportComponents) {
    const std::string path = std::string(HPRAY_SHARED_DATA) + "/dealii_step44_hex_q2.vtu";
    if (!std::filesystem::exists(path)) GTEST_SKIP() << "no shared data";
    const auto j = InfoJson(path);
    EXPECT_EQ(j["fields"]["displacement"]["components"], 3);
    EXPECT_EQ(j["fields"]["displacement"]["component_ranges"].size(), 3u);
    EXPECT_EQ(j["fields"]["pressure"]["components"], 1);
}

}  // namespace
