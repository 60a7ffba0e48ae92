// ParaView collections (.pvd): steps ordered by time, parts merged, every file checked
// when the collection is read, and each bad input an InputError naming the .pvd and the
// DataSet.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <set>
#include <string>

#include <unistd.h>

#include "io/mesh_io.h"
#include "io/vtu_writer.h"
#include "mesh/builtin.h"
#include "util/error.h"

namespace hpray {
namespace {

namespace fs = std::filesystem;

class Pvd : public ::testing::Test {
  protected:
    void SetUp() override {
        dir_ = fs::temp_directory_path() / ("hpray_test_pvd_" + std::to_string(getpid()));
        fs::remove_all(dir_);
        fs::create_directories(dir_ / "steps");
        // Two meshes of different size, u shifted per file so each is recognisable.
        for (int k = 0; k < 3; ++k) {
            Mesh mesh = MakeBuiltin("builtin:cube-tets-" + std::to_string(k + 1));
            for (double& u : mesh.pointFields[0].values) u += 100.0 * k;
            WriteVtu((dir_ / "steps" / ("m" + std::to_string(k) + ".vtu")).string(), mesh);
        }
        Mesh noField = MakeBuiltin("builtin:cube-tets-1");
        noField.pointFields.clear();
        WriteVtu((dir_ / "steps" / "nofield.vtu").string(), noField);
    }
    void TearDown() override { fs::remove_all(dir_); }

    /// Writes dir/name with `datasets` in its <Collection>; returns its path.
    std::string Write(const std::string& name, const std::string& datasets) {
        const fs::path path = dir_ / name;
        std::ofstream out(path);
        out << "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\" "
               "byte_order=\"LittleEndian\">\n<Collection>\n"
            << datasets << "</Collection>\n</VTKFile>\n";
        return path.string();
    }

    /// The InputError message of reading `path` (whole collection and first step).
    static std::string ErrorOf(const std::string& path) {
        try {
            ReadMesh(path);
        } catch (const InputError& e) {
            return e.what();
        }
        return "NO ERROR";
    }

