// hpray render of a .pvd time series and of several frames in one run (scene key
// `frames`), on one process and on 2 MPI ranks: every numbered output must equal, bit for
// bit, a separate `hpray render` of that frame alone (the step's own .vtu, the camera set
// with --set). Bad .pvd input and bad time selections exit 2 with a message that names
// the problem.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <unistd.h>

#include <nlohmann/json.hpp>

#include "app/process_util.h"
#include "io/image.h"
#include "io/vtu_writer.h"
#include "mesh/builtin.h"

namespace hpray {
namespace {

namespace fs = std::filesystem;
using test::Mpirun;
using test::RunCommand;

// One folder per test process: ctest runs the tests of this binary in parallel processes.
const fs::path kDir = fs::temp_directory_path() / ("hpray_test_frames_" + std::to_string(getpid()));

constexpr int kSteps = 3;
const double kTimes[kSteps] = {0.0, 0.25, 0.5};

/// Step s of the series: the quadratic ball grown by 10% per step (an automatic camera
/// fits each step's bounds) with u = (1 + 0.4 s) (x^2 + y^2 + z^2) and v = x + s.
Mesh StepMesh(int s) {
    Mesh mesh = MakeBuiltin("builtin:ball-p2?n=2");
    for (double& x : mesh.points) x *= 1.0 + 0.1 * s;
    for (Field& f : mesh.pointFields) {
        if (f.name == "u")
            for (double& u : f.values) u *= 1.0 + 0.4 * s;
        if (f.name == "v")
            for (double& v : f.values) v += s;
    }
    return mesh;
}

std::string StepFile(int s) { return (kDir / ("ball_" + std::to_string(s) + ".vtu")).string(); }

void WriteText(const fs::path& path, const std::string& text) {
    std::ofstream out(path);
    out << text;
    ASSERT_TRUE(out.good()) << path;
}

/// A .pvd listing `datasets` (each a <DataSet .../> line) in its <Collection>.
void WritePvd(const fs::path& path, const std::string& datasets) {
    WriteText(path, "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\">\n"
                    "  <Collection>\n" + datasets + "  </Collection>\n</VTKFile>\n");
}

std::string DataSet(double time, int part, const std::string& file) {
    char text[512];
    std::snprintf(text, sizeof text, "    <DataSet timestep=\"%.17g\" part=\"%d\" file=\"%s\"/>\n",
                  time, part, file.c_str());
    return text;
}

/// The scene every test renders: an isosurface of u, a slice coloured by v over its range
/// in the data (range: auto follows each step), an automatic camera, small images.
const char* kScene = R"(data: {mesh: series.pvd}
camera: {width: 40, height: 36, view: iso}
isosurfaces:
  - {field: u, value: 0.5, color: [0.85, 0.3, 0.2], opacity: 0.6}
slices:
  - {point: [0, 0, 0], normal: [0, 0, 1], field: v, color_tf: {map: viridis}, opacity: 0.8}
threads: 2
)";

class Frames : public ::testing::Test {
  protected:
    static void SetUpTestSuite() {
        fs::remove_all(kDir);
        fs::create_directories(kDir);
        std::string datasets;
        // Listed out of time order: the collection orders its steps by time.
        for (int s : {2, 0, 1}) {
            WriteVtu(StepFile(s), StepMesh(s));
            datasets += DataSet(kTimes[s], 0, "ball_" + std::to_string(s) + ".vtu");
        }
        WritePvd(kDir / "series.pvd", datasets);
        WriteText(kDir / "scene.yaml", kScene);
    }
    static void TearDownTestSuite() { fs::remove_all(kDir); }
};

std::string Hpray() { return std::string(HPRAY_BINARY) + " "; }

/// `hpray render scene.yaml -q` with `sets` (--set items), writing rgba, hits and stats
/// under the name `tag` (numbered ones when the scene has frames); returns the output.
std::string Render(const std::string& tag, const std::string& sets,
                   const std::string& launcher = "", int expectCode = 0) {
    const std::string cmd = launcher + Hpray() + "render " + (kDir / "scene.yaml").string() +
                            " -q " + sets + " --set output.rgba=" +
                            (kDir / (tag + ".npy")).string() + " --set output.hits=" +
                            (kDir / (tag + "_hits.npy")).string() + " --set output.stats=" +
                            (kDir / (tag + ".json")).string();
    std::string out;
    EXPECT_EQ(RunCommand(cmd, &out), expectCode) << cmd << "\n" << out;
    return out;
}

std::string Numbered(const std::string& tag, int k) {
    char text[16];
    std::snprintf(text, sizeof text, "_%04d", k);
    return tag + text;
}

/// The rgba and hits arrays of output name `tag`, one after the other; of frame `k`
/// (tag_000k.npy and tag_hits_000k.npy) unless k < 0.
std::vector<double> Arrays(const std::string& tag, int k = -1) {
    const std::string rgba = k < 0 ? tag : Numbered(tag, k);
    const std::string hits = k < 0 ? tag + "_hits" : Numbered(tag + "_hits", k);
    std::vector<std::size_t> shape;
    std::vector<double> a = ReadNpy((kDir / (rgba + ".npy")).string(), shape);
    EXPECT_EQ(shape, (std::vector<std::size_t>{36, 40, 4})) << rgba;
    const std::vector<double> h = ReadNpy((kDir / (hits + ".npy")).string(), shape);
    EXPECT_EQ(shape, (std::vector<std::size_t>{36, 40, 5})) << hits;
    a.insert(a.end(), h.begin(), h.end());
    return a;
}

/// Bit for bit (NaN equal to NaN); also that something is drawn.
void ExpectIdentical(const std::vector<double>& ref, const std::vector<double>& got,
                     const std::string& what) {
    ASSERT_EQ(ref.size(), got.size()) << what;
    std::size_t differing = 0, first = ref.size(), drawn = 0;
    for (std::size_t i = 0; i < ref.size(); ++i) {
        const bool same = std::isnan(ref[i]) ? std::isnan(got[i]) : ref[i] == got[i];
        if (!same && differing++ == 0) first = i;
        drawn += i < 36 * 40 * 4 && ref[i] > 0;
    }
    EXPECT_EQ(differing, 0u) << what << ": first at entry " << first;
    EXPECT_GT(drawn, 100u) << what << ": the image is (almost) empty";
}

nlohmann::json Stats(const std::string& name) {
    std::ifstream in(kDir / (name + ".json"));
    return nlohmann::json::parse(in);
}

/// A separate render of step `s` from its own .vtu, with further --set items.
std::vector<double> Reference(int s, const std::string& tag, const std::string& sets = "") {
    Render(tag, "--set data.mesh=" + StepFile(s) + " " + sets);
    return Arrays(tag);
}

TEST_F(Frames, EveryTimeStepInOneRunEqualsItsOwnRender) {
    // The steps differ (else the test would prove nothing).
    const auto r0 = Reference(0, "ref_t0"), r1 = Reference(1, "ref_t1"),
               r2 = Reference(2, "ref_t2");
    EXPECT_NE(r0, r1);
    EXPECT_NE(r1, r2);
    const std::vector<double>* refs[] = {&r0, &r1, &r2};
    Render("time", "--set frames.time=all");
    for (int k = 0; k < kSteps; ++k) {
        ExpectIdentical(*refs[k], Arrays("time", k), "frame " + std::to_string(k));
        const nlohmann::json stats = Stats(Numbered("time", k));
        EXPECT_EQ(stats["frame"], k);
        EXPECT_EQ(stats["time"]["step"], k);
        EXPECT_EQ(stats["time"]["value"], kTimes[k]);
    }
    EXPECT_FALSE(fs::exists(kDir / (Numbered("time", kSteps) + ".npy")));
    EXPECT_FALSE(fs::exists(kDir / "time.npy"));  // only numbered outputs

    // data.time picks one step, by index or by value, in a single-frame render.
    Render("one_index", "--set data.time=2");
    ExpectIdentical(r2, Arrays("one_index"), "data.time=2");
    Render("one_value", "--set 'data.time={value: 0.25}'");
    ExpectIdentical(r1, Arrays("one_value"), "data.time={value: 0.25}");
    Render("one_float", "--set data.time=0.5");
    ExpectIdentical(r2, Arrays("one_float"), "data.time=0.5");
    Render("first", "");
    ExpectIdentical(r0, Arrays("first"), "the default step");
    EXPECT_EQ(Stats("first")["time"]["step"], 0);
    EXPECT_FALSE(Stats("first").contains("frame"));

    // A range of steps.
    Render("range", "--set frames.time=[1,2]");
    ExpectIdentical(r1, Arrays("range", 0), "range frame 0");
    ExpectIdentical(r2, Arrays("range", 1), "range frame 1");
    EXPECT_FALSE(fs::exists(kDir / (Numbered("range", 2) + ".npy")));
}

TEST_F(Frames, CameraPathFrameEqualsARenderWithThatCamera) {
    // Four frames, azimuth 0..90 and elevation 0..30: frame k has 30 k and 10 k.
    const std::string out =
        Render("path", "--set data.time=1 --set 'frames={count: 4, azimuth: [0, 90], "
                       "elevation: [0, 30]}'");
    for (int k = 0; k < 4; ++k) {
        const std::string sets = "--set camera.azimuth=" + std::to_string(30 * k) +
                                 " --set camera.elevation=" + std::to_string(10 * k);
        const auto ref = Reference(1, "ref_path" + std::to_string(k), sets);
        ExpectIdentical(ref, Arrays("path", k), "path frame " + std::to_string(k));
        // The camera-only frames reuse the preparation: no load or accel time after the
        // first.
        const nlohmann::json stats = Stats(Numbered("path", k));
        if (k > 0) {
            EXPECT_EQ(stats["timing_s"]["load"], 0.0);
            EXPECT_EQ(stats["timing_s"]["accel"], 0.0);
        }
        EXPECT_EQ(stats["time"]["step"], 1);
    }
}

TEST_F(Frames, ListOfOverridesAndTimeWithCameraPath) {
    // Per-frame keys: another view, another step and zoom, another isovalue (the set-up
    // rebuilt on the same step), and back to the first step.
    WriteText(kDir / "list.yaml",
              std::string(kScene) +
                  "frames:\n  list:\n    - {camera.view: +x}\n"
                  "    - {data.time: 2, camera.zoom: 1.5}\n"
                  "    - {data.time: 2, isosurfaces.0.value: 0.8}\n"
                  "    - {}\n");
    std::string out;
    const std::string cmd = Hpray() + "render " + (kDir / "list.yaml").string() +
                            " -q --set output.rgba=" + (kDir / "list.npy").string() +
                            " --set output.hits=" + (kDir / "list_hits.npy").string();
    ASSERT_EQ(RunCommand(cmd, &out), 0) << cmd << "\n" << out;
    const std::pair<int, std::string> expected[] = {
        {0, "--set camera.view=+x"},
        {2, "--set camera.zoom=1.5"},
        {2, "--set isosurfaces.0.value=0.8"},
        {0, ""}};
    for (int k = 0; k < 4; ++k) {
        const auto ref = Reference(expected[k].first, "ref_list" + std::to_string(k),
                                   expected[k].second);
        ExpectIdentical(ref, Arrays("list", k), "list frame " + std::to_string(k));
    }

    // Time and a camera path together: one frame per step, the camera moving along.
    Render("timepath", "--set 'frames={time: all, azimuth: [0, 60]}'");
    for (int k = 0; k < kSteps; ++k) {
        const auto ref = Reference(k, "ref_timepath" + std::to_string(k),
                                   "--set camera.azimuth=" + std::to_string(30 * k));
        ExpectIdentical(ref, Arrays("timepath", k),
                        "time and path frame " + std::to_string(k));
    }
}

TEST_F(Frames, TwoRanksRenderTheSameFrames) {
    // The image split (the default for a mesh) is bit for bit the single-rank image.
    Render("mpi", "--set 'frames={time: all, azimuth: [0, 60]}'", Mpirun(2));
    Render("mpi_list", "--set 'frames={list: [{data.time: 1}, {data.time: 1, camera.zoom: 2}, "
                       "{data.time: 0}]}'",
           Mpirun(2));
    for (int k = 0; k < kSteps; ++k) {
        const auto ref = Reference(k, "ref_mpi" + std::to_string(k),
                                   "--set camera.azimuth=" + std::to_string(30 * k));
        ExpectIdentical(ref, Arrays("mpi", k), "2 ranks, frame " + std::to_string(k));
        EXPECT_EQ(Stats(Numbered("mpi", k))["ranks"], 2);
    }
    ExpectIdentical(Reference(1, "ref_mpi_list0"), Arrays("mpi_list", 0),
                    "2 ranks, list frame 0");
    ExpectIdentical(Reference(1, "ref_mpi_list1", "--set camera.zoom=2"),
                    Arrays("mpi_list", 1), "2 ranks, list frame 1");
    ExpectIdentical(Reference(0, "ref_mpi_list2"), Arrays("mpi_list", 2),
                    "2 ranks, list frame 2");
}

TEST_F(Frames, PartsOfAStepAreMergedAsPiecesOfAPvtu) {
    // Step 1 split in two parts (cells halved, all points in each part), in the .pvd and
    // in a .pvtu: the two reads must give the same mesh, so the same image.
    const Mesh whole = StepMesh(1);
    const std::int64_t half = whole.CellCount() / 2;
    std::string pieces;
    for (int p = 0; p < 2; ++p) {
        Mesh part;
        part.points = whole.points;
        part.pointFields = whole.pointFields;
        for (std::int64_t c = p == 0 ? 0 : half; c < (p == 0 ? half : whole.CellCount()); ++c)
            part.AddCell(whole.cellShape[c], whole.cellOrder[c], whole.cellFamily[c],
                         whole.CellNodes(c), whole.CellNodeCount(c));
        WriteVtu((kDir / ("part_" + std::to_string(p) + ".vtu")).string(), part);
        pieces += "    <Piece Source=\"part_" + std::to_string(p) + ".vtu\"/>\n";
    }
    WriteText(kDir / "parts.pvtu",
              "<?xml version=\"1.0\"?>\n<VTKFile type=\"PUnstructuredGrid\" version=\"1.0\" "
              "byte_order=\"LittleEndian\" header_type=\"UInt64\">\n"
              "  <PUnstructuredGrid GhostLevel=\"0\">\n"
              "    <PPointData><PDataArray type=\"Float64\" Name=\"u\"/>"
              "<PDataArray type=\"Float64\" Name=\"v\"/></PPointData>\n"
              "    <PPoints><PDataArray type=\"Float64\" NumberOfComponents=\"3\"/></PPoints>\n" +
                  pieces + "  </PUnstructuredGrid>\n</VTKFile>\n");
    // Parts listed in reverse: the part number orders them.
    WritePvd(kDir / "parts.pvd", DataSet(0.25, 1, "part_1.vtu") + DataSet(0.25, 0, "part_0.vtu"));
    Render("pvtu", "--set data.mesh=" + (kDir / "parts.pvtu").string());
    Render("pvd_parts", "--set data.mesh=" + (kDir / "parts.pvd").string());
    ExpectIdentical(Arrays("pvtu"), Arrays("pvd_parts"), "two parts");
    std::string out;
    ASSERT_EQ(RunCommand(Hpray() + "info --json -q " + (kDir / "parts.pvd").string(), &out), 0)
        << out;
    const nlohmann::json info = nlohmann::json::parse(out);
    EXPECT_EQ(info["cells"], whole.CellCount());
    EXPECT_EQ(info["time_steps"], nlohmann::json::array({0.25}));
}

/// Renders `scene` text (written to bad.yaml) expecting exit 2; returns the output.
std::string RenderBad(const std::string& scene, const std::string& sets = "") {
    WriteText(kDir / "bad.yaml", scene);
    const std::string cmd = Hpray() + "render " + (kDir / "bad.yaml").string() +
                            " --set output.rgba=" + (kDir / "bad.npy").string() + " " + sets;
    std::string out;
    EXPECT_EQ(RunCommand(cmd, &out), 2) << cmd << "\n" << out;
    EXPECT_FALSE(fs::exists(kDir / "bad.npy")) << cmd;
    EXPECT_FALSE(fs::exists(kDir / "bad_0000.npy")) << cmd;
    return out;
}

#define EXPECT_MENTIONS(text, part) \
    EXPECT_NE((text).find(part), std::string::npos) << "expected '" << (part) << "' in:\n" << (text)

TEST_F(Frames, BadCollectionsAndTimesExitTwoWithAMessage) {
    const std::string scene = "camera: {width: 8, height: 8}\n"
                              "isosurfaces: [{field: u, value: 0.5}]\n";
    // A step file that does not exist.
    WritePvd(kDir / "missing.pvd", DataSet(0, 0, "ball_0.vtu") + DataSet(1, 0, "nowhere.vtu"));
    std::string out = RenderBad("data: {mesh: missing.pvd}\n" + scene);
    EXPECT_MENTIONS(out, "missing.pvd");
    EXPECT_MENTIONS(out, "<DataSet> 1");
    EXPECT_MENTIONS(out, "no such file");
    EXPECT_MENTIONS(out, "nowhere.vtu");
    // An empty collection.
    WritePvd(kDir / "empty.pvd", "");
    out = RenderBad("data: {mesh: empty.pvd}\n" + scene);
    EXPECT_MENTIONS(out, "empty.pvd");
    EXPECT_MENTIONS(out, "the collection is empty");
    // A timestep that is not a number.
    WritePvd(kDir / "badtime.pvd",
             "    <DataSet timestep=\"0.1x\" part=\"0\" file=\"ball_0.vtu\"/>\n");
    out = RenderBad("data: {mesh: badtime.pvd}\n" + scene);
    EXPECT_MENTIONS(out, "badtime.pvd");
    EXPECT_MENTIONS(out, "timestep=\"0.1x\"");
    EXPECT_MENTIONS(out, "not a finite number");
    // Not a collection at all; malformed XML.
    WriteText(kDir / "notcoll.pvd", "<VTKFile type=\"UnstructuredGrid\"/>\n");
    out = RenderBad("data: {mesh: notcoll.pvd}\n" + scene);
    EXPECT_MENTIONS(out, "is not Collection");
    WriteText(kDir / "broken.pvd", "<VTKFile type=\"Collection\"><Collection>\n");
    out = RenderBad("data: {mesh: broken.pvd}\n" + scene);
    EXPECT_MENTIONS(out, "broken.pvd");
    EXPECT_MENTIONS(out, "malformed XML");
    // A step that is a partition directory.
    fs::create_directories(kDir / "part_dir");
    WritePvd(kDir / "dirs.pvd", DataSet(0, 0, "part_dir"));
    out = RenderBad("data: {mesh: dirs.pvd}\n" + scene);
    EXPECT_MENTIONS(out, "time series of partition directories is not supported");

    // data.time out of range, by index and by value (the message lists the times).
    const std::string series = "data: {mesh: series.pvd}\n" + scene;
    out = RenderBad(series, "--set data.time=3");
    EXPECT_MENTIONS(out, "data.time");
    EXPECT_MENTIONS(out, "step 3 is past the last step");
    EXPECT_MENTIONS(out, "3 time steps: 0 to 2");
    out = RenderBad(series, "--set data.time=0.3");
    EXPECT_MENTIONS(out, "no step of");
    EXPECT_MENTIONS(out, "at time 0.3");
    EXPECT_MENTIONS(out, "0, 0.25, 0.5");
    out = RenderBad(series, "--set data.time=-1");
    EXPECT_MENTIONS(out, "data.time");
    EXPECT_MENTIONS(out, ">= 0");
    out = RenderBad(series, "--set data.time=soon");
    EXPECT_MENTIONS(out, "data.time");
    // ... in frames: checked before anything is rendered or written.
    out = RenderBad(series, "--set frames.time=[1,3]");
    EXPECT_MENTIONS(out, "frames.time");
    EXPECT_MENTIONS(out, "step 3 is past the last step");
    out = RenderBad(series, "--set 'frames={list: [{data.time: 0}, {data.time: 7}]}'");
    EXPECT_MENTIONS(out, "data.time");
    EXPECT_MENTIONS(out, "in frame 1 of frames");
    out = RenderBad(series, "--set 'frames={time: all, count: 5, azimuth: [0, 90]}'");
    EXPECT_MENTIONS(out, "frames.count");
    // data.time or frames.time with data that is not a collection.
    out = RenderBad("data: {mesh: ball_0.vtu, time: 1}\n" + scene);
    EXPECT_MENTIONS(out, "data.time");
    EXPECT_MENTIONS(out, "is not a .pvd collection");
    out = RenderBad("data: {mesh: ball_0.vtu}\n" + scene, "--set frames.time=all");
    EXPECT_MENTIONS(out, "frames.time");
    // Frames that may not change a key, or change an unknown one.
    out = RenderBad(series, "--set 'frames={list: [{output.png: x.png}]}'");
    EXPECT_MENTIONS(out, "frames.list.0.output.png");
    out = RenderBad(series, "--set 'frames={list: [{camera.azimut: 10}]}'");
    EXPECT_MENTIONS(out, "did you mean 'azimuth'");
    out = RenderBad(series, "--set 'frames={count: 3, azimuth: [0, 90]}' "
                            "--set camera.position=[3,3,3]");
    EXPECT_MENTIONS(out, "frames.azimuth");
}

}  // namespace
}  // namespace hpray