    fs::path dir_;
};

#define EXPECT_MENTIONS(text, part) \
    EXPECT_NE((text).find(part), std::string::npos) << "expected '" << (part) << "' in: " << (text)

TEST_F(Pvd, StepsByTimePartsByNumberPathsFromThePvdFolder) {
    const std::string path = Write(
        "c.pvd",
        "<DataSet timestep=\"1.5\" part=\"1\" file=\"steps/m1.vtu\"/>\n"
        "<DataSet timestep=\"0.5\" part=\"0\" file=\"steps/m2.vtu\"/>\n"
        "<DataSet timestep=\" 1.5 \" part=\"0\" file=\"./steps/../steps/m0.vtu\"/>\n"
        "<DataSet timestep=\"1e1\" file=\"" + (dir_ / "steps" / "m0.vtu").string() + "\"/>\n");
    const Collection c = ReadCollection(path);
    ASSERT_EQ(c.steps.size(), 3u);
    EXPECT_EQ(c.steps[0].time, 0.5);
    EXPECT_EQ(c.steps[1].time, 1.5);
    EXPECT_EQ(c.steps[2].time, 10.0);
    const std::string steps = (dir_ / "steps").string();
    EXPECT_EQ(c.steps[0].files, (std::vector<std::string>{steps + "/m2.vtu"}));
    EXPECT_EQ(c.steps[1].files, (std::vector<std::string>{steps + "/m0.vtu", steps + "/m1.vtu"}));
    EXPECT_EQ(c.TimesText(), "0.5, 1.5, 10");
    EXPECT_EQ(c.TimesText(2), "0.5, 1.5, ...");

    // Step 1 is m0 then m1, merged as pieces: points and cells appended, u along.
    const Mesh m0 = MakeBuiltin("builtin:cube-tets-1"), m1 = MakeBuiltin("builtin:cube-tets-2");
    ReadOptions options;
    options.timeStep = 1;
    const Mesh step = ReadMesh(path, options);
    EXPECT_EQ(step.CellCount(), m0.CellCount() + m1.CellCount());
    EXPECT_EQ(step.PointCount(), m0.PointCount() + m1.PointCount());
    const Field* u = step.FindPointField("u");
    ASSERT_NE(u, nullptr);
    EXPECT_EQ(u->values[0], m0.pointFields[0].values[0]);
    EXPECT_EQ(u->values[m0.PointCount()], m1.pointFields[0].values[0] + 100.0);
    EXPECT_EQ(step.connectivity[step.cellOffsets[m0.CellCount()]],
              m1.connectivity[0] + m0.PointCount());
    // The default step is the first (by time): m2.
    EXPECT_EQ(ReadMesh(path).CellCount(), MakeBuiltin("builtin:cube-tets-3").CellCount());
    // A field filter reaches every part.
    options.fields = std::set<std::string>{"nothing"};
    EXPECT_EQ(ErrorOf(path), "NO ERROR");  // the unfiltered read is fine
    EXPECT_THROW(ReadMesh(path, options), InputError);
    // A step past the last.
    options.fields.reset();
    options.timeStep = 3;
    try {
        ReadMesh(path, options);
        ADD_FAILURE() << "no error";
    } catch (const InputError& e) {
        EXPECT_MENTIONS(std::string(e.what()), "has 3 time steps (0 to 2); step 3 does not exist");
    }
}

TEST_F(Pvd, FindTimeWithinATinyToleranceOnly) {
    const Collection c = ReadCollection(Write(
        "t.pvd", "<DataSet timestep=\"0\" file=\"steps/m0.vtu\"/>\n"
                 "<DataSet timestep=\"0.3\" file=\"steps/m1.vtu\"/>\n"
                 "<DataSet timestep=\"0.6\" file=\"steps/m2.vtu\"/>\n"));
    EXPECT_EQ(c.FindTime(0.0), 0);
    EXPECT_EQ(c.FindTime(0.1 + 0.2), 1);  // 0.30000000000000004
    EXPECT_EQ(c.FindTime(0.6), 2);
    EXPECT_EQ(c.FindTime(0.3001), -1);
    EXPECT_EQ(c.FindTime(-0.3), -1);
    EXPECT_EQ(c.FindTime(1.0), -1);
}

TEST_F(Pvd, WithoutTimestepsAllDataSetsArePartsOfOneStep) {
    const Collection c = ReadCollection(
        Write("one.pvd", "<DataSet part=\"0\" file=\"steps/m0.vtu\"/>\n"
                         "<DataSet part=\"1\" file=\"steps/m1.vtu\"/>\n"));
    ASSERT_EQ(c.steps.size(), 1u);
    EXPECT_EQ(c.steps[0].time, 0.0);
    EXPECT_EQ(c.steps[0].files.size(), 2u);
}

TEST_F(Pvd, BadCollectionsNameTheFileAndTheDataSet) {
    struct Case {
        std::string datasets, fragments[3];
    };
    const Case cases[] = {
        {"", {"<Collection>", "the collection is empty", "e.pvd"}},
        {"<DataSet timestep=\"0\" file=\"steps/m0.vtu\"/>\n"
         "<DataSet timestep=\"1\" file=\"steps/gone.vtu\"/>\n",
         {"<DataSet> 1 file=\"steps/gone.vtu\"", "no such file", "steps/gone.vtu"}},
        {"<DataSet timestep=\"soon\" file=\"steps/m0.vtu\"/>\n",
         {"<DataSet> 0 timestep=\"soon\"", "not a finite number", "e.pvd"}},
        {"<DataSet timestep=\"inf\" file=\"steps/m0.vtu\"/>\n",
         {"timestep=\"inf\"", "not a finite number", "e.pvd"}},
        {"<DataSet timestep=\"\" file=\"steps/m0.vtu\"/>\n", {"timestep=\"\"", "not a finite", ""}},
        {"<DataSet timestep=\"0\" file=\"steps/m0.vtu\"/>\n<DataSet file=\"steps/m1.vtu\"/>\n",
         {"<DataSet> 1", "some DataSets have a timestep", ""}},
        {"<DataSet file=\"steps/m0.vtu\"/>\n<DataSet timestep=\"0\" file=\"steps/m1.vtu\"/>\n",
         {"<DataSet> 1", "some DataSets have a timestep", ""}},
        {"<DataSet timestep=\"0\" part=\"2\" file=\"steps/m0.vtu\"/>\n"
         "<DataSet timestep=\"0.0\" part=\"2\" file=\"steps/m1.vtu\"/>\n",
         {"<DataSet> 1", "repeats timestep 0 part 2 of <DataSet> 0", ""}},
        {"<DataSet timestep=\"0\" part=\"-1\" file=\"steps/m0.vtu\"/>\n",
         {"part=\"-1\"", "not an integer >= 0", ""}},
        {"<DataSet timestep=\"0\"/>\n", {"<DataSet> 0", "has no file attribute", ""}},
        {"<DataSet timestep=\"0\" file=\"steps\"/>\n",
         {"<DataSet> 0 file=\"steps\"", "time series of partition directories is not supported", ""}},
        {"<DataSet timestep=\"0\" file=\"e.pvd\"/>\n",
         {"<DataSet> 0", "a collection inside a collection", ""}},
        {"<DataSet timestep=\"0\" file=\"e.pvd.txt\"/>\n", {"no such file", "", ""}},
    };
    for (const Case& c : cases) {
        const std::string e = ErrorOf(Write("e.pvd", c.datasets));
        for (const std::string& fragment : c.fragments) EXPECT_MENTIONS(e, fragment);
    }
    // A file of another format; parts whose fields differ (the part file is named).
    {
        std::ofstream(dir_ / "steps" / "notes.txt") << "x";
        const std::string e = ErrorOf(Write("e.pvd", "<DataSet file=\"steps/notes.txt\"/>\n"));
        EXPECT_MENTIONS(e, "'.txt' is not a mesh format hpray reads");
    }
    {
        const std::string e = ErrorOf(Write(
            "e.pvd", "<DataSet part=\"0\" file=\"steps/m0.vtu\"/>\n"
                     "<DataSet part=\"1\" file=\"steps/nofield.vtu\"/>\n"));
        EXPECT_MENTIONS(e, "nofield.vtu");
        EXPECT_MENTIONS(e, "part 1 of time step 0");
        EXPECT_MENTIONS(e, "different set of point fields");
    }
    // Not a collection, malformed XML, no <Collection>, no file.
    const fs::path raw = dir_ / "raw.pvd";
    std::ofstream(raw) << "<VTKFile type=\"UnstructuredGrid\"><Collection/></VTKFile>";
    EXPECT_MENTIONS(ErrorOf(raw.string()), "type 'UnstructuredGrid' is not Collection");
    std::ofstream(raw) << "<VTKFile type=\"Collection\"><Collection>\n<DataSet";
    EXPECT_MENTIONS(ErrorOf(raw.string()), "malformed XML");
    std::ofstream(raw) << "<VTKFile type=\"Collection\"></VTKFile>";
    EXPECT_MENTIONS(ErrorOf(raw.string()), "has no <Collection> element");
    std::ofstream(raw) << "<Other/>";
    EXPECT_MENTIONS(ErrorOf(raw.string()), "no <VTKFile> root element");
    EXPECT_MENTIONS(ErrorOf((dir_ / "absent.pvd").string()), "absent.pvd: no such file");
}

}  // namespace
}  // namespace hpray
