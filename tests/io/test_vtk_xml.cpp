// Tests of the VTK XML reader (.vtu, .pvtu, .vts) and the .vtu writer: every encoding on
// files with known content, VTK-written fixtures, the real data files, round trips and
// malformed input.
#include <gtest/gtest.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "io/mesh_io.h"
#include "io/raw_vtu.h"
#include "io/vtk_cells.h"
#include "io/vtu_writer.h"
#include "mesh/cell.h"
#include "util/error.h"
#include "util/log.h"

namespace hpray {
namespace {

namespace fs = std::filesystem;

// ---------------------------------------------------------------------------------------
// Small independent helpers: files, base64, typed bytes.

fs::path TempDir() {
    static const fs::path dir = [] {
        fs::path d =
            fs::temp_directory_path() /
            ("hpray_test_vtk_xml_" + std::to_string(static_cast<long>(getpid())));
        fs::create_directories(d);
        return d;
    }();
    return dir;
}

/// Removes the scratch folder when the test binary ends (gtest owns the environment).
class TempDirCleanup : public ::testing::Environment {
  public:
    void TearDown() override {
        std::error_code ec;
        fs::remove_all(TempDir(), ec);
    }
};
const ::testing::Environment* const kCleanup =
    ::testing::AddGlobalTestEnvironment(new TempDirCleanup);

std::string WriteFile(const std::string& name, const std::string& bytes) {
    const std::string path = (TempDir() / name).string();
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    return path;
}

std::string ReadBytes(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    std::ostringstream os;
    os << in.rdbuf();
    return os.str();
}

std::string Base64(const std::string& in) {
    static const char* a =
        "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    std::string out;
    std::size_t i = 0;
    for (; i + 2 < in.size(); i += 3) {
        const unsigned v = (static_cast<unsigned char>(in[i]) << 16) |
                           (static_cast<unsigned char>(in[i + 1]) << 8) |
                           static_cast<unsigned char>(in[i + 2]);
        out += a[v >> 18];
        out += a[(v >> 12) & 63];
        out += a[(v >> 6) & 63];
        out += a[v & 63];
    }
    if (i + 1 == in.size()) {
        const unsigned v = static_cast<unsigned char>(in[i]) << 16;
        out += a[v >> 18];
        out += a[(v >> 12) & 63];
        out += "==";
    } else if (i + 2 == in.size()) {
        const unsigned v = (static_cast<unsigned char>(in[i]) << 16) |
                           (static_cast<unsigned char>(in[i + 1]) << 8);
        out += a[v >> 18];
        out += a[(v >> 12) & 63];
        out += a[(v >> 6) & 63];
        out += '=';
    }
    return out;
}

template <typename T>
void Put(std::string& out, T value, bool bigEndian) {
    char b[sizeof(T)];
    std::memcpy(b, &value, sizeof(T));
    if (bigEndian) std::reverse(b, b + sizeof(T));
    out.append(b, sizeof(T));
}

/// A value as the file's type stores it, read back as double.
double Round(const std::string& type, double v) {
    return type == "Float32" ? static_cast<double>(static_cast<float>(v)) : v;
}

std::string TypedBytes(const std::string& type, const std::vector<double>& values,
                       bool big) {
    std::string out;
    for (double d : values) {
        if (type == "Int8")
            Put(out, static_cast<std::int8_t>(d), big);
        else if (type == "UInt8")
            Put(out, static_cast<std::uint8_t>(d), big);
        else if (type == "Int16")
            Put(out, static_cast<std::int16_t>(d), big);
        else if (type == "UInt16")
            Put(out, static_cast<std::uint16_t>(d), big);
        else if (type == "Int32")
            Put(out, static_cast<std::int32_t>(d), big);
        else if (type == "UInt32")
            Put(out, static_cast<std::uint32_t>(d), big);
        else if (type == "Int64")
            Put(out, static_cast<std::int64_t>(d), big);
        else if (type == "UInt64")
            Put(out, static_cast<std::uint64_t>(d), big);
        else if (type == "Float32")
            Put(out, static_cast<float>(d), big);
        else if (type == "Float64")
            Put(out, d, big);
        else
            ADD_FAILURE() << "type " << type;
    }
    return out;
}

std::string AsciiText(const std::string& type, const std::vector<double>& values) {
    std::ostringstream os;
    os.precision(17);
    for (std::size_t i = 0; i < values.size(); ++i) {
        if (i) os << (i % 6 == 0 ? "\n" : " ");
        const double v = values[i];
        if (type == "UInt64")
            os << static_cast<std::uint64_t>(v);
        else if (type == "Float32" || type == "Float64") {
            if (std::isnan(v))
                os << "nan";
            else
                os << Round(type, v);
        } else
            os << static_cast<std::int64_t>(v);
    }
    return os.str();
}

// ---------------------------------------------------------------------------------------
// A VTU writer for tests, independent of the one under test: any encoding.

enum class Format { Ascii, Binary, AppendedRaw, AppendedBase64 };

struct Encoding {
    std::string label;
    Format format = Format::Ascii;
    bool header64 = false;
    bool zlib = false;
    bool bigEndian = false;
    std::size_t blockSize = 32768;
    bool separateHeader = false;  ///< base64 of the size header encoded on its own
    std::string pointType = "Float64";
    std::string connType = "Int64";
};

struct Arr {
    std::string name;
    std::string type;
    int comps = 1;
    std::vector<double> values;
};

struct Doc {
    std::string version = "2.2";
    std::int64_t nPoints = 0, nCells = 0;
    std::string numberOfPoints;  ///< overrides nPoints in the XML when non-empty
    std::vector<Arr> pointData, cellData;
    Arr points, connectivity, offsets, types;
    std::string cellDataAttributes;
    std::string headerTypeAttribute;  ///< overrides the header_type attribute
    std::string compressorAttribute;  ///< overrides the compressor attribute
};

struct Payload {
    std::string header, data;
};

Payload MakePayload(const std::string& bytes, const Encoding& e) {
    Payload p;
    auto word = [&](std::uint64_t v) {
        if (e.header64)
            Put(p.header, v, e.bigEndian);
        else
            Put(p.header, static_cast<std::uint32_t>(v), e.bigEndian);
    };
    if (!e.zlib) {
        word(bytes.size());
        p.data = bytes;
        return p;
    }
    const std::size_t bs = e.blockSize;
    const std::size_t nb = (bytes.size() + bs - 1) / bs;
    std::vector<std::string> blocks;
    for (std::size_t b = 0; b < nb; ++b) {
        const std::string in = bytes.substr(b * bs, bs);
        uLongf len = compressBound(in.size());
        std::string out(len, '\0');
        compress2(reinterpret_cast<Bytef*>(out.data()), &len,
                  reinterpret_cast<const Bytef*>(in.data()), in.size(), 6);
        out.resize(len);
        blocks.push_back(out);
    }
    word(nb);
    word(bs);
    word(bytes.size() % bs);
    for (const std::string& b : blocks) word(b.size());
    for (const std::string& b : blocks) p.data += b;
    return p;
}

std::string Base64Payload(const Payload& p, const Encoding& e) {
    if (e.zlib || e.separateHeader) return Base64(p.header) + Base64(p.data);
    return Base64(p.header + p.data);
}

std::string BuildVtu(const Doc& d, const Encoding& e) {
    std::string appended;
    auto arrayXml = [&](const Arr& a) {
        std::string x = "<DataArray type=\"" + a.type + "\" Name=\"" + a.name + "\"";
        if (a.comps != 1) x += " NumberOfComponents=\"" + std::to_string(a.comps) + "\"";
        if (e.format == Format::Ascii || a.type == "String")
            return x + " format=\"ascii\">\n" + AsciiText(a.type, a.values) +
                   "\n</DataArray>\n";
        const Payload p = MakePayload(TypedBytes(a.type, a.values, e.bigEndian), e);
        if (e.format == Format::Binary)
            return x + " format=\"binary\">\n" + Base64Payload(p, e) + "\n</DataArray>\n";
        x +=
            " format=\"appended\" offset=\"" + std::to_string(appended.size()) + "\"/>\n";
        appended +=
            e.format == Format::AppendedRaw ? p.header + p.data : Base64Payload(p, e);
        return x;
    };
    std::string x =
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"" +
        d.version + "\" byte_order=\"" + (e.bigEndian ? "BigEndian" : "LittleEndian") +
        "\"";
    if (!d.headerTypeAttribute.empty())
        x += " header_type=\"" + d.headerTypeAttribute + "\"";
    else if (e.header64)
        x += " header_type=\"UInt64\"";  // UInt32 is the default when absent
    if (!d.compressorAttribute.empty())
        x += " compressor=\"" + d.compressorAttribute + "\"";
    else if (e.zlib)
        x += " compressor=\"vtkZLibDataCompressor\"";
    x += ">\n<UnstructuredGrid>\n<Piece NumberOfPoints=\"" +
         (d.numberOfPoints.empty() ? std::to_string(d.nPoints) : d.numberOfPoints) +
         "\" NumberOfCells=\"" + std::to_string(d.nCells) + "\">\n<PointData>\n";
    for (const Arr& a : d.pointData) x += arrayXml(a);
    x += "</PointData>\n<CellData" + d.cellDataAttributes + ">\n";
    for (const Arr& a : d.cellData) x += arrayXml(a);
    x += "</CellData>\n<Points>\n" + arrayXml(d.points) + "</Points>\n<Cells>\n";
    x += arrayXml(d.connectivity) + arrayXml(d.offsets) + arrayXml(d.types);
    x += "</Cells>\n</Piece>\n</UnstructuredGrid>\n";
    if (e.format == Format::AppendedRaw || e.format == Format::AppendedBase64)
        x += std::string("<AppendedData encoding=\"") +
             (e.format == Format::AppendedRaw ? "raw" : "base64") + "\">\n   _" +
             appended + "\n</AppendedData>\n";
    x += "</VTKFile>\n";
    return x;
}

// ---------------------------------------------------------------------------------------
// The known content: a linear hex, a triangle (skipped), a tet and a voxel. Cell c's VTK
// node with parametric coordinates (r, s, t) sits at Geometry(c, r, s, t), so a correctly
// ordered internal node with reference coordinates (r, s, t) must sit there as well.

std::array<double, 3> Geometry(int cell, double r, double s, double t) {
    return {r + 0.25 * s + 5.0 * cell, s - 0.125 * t, t + 0.5 * r};
}

const char* kPointFieldTypes[] = {"Int8",   "UInt8", "Int16",  "UInt16",  "Int32",
                                  "UInt32", "Int64", "UInt64", "Float32", "Float64"};

double PointFieldValue(const std::string& type, int i) {
    if (type == "Int8") return i * 7 - 60;
    if (type == "UInt8") return i * 12;
    if (type == "Int16") return i * 1000 - 9000;
    if (type == "UInt16") return i * 3000;
    if (type == "Int32") return i * 100000000.0 - 1e9;
    if (type == "UInt32") return i * 200000000.0;
    if (type == "Int64") return i * std::ldexp(1.0, 40) - std::ldexp(1.0, 44);
    if (type == "UInt64") return i * std::ldexp(1.0, 59);
    if (type == "Float32") return i * 0.1 + 1.0 / 3.0;
    return std::sin(i) * 1e3;
}

constexpr int kSynthPoints = 20;
// VTK parametric coordinates of VTK_HEXAHEDRON / VTK_TETRA / VTK_VOXEL nodes.
const double kHexParam[8][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0},
                                {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};
const double kTetParam[4][3] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
const double kVoxelParam[8][3] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0},
                                  {0, 0, 1}, {1, 0, 1}, {0, 1, 1}, {1, 1, 1}};

Doc SyntheticDoc(const Encoding& e) {
    Doc d;
    d.nPoints = kSynthPoints;
    d.nCells = 4;
    // Output cell 0 = file cell 0 (hex), 1 = file cell 2 (tet), 2 = file cell 3 (voxel).
    std::vector<double> xyz;
    for (const auto& p : kHexParam)
        for (double v : Geometry(0, p[0], p[1], p[2])) xyz.push_back(v);
    for (const auto& p : kTetParam)
        for (double v : Geometry(1, p[0], p[1], p[2])) xyz.push_back(v);
    for (const auto& p : kVoxelParam)
        for (double v : Geometry(2, p[0], p[1], p[2])) xyz.push_back(v);
    d.points = {"Points", e.pointType, 3, xyz};
    d.connectivity = {"connectivity", e.connType, 1, {}};
    for (int i = 0; i < 8; ++i) d.connectivity.values.push_back(i);
    for (int i : {0, 1, 2}) d.connectivity.values.push_back(i);  // triangle
    for (int i = 8; i < 20; ++i) d.connectivity.values.push_back(i);
    d.offsets = {"offsets", e.connType, 1, {8, 11, 15, 23}};
    d.types = {"types", "UInt8", 1, {12, 5, 10, 11}};
    for (const char* type : kPointFieldTypes) {
        Arr a{type, type, 1, {}};
        for (int i = 0; i < kSynthPoints; ++i)
            a.values.push_back(PointFieldValue(type, i));
        d.pointData.push_back(a);
    }
    Arr vec{"vec", "Float64", 3, {}};
    for (int i = 0; i < kSynthPoints; ++i)
        for (double v : {i + 0.5, 2.0 * i + 0.5, -i + 0.5}) vec.values.push_back(v);
    d.pointData.push_back(vec);
    d.cellData.push_back({"cid", "Int32", 1, {10, 11, 12, 13}});
    d.cellData.push_back({"cvec", "Float32", 2, {0, 0, 1, -1, 2, -2, 3, -3}});
    d.cellData.push_back({"vtkGhostType", "UInt8", 1, {0, 1, 0, 1}});
    return d;
}

std::string Basename(const std::string& path) {
    return fs::path(path).filename().string();
}

/// Runs `read` and expects an InputError whose message names the file and contains every
/// string of `parts`.
void ExpectInputError(const std::string& path, const std::vector<std::string>& parts,
                      const ReadOptions& options = {}) {
    try {
        const Mesh m = ReadVtkXml(path, options);
        ADD_FAILURE() << "no error reading " << path;
    } catch (const InputError& e) {
        const std::string msg = e.what();
        EXPECT_NE(msg.find(Basename(path)), std::string::npos) << msg;
        for (const std::string& p : parts)
            EXPECT_NE(msg.find(p), std::string::npos) << "'" << p << "' not in: " << msg;
    } catch (const std::exception& e) {
        ADD_FAILURE() << "wrong exception type: " << e.what();
    }
}

/// Every node of cell c (internal order) sits at geometry(reference coordinates).
template <typename G>
void ExpectCellGeometry(const Mesh& m, std::int64_t c, G geometry, double tol) {
    const auto& lattice = LatticeNodes(m.cellShape[c], m.cellOrder[c], m.cellFamily[c]);
    ASSERT_EQ(static_cast<int>(lattice.size()), m.CellNodeCount(c)) << "cell " << c;
    for (std::size_t n = 0; n < lattice.size(); ++n) {
        const auto ref = LatticeRefCoords(m.cellShape[c], m.cellOrder[c], lattice[n]);
        const std::array<double, 3> want = geometry(ref[0], ref[1], ref[2]);
        const std::int64_t p = m.CellNodes(c)[n];
        for (int a = 0; a < 3; ++a)
            ASSERT_NEAR(m.points[3 * p + a], want[a], tol)
                << "cell " << c << " node " << n << " axis " << a;
    }
}

void ExpectSynthetic(const Mesh& m, const Encoding& e) {
    ASSERT_EQ(m.PointCount(), kSynthPoints);
    ASSERT_EQ(m.CellCount(), 3);  // the triangle is skipped
    const CellShape shapes[] = {CellShape::Hex, CellShape::Tet, CellShape::Hex};
    const int fileCell[] = {0, 1, 2};
    for (int c = 0; c < 3; ++c) {
        EXPECT_EQ(m.cellShape[c], shapes[c]);
        EXPECT_EQ(m.cellOrder[c], 1);
        EXPECT_EQ(m.cellFamily[c], CellFamily::Lagrange);
        ExpectCellGeometry(
            m, c,
            [&](double r, double s, double t) {
                auto g = Geometry(fileCell[c], r, s, t);
                for (double& v : g) v = Round(e.pointType, v);
                return g;
            },
            0.0);
    }
    ASSERT_EQ(m.pointFields.size(), std::size(kPointFieldTypes) + 1);
    for (const char* type : kPointFieldTypes) {
        const Field* f = m.FindPointField(type);
        ASSERT_NE(f, nullptr) << type;
        EXPECT_EQ(f->components, 1);
        ASSERT_EQ(f->values.size(), static_cast<std::size_t>(kSynthPoints));
        for (int i = 0; i < kSynthPoints; ++i)
            EXPECT_EQ(f->values[i], Round(type, PointFieldValue(type, i)))
                << type << " " << i;
    }
    const Field* vec = m.FindPointField("vec");
    ASSERT_NE(vec, nullptr);
    EXPECT_EQ(vec->components, 3);
    for (int i = 0; i < kSynthPoints; ++i) {
        EXPECT_EQ(vec->values[3 * i], i + 0.5);
        EXPECT_EQ(vec->values[3 * i + 1], 2.0 * i + 0.5);
        EXPECT_EQ(vec->values[3 * i + 2], -i + 0.5);
    }
    ASSERT_EQ(m.cellFields.size(), 2u);  // vtkGhostType is not a field
    const Field* cid = m.FindCellField("cid");
    ASSERT_NE(cid, nullptr);
    EXPECT_EQ(cid->values, (std::vector<double>{10, 12, 13}));
    const Field* cvec = m.FindCellField("cvec");
    ASSERT_NE(cvec, nullptr);
    EXPECT_EQ(cvec->components, 2);
    EXPECT_EQ(cvec->values, (std::vector<double>{0, 0, 2, -2, 3, -3}));
    EXPECT_EQ(m.ghost, (std::vector<std::uint8_t>{0, 0, 1}));
}

std::vector<Encoding> AllEncodings() {
    std::vector<Encoding> v;
    auto add = [&](std::string label, Format f, bool h64, bool z, bool big,
                   std::size_t bs, bool sep, std::string pt, std::string ct) {
        Encoding e;
        e.label = label;
        e.format = f;
        e.header64 = h64;
        e.zlib = z;
        e.bigEndian = big;
        e.blockSize = bs;
        e.separateHeader = sep;
        e.pointType = pt;
        e.connType = ct;
        v.push_back(e);
    };
    add("ascii", Format::Ascii, false, false, false, 0, false, "Float64", "Int64");
    add("ascii_f32", Format::Ascii, false, false, false, 0, false, "Float32", "Int32");
    add("binary_u32", Format::Binary, false, false, false, 0, false, "Float32", "Int32");
    add("binary_u64_sep", Format::Binary, true, false, false, 0, true, "Float64",
        "Int64");
    add("binary_u32_zlib", Format::Binary, false, true, false, 64, false, "Float64",
        "UInt32");
    add("binary_u64_zlib", Format::Binary, true, true, false, 1 << 20, false, "Float32",
        "Int64");
    add("raw_u32", Format::AppendedRaw, false, false, false, 0, false, "Float64",
        "Int32");
    add("raw_u64_zlib", Format::AppendedRaw, true, true, false, 64, false, "Float32",
        "Int64");
    add("raw_u32_zlib_odd", Format::AppendedRaw, false, true, false, 100, false,
        "Float64", "Int16");
    add("b64_u32", Format::AppendedBase64, false, false, false, 0, false, "Float64",
        "UInt64");
    add("b64_u64_zlib", Format::AppendedBase64, true, true, false, 100, false, "Float32",
        "Int32");
    add("big_raw_u64_zlib", Format::AppendedRaw, true, true, true, 64, false, "Float64",
        "Int64");
    add("big_binary_u32", Format::Binary, false, false, true, 0, false, "Float32",
        "UInt16");
    add("big_b64_u32_zlib", Format::AppendedBase64, false, true, true, 40, false,
        "Float64", "Int32");
    return v;
}

Encoding Enc(Format f, bool zlib = false, bool header64 = false) {
    Encoding e;
    e.label = "x";
    e.format = f;
    e.zlib = zlib;
    e.header64 = header64;
    e.blockSize = 64;
    return e;
}

class EncodingTest : public ::testing::TestWithParam<Encoding> {};

TEST_P(EncodingTest, ReadsKnownContent) {
    const Encoding& e = GetParam();
    const std::string path =
        WriteFile("xml_" + e.label + ".vtu", BuildVtu(SyntheticDoc(e), e));
    const Mesh m = ReadVtkXml(path, {});
    ExpectSynthetic(m, e);
}

TEST_P(EncodingTest, ReadsThroughReadMesh) {
    const Encoding& e = GetParam();
    const std::string path =
        WriteFile("xml_rm_" + e.label + ".vtu", BuildVtu(SyntheticDoc(e), e));
    ExpectSynthetic(ReadMesh(path), e);
}

TEST_P(EncodingTest, HugeNumberOfPointsRejectedBeforeAllocating) {
    const Encoding& e = GetParam();
    Doc d = SyntheticDoc(e);
    d.numberOfPoints = "1000000000000";
    const std::string path = WriteFile("xml_huge_" + e.label + ".vtu", BuildVtu(d, e));
    ExpectInputError(path, {"<DataArray Name=\"Points\">", "expected"});
}

TEST_P(EncodingTest, WrongPointCountRejected) {
    const Encoding& e = GetParam();
    Doc d = SyntheticDoc(e);
    d.numberOfPoints = "21";
    const std::string path = WriteFile("xml_wrongn_" + e.label + ".vtu", BuildVtu(d, e));
    ExpectInputError(path, {"<DataArray Name=\"Points\">", "21"});
}

TEST_P(EncodingTest, TruncatedFileRejected) {
    const Encoding& e = GetParam();
    const std::string full = BuildVtu(SyntheticDoc(e), e);
    for (double fraction : {0.3, 0.6, 0.9, 0.99}) {
        const std::string path =
            WriteFile("xml_trunc_" + e.label + ".vtu",
                      full.substr(0, static_cast<std::size_t>(full.size() * fraction)));
        ExpectInputError(path, {});
    }
}

INSTANTIATE_TEST_SUITE_P(AllEncodings, EncodingTest, ::testing::ValuesIn(AllEncodings()),
                         [](const auto& info) { return info.param.label; });

// Seeded random corruption of every encoding: reads either succeed or throw InputError
// (never crash, hang or throw anything else).
TEST(VtkXmlFuzz, CorruptedFilesGiveInputErrorOrAMesh) {
    const log::Level level = log::GetLevel();
    log::SetLevel(log::Level::Error);  // skipped-cell warnings of the mutants
    for (const Encoding& e : AllEncodings()) {
        const std::string full = BuildVtu(SyntheticDoc(e), e);
        for (int i = 0; i < 60; ++i) {
            std::mt19937 rng(1000 * i + static_cast<unsigned>(e.label.size()));
            std::string bytes = full;
            const int edits = 1 + static_cast<int>(rng() % 4);
            for (int k = 0; k < edits; ++k) {
                const std::size_t at = rng() % bytes.size();
                switch (rng() % 4) {
                    case 0:
                        bytes[at] = static_cast<char>(rng());
                        break;
                    case 1:
                        bytes[at] = "0123456789<>\"_=/ "[rng() % 17];
                        break;
                    case 2:
                        bytes.erase(at, 1 + rng() % 16);
                        break;
                    case 3:
                        bytes.resize(at);
                        break;
                }
                if (bytes.empty()) bytes = "x";
            }
            const std::string path = WriteFile("xml_fuzz.vtu", bytes);
            try {
                const Mesh m = ReadVtkXml(path, {});
                EXPECT_NO_THROW(m.Validate(path));
            } catch (const InputError& err) {
                EXPECT_NE(std::string(err.what()).find("xml_fuzz.vtu"), std::string::npos)
                    << err.what();
            } catch (const std::exception& err) {
                ADD_FAILURE() << e.label << " mutation " << i << ": " << err.what();
            }
        }
    }
    log::SetLevel(level);
}

TEST(VtkXmlWarnings, SkippedCellsAreCountedInOneWarning) {
    Encoding e = Enc(Format::Ascii);
    Doc d = SyntheticDoc(e);
    // Two more faces: a quad (9) and a Lagrange triangle (69) after the voxel.
    d.nCells = 6;
    for (int i : {8, 9, 10, 11, 0, 1, 2}) d.connectivity.values.push_back(i);
    d.offsets.values.push_back(27);
    d.offsets.values.push_back(30);
    d.types.values.push_back(9);
    d.types.values.push_back(69);
    d.cellData[0].values = {10, 11, 12, 13, 14, 15};
    d.cellData[1].values = {0, 0, 1, -1, 2, -2, 3, -3, 4, -4, 5, -5};
    d.cellData[2].values = {0, 1, 0, 1, 1, 1};
    const std::string path = WriteFile("xml_faces.vtu", BuildVtu(d, e));
    ::testing::internal::CaptureStderr();
    const Mesh m = ReadVtkXml(path, {});
    const std::string err = ::testing::internal::GetCapturedStderr();
    EXPECT_NE(err.find("skipped 3 cells"), std::string::npos) << err;
    EXPECT_EQ(err.find("skipped", err.find("skipped") + 1), std::string::npos) << err;
    ExpectSynthetic(m, e);  // cell data filtered consistently with the cells
}

// ---------------------------------------------------------------------------------------
// Specific malformed inputs.

std::string Replace(std::string s, const std::string& from, const std::string& to) {
    const auto at = s.find(from);
    EXPECT_NE(at, std::string::npos) << from;
    if (at != std::string::npos) s.replace(at, from.size(), to);
    return s;
}

TEST(VtkXmlErrors, AppendedOffsetBeyondEnd) {
    const Encoding e = Enc(Format::AppendedRaw);
    std::string text = BuildVtu(SyntheticDoc(e), e);
    text = Replace(text, "Name=\"cid\" format=\"appended\" offset=\"",
                   "Name=\"cid\" format=\"appended\" offset=\"99999999");
    ExpectInputError(WriteFile("xml_badoffset.vtu", text),
                     {"<DataArray Name=\"cid\">", "beyond the end"});
}

TEST(VtkXmlErrors, BadBase64Character) {
    const Encoding e = Enc(Format::Binary);
    std::string text = BuildVtu(SyntheticDoc(e), e);
    const std::size_t tag = text.find("Name=\"Float64\" format=\"binary\">\n");
    ASSERT_NE(tag, std::string::npos);
    const std::size_t at = text.find('\n', tag) + 5;
    text[at] = '!';
    ExpectInputError(WriteFile("xml_badb64.vtu", text),
                     {"<DataArray Name=\"Float64\">", "invalid base64 character '!'",
                      "byte " + std::to_string(at)});
}

TEST(VtkXmlErrors, ZlibCorruption) {
    const Encoding e = Enc(Format::AppendedRaw, true);
    std::string text = BuildVtu(SyntheticDoc(e), e);
    // The first array (offset 0) is Int8 with 20 bytes: one block; its header is 4 words.
    const std::size_t data = text.find("   _") + 4;
    const std::size_t at = data + 4 * 4 + 6;
    text[at] = static_cast<char>(text[at] ^ 0x5a);
    ExpectInputError(WriteFile("xml_badzlib.vtu", text),
                     {"<DataArray Name=\"Int8\">", "zlib"});
}

// Raw zlib blocks inflate side by side; the error is still the first bad block's, with
// its offset, as when they are inflated in order.
TEST(VtkXmlErrors, ZlibCorruptionNamesTheFirstBadBlock) {
    Encoding e = Enc(Format::AppendedRaw, true);
    e.blockSize = 8;
    std::string text = BuildVtu(SyntheticDoc(e), e);
    // The first array (offset 0) is Int8 with 20 bytes: blocks of 8, 8 and 4 bytes. Its
    // header is 3 + 3 UInt32 words (blocks, block size, last size, compressed sizes).
    const std::size_t data = text.find("   _") + 4;
    std::uint32_t words[6];
    std::memcpy(words, &text[data], sizeof words);
    ASSERT_EQ(words[0], 3u);
    const std::size_t block1 = data + sizeof words + words[3], block2 = block1 + words[4];
    text[block2 + 3] = static_cast<char>(text[block2 + 3] ^ 0x5a);
    text[block1 + 3] = static_cast<char>(text[block1 + 3] ^ 0x5a);
    ExpectInputError(WriteFile("xml_badzlib_blocks.vtu", text),
                     {"<DataArray Name=\"Int8\">", "zlib block 1 of 3",
                      "byte " + std::to_string(block1)});
}

TEST(VtkXmlErrors, ImplausibleCompressedSizeRejected) {
    const Encoding e = Enc(Format::AppendedRaw, true);
    std::string text = BuildVtu(SyntheticDoc(e), e);
    const std::size_t data = text.find("   _") + 4;
    // Claim one 2^31-byte block made from a few compressed bytes.
    const std::uint32_t big = 1u << 31, zero = 0;
    std::memcpy(&text[data + 4], &big, 4);
    std::memcpy(&text[data + 8], &zero, 4);
    ExpectInputError(WriteFile("xml_zbomb.vtu", text), {"<DataArray Name=\"Int8\">"});
}

TEST(VtkXmlErrors, OutOfRangeConnectivity) {
    const Encoding e = Enc(Format::Ascii);
    Doc d = SyntheticDoc(e);
    d.connectivity.values[13] = kSynthPoints;
    ExpectInputError(
        WriteFile("xml_badconn.vtu", BuildVtu(d, e)),
        {"<DataArray Name=\"connectivity\">", "cell 2", "point 20", "outside"});
    d.connectivity.values[13] = -1;
    ExpectInputError(WriteFile("xml_badconn.vtu", BuildVtu(d, e)),
                     {"cell 2", "point -1"});
}

TEST(VtkXmlErrors, UnknownCellTypeNamesCellAndType) {
    const Encoding e = Enc(Format::AppendedRaw, true);
    Doc d = SyntheticDoc(e);
    d.types.values[3] = 200;
    ExpectInputError(WriteFile("xml_badtype.vtu", BuildVtu(d, e)),
                     {"cell 3", "type 200"});
    d.types.values[3] = 42;  // polyhedron: 3-D but unsupported
    ExpectInputError(WriteFile("xml_polyhedron.vtu", BuildVtu(d, e)),
                     {"cell 3", "type 42"});
}

TEST(VtkXmlErrors, WrongNodeCountForType) {
    const Encoding e = Enc(Format::Ascii);
    Doc d = SyntheticDoc(e);
    d.types.values[2] = 12;  // a hexahedron with 4 nodes
    ExpectInputError(WriteFile("xml_badcount.vtu", BuildVtu(d, e)),
                     {"cell 2", "type 12"});
}

TEST(VtkXmlErrors, NanAndInfInPointsAndFields) {
    for (Format f : {Format::Ascii, Format::AppendedRaw}) {
        const Encoding e = Enc(f, f == Format::AppendedRaw);
        Doc d = SyntheticDoc(e);
        d.points.values[3 * 5 + 1] = std::nan("");
        ExpectInputError(WriteFile("xml_nanpoint.vtu", BuildVtu(d, e)),
                         {"point 5", "NaN"});
        d = SyntheticDoc(e);
        d.pointData[9].values[7] = HUGE_VAL;  // the Float64 field
        if (f == Format::Ascii) d.pointData[9].values[7] = std::nan("");
        ExpectInputError(WriteFile("xml_nanfield.vtu", BuildVtu(d, e)),
                         {"'Float64'", "entry 7"});
        d = SyntheticDoc(e);
        d.cellData[1].values[4] = -HUGE_VAL;  // cvec of file cell 2 = output cell 1
        if (f == Format::Ascii) d.cellData[1].values[4] = std::nan("");
        ExpectInputError(WriteFile("xml_nancell.vtu", BuildVtu(d, e)),
                         {"'cvec'", "entry 1"});
    }
}

TEST(VtkXmlErrors, OffsetsMustNotDecrease) {
    const Encoding e = Enc(Format::Ascii);
    Doc d = SyntheticDoc(e);
    d.offsets.values = {8, 11, 9, 23};
    ExpectInputError(WriteFile("xml_badoffsets.vtu", BuildVtu(d, e)),
                     {"<DataArray Name=\"offsets\">", "cell 2"});
}

TEST(VtkXmlErrors, AsciiGarbageAndRange) {
    const Encoding e = Enc(Format::Ascii);
    std::string text = BuildVtu(SyntheticDoc(e), e);
    ExpectInputError(WriteFile("xml_asciibad.vtu", Replace(text, "-60 -53", "-60 abc")),
                     {"<DataArray Name=\"Int8\">", "'abc'"});
    ExpectInputError(WriteFile("xml_asciirange.vtu", Replace(text, "-60 -53", "-60 300")),
                     {"<DataArray Name=\"Int8\">", "out of range"});
}

TEST(VtkXmlErrors, UnsupportedHeaderAttributes) {
    const Encoding e = Enc(Format::AppendedRaw);
    Doc d = SyntheticDoc(e);
    d.headerTypeAttribute = "UInt16";
    ExpectInputError(WriteFile("xml_badheader.vtu", BuildVtu(d, e)), {"header_type"});
    d = SyntheticDoc(e);
    d.compressorAttribute = "vtkLZ4DataCompressor";
    ExpectInputError(WriteFile("xml_lz4.vtu", BuildVtu(d, e)), {"vtkLZ4DataCompressor"});
    std::string text = BuildVtu(SyntheticDoc(e), e);
    ExpectInputError(
        WriteFile("xml_badorder.vtu", Replace(text, "LittleEndian", "MiddleEndian")),
        {"byte_order"});
    ExpectInputError(WriteFile("xml_badformat.vtu",
                               Replace(text, "format=\"appended\"", "format=\"zipped\"")),
                     {"zipped"});
    ExpectInputError(WriteFile("xml_notvtk.vtu", "<?xml version=\"1.0\"?><Foo/>"),
                     {"<Foo>"});
    ExpectInputError(WriteFile("xml_empty.vtu", ""), {});
    ExpectInputError(
        WriteFile("xml_badtype2.vtu",
                  Replace(text, "type=\"UnstructuredGrid\"", "type=\"ImageData\"")),
        {"ImageData"});
    ExpectInputError(WriteFile("xml_nounderscore.vtu", Replace(text, "   _", "   ")),
                     {"'_'"});
    ExpectInputError(WriteFile("xml_missingcells.vtu",
                               Replace(text, "Name=\"types\"", "Name=\"typos\"")),
                     {"types"});
}

TEST(VtkXmlErrors, MissingFile) {
    ExpectInputError((TempDir() / "xml_does_not_exist.vtu").string(), {"cannot open"});
}

// ---------------------------------------------------------------------------------------
// Field selection.

TEST(VtkXmlFields, OnlyRequestedFieldsAreLoaded) {
    const Encoding e = Enc(Format::AppendedRaw, true);
    const std::string path = WriteFile("xml_fields.vtu", BuildVtu(SyntheticDoc(e), e));
    ReadOptions options;
    options.fields = std::set<std::string>{"vec.y", "cid"};
    const Mesh m = ReadVtkXml(path, options);
    ASSERT_EQ(m.pointFields.size(), 1u);
    EXPECT_EQ(m.pointFields[0].name, "vec");
    EXPECT_EQ(m.pointFields[0].components, 3);
    ASSERT_EQ(m.cellFields.size(), 1u);
    EXPECT_EQ(m.cellFields[0].name, "cid");
    EXPECT_EQ(m.ghost, (std::vector<std::uint8_t>{0, 0, 1}));  // structural, always read

    options.fields = std::set<std::string>{"vec[2]", "Int8"};
    const Mesh m2 = ReadVtkXml(path, options);
    ASSERT_EQ(m2.pointFields.size(), 2u);
    EXPECT_EQ(m2.cellFields.size(), 0u);

    options.fields = std::set<std::string>{};
    EXPECT_EQ(ReadVtkXml(path, options).pointFields.size(), 0u);
}

TEST(VtkXmlFields, MissingRequestedFieldListsAvailable) {
    const Encoding e = Enc(Format::Binary);
    const std::string path =
        WriteFile("xml_missingfield.vtu", BuildVtu(SyntheticDoc(e), e));
    ReadOptions options;
    options.fields = std::set<std::string>{"pressure"};
    ExpectInputError(path, {"'pressure'", "available", "Float64", "vec", "cid"}, options);
}

TEST(VtkXmlFields, NonNumericArraysAreSkipped) {
    const Encoding e = Enc(Format::AppendedRaw);
    Doc d = SyntheticDoc(e);
    std::string text = BuildVtu(d, e);
    text =
        Replace(text, "<PointData>\n",
                "<PointData>\n<DataArray type=\"String\" Name=\"label\" format=\"ascii\">"
                "104 105 0</DataArray>\n");
    const Mesh m = ReadVtkXml(WriteFile("xml_string.vtu", text), {});
    EXPECT_EQ(m.FindField("label"), nullptr);
    ExpectSynthetic(m, e);
}

TEST(VtkXmlFields, OffsetsWithLeadingZeroAccepted) {
    const Encoding e = Enc(Format::Ascii);
    Doc d = SyntheticDoc(e);
    d.offsets.values.insert(d.offsets.values.begin(), 0);
    ExpectSynthetic(ReadVtkXml(WriteFile("xml_offsets0.vtu", BuildVtu(d, e)), {}), e);
}

// ---------------------------------------------------------------------------------------
// Fixtures written by VTK itself (scripts/gen_xml_fixtures.py): closed-form content.

std::string TestData(const std::string& name) {
    return std::string(HPRAY_TEST_DATA) + "/" + name;
}

double F(double x, double y, double z) { return x + 2 * y + 3 * z; }

std::array<double, 3> Mapped(double r, double s, double t, int c) {
    return {r + 0.1 * s * s + 2 * c, s + 0.1 * t * r, t + 0.05 * r * s * t};
}

void ExpectVtkLagrangeFixture(const Mesh& m, double tol) {
    ASSERT_EQ(m.CellCount(), 4);
    EXPECT_EQ(m.PointCount(), 27 + 64 + 20 + 18);
    const CellShape shapes[] = {CellShape::Hex, CellShape::Hex, CellShape::Tet,
                                CellShape::Wedge};
    const int orders[] = {2, 3, 3, 2};
    for (int c = 0; c < 4; ++c) {
        EXPECT_EQ(m.cellShape[c], shapes[c]) << c;
        EXPECT_EQ(m.cellOrder[c], orders[c]) << c;
        EXPECT_EQ(m.cellFamily[c], CellFamily::Lagrange);
        ExpectCellGeometry(
            m, c, [&](double r, double s, double t) { return Mapped(r, s, t, c); }, tol);
    }
    const Field* f = m.FindPointField("f");
    ASSERT_NE(f, nullptr);
    for (std::int64_t p = 0; p < m.PointCount(); ++p)
        EXPECT_NEAR(f->values[p],
                    F(m.points[3 * p], m.points[3 * p + 1], m.points[3 * p + 2]),
                    1e-12 + 10 * tol);
    const Field* cid = m.FindCellField("cid");
    ASSERT_NE(cid, nullptr);
    EXPECT_EQ(cid->values, (std::vector<double>{0, 1, 2, 3}));
    EXPECT_EQ(m.FindField("HigherOrderDegrees"), nullptr);
}

TEST(VtkXmlFixtures, LagrangeCellsWrittenByVtk) {
    const Mesh m = ReadVtkXml(TestData("xml_vtk_lagrange.vtu"), {});
    ExpectVtkLagrangeFixture(m, 1e-14);
}

TEST(VtkXmlFixtures, DegreesArrayNamedByTheCellDataAttribute) {
    // VTK identifies the degrees by the attribute; rename the array and point at it.
    std::string bytes = ReadBytes(TestData("xml_vtk_lagrange.vtu"));
    bytes = Replace(bytes, "HigherOrderDegrees=\"HigherOrderDegrees\"",
                    "HigherOrderDegrees=\"OrderOfCell\"");
    bytes = Replace(bytes, "Name=\"HigherOrderDegrees\"", "Name=\"OrderOfCell\"");
    const Mesh m = ReadVtkXml(WriteFile("xml_degrees_renamed.vtu", bytes), {});
    ExpectVtkLagrangeFixture(m, 1e-14);
    EXPECT_EQ(m.FindField("OrderOfCell"), nullptr);
    // Degrees that contradict the node count are an error naming the cell: set cell 0
    // (27 nodes) to degree 3. The array is appended raw Int32 after a UInt32 size.
    bytes = ReadBytes(TestData("xml_vtk_lagrange.vtu"));
    const std::size_t tag = bytes.find("Name=\"HigherOrderDegrees\"");
    ASSERT_NE(tag, std::string::npos);
    const std::size_t off = bytes.find("offset=\"", tag) + 8;
    const std::size_t data = bytes.find('_', bytes.find("<AppendedData")) + 1;
    const std::size_t at = data + std::stoul(bytes.substr(off, 20)) + 4;
    for (int k = 0; k < 3; ++k) {
        const std::int32_t three = 3;
        std::memcpy(&bytes[at + 4 * k], &three, 4);
    }
    ExpectInputError(WriteFile("xml_degrees_wrong.vtu", bytes), {"cell 0", "type 72"});
}

TEST(VtkXmlFixtures, BigEndianZlibWrittenByVtk) {
    const Mesh m = ReadVtkXml(TestData("xml_vtk_bigendian.vtu"), {});
    ExpectVtkLagrangeFixture(m, 1e-6);  // Float32 points
    auto values = [&](const char* name) {
        const Field* f = m.FindCellField(name);
        EXPECT_NE(f, nullptr) << name;
        return f ? f->values : std::vector<double>{};
    };
    const double t40 = std::ldexp(1.0, 40);
    EXPECT_EQ(values("i8"), (std::vector<double>{-1, -2, -3, -4}));
    EXPECT_EQ(values("u16"), (std::vector<double>{0, 1000, 2000, 3000}));
    EXPECT_EQ(values("i64"), (std::vector<double>{0, -t40, -2 * t40, -3 * t40}));
    EXPECT_EQ(values("u32"), (std::vector<double>{0, 7, 14, 21}));
}

std::array<double, 3> GridPoint(int i, int j, int k) {
    return {i + 0.1 * std::sin(j), 0.5 * j + 0.05 * k, 0.25 * k + 0.02 * i * j};
}

TEST(VtkXmlFixtures, StructuredGridWrittenByVtk) {
    const Mesh m = ReadVtkXml(TestData("xml_vtk_grid.vts"), {});
    ASSERT_EQ(m.PointCount(), 4 * 3 * 5);
    ASSERT_EQ(m.CellCount(), 3 * 2 * 4);
    const Field* cid = m.FindCellField("cid");
    ASSERT_NE(cid, nullptr);
    int c = 0;
    for (int k = 0; k < 4; ++k)
        for (int j = 0; j < 2; ++j)
            for (int i = 0; i < 3; ++i, ++c) {
                EXPECT_EQ(m.cellShape[c], CellShape::Hex);
                EXPECT_EQ(m.cellOrder[c], 1);
                EXPECT_EQ(cid->values[c], c);
                // A linear hex's node at reference (r, s, t) in {0,1}^3 is grid point
                // (i + r, j + s, k + t).
                ExpectCellGeometry(
                    m, c,
                    [&](double r, double s, double t) {
                        return GridPoint(i + static_cast<int>(r), j + static_cast<int>(s),
                                         k + static_cast<int>(t));
                    },
                    1e-14);
            }
    const Field* f = m.FindPointField("f");
    const Field* g = m.FindPointField("g");
    ASSERT_NE(f, nullptr);
    ASSERT_NE(g, nullptr);
    EXPECT_EQ(g->components, 3);
    for (std::int64_t p = 0; p < m.PointCount(); ++p) {
        const double* x = &m.points[3 * p];
        EXPECT_NEAR(f->values[p], F(x[0], x[1], x[2]), 1e-12);
        for (int a = 0; a < 3; ++a)
            EXPECT_EQ(g->values[3 * p + a], Round("Float32", 2 * x[a]));
    }
}

TEST(VtkXmlFixtures, ParallelPiecesConcatenated) {
    const Mesh m = ReadVtkXml(TestData("xml_vtk_pieces.pvtu"), {});
    ASSERT_EQ(m.PointCount(), 12 + 8);
    ASSERT_EQ(m.CellCount(), 3);
    const double x0[] = {0, 1, 3};
    for (int c = 0; c < 3; ++c)
        ExpectCellGeometry(
            m, c,
            [&](double r, double s, double t) {
                return std::array<double, 3>{x0[c] + r, s, t};
            },
            0.0);
    EXPECT_EQ(m.FindCellField("cid")->values, (std::vector<double>{0, 1, 10}));
    const Field* f = m.FindPointField("f");
    ASSERT_NE(f, nullptr);
    for (std::int64_t p = 0; p < m.PointCount(); ++p)
        EXPECT_EQ(f->values[p],
                  F(m.points[3 * p], m.points[3 * p + 1], m.points[3 * p + 2]));
}

TEST(VtkXmlFixtures, ParallelIndexErrorsNameThePiece) {
    const std::string index = ReadBytes(TestData("xml_vtk_pieces.pvtu"));
    const fs::path dir = TempDir() / "pvtu";
    fs::create_directories(dir);
    for (const char* piece : {"xml_vtk_pieces_0.vtu", "xml_vtk_pieces_1.vtu"})
        fs::copy_file(TestData(piece), dir / piece, fs::copy_options::overwrite_existing);
    {
        std::ofstream(dir / "missing.pvtu")
            << Replace(index, "xml_vtk_pieces_1.vtu", "xml_vtk_pieces_7.vtu");
    }
    ExpectInputError((dir / "missing.pvtu").string(),
                     {"<Piece> 1", "xml_vtk_pieces_7.vtu"});
    // A piece whose fields differ from the first one.
    const std::string piece1 = ReadBytes(TestData("xml_vtk_pieces_1.vtu"));
    {
        std::ofstream(dir / "xml_vtk_pieces_1.vtu")
            << Replace(piece1, "Name=\"f\"", "Name=\"h\"");
    }
    { std::ofstream(dir / "ok.pvtu") << index; }
    try {
        ReadVtkXml((dir / "ok.pvtu").string(), {});
        ADD_FAILURE() << "pieces with different fields accepted";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("xml_vtk_pieces_1.vtu"), std::string::npos)
            << e.what();
    }
}

TEST(VtkXmlFixtures, StructuredGridFromTestWriter) {
    // A flat (2-D) grid has no 3-D cells: no cells, a warning, points and fields kept.
    const std::string text =
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"StructuredGrid\" version=\"1.0\">\n"
        "<StructuredGrid WholeExtent=\"0 1 0 1 0 0\"><Piece Extent=\"0 1 0 1 0 0\">\n"
        "<PointData><DataArray type=\"Float64\" Name=\"u\" format=\"ascii\">1 2 3 4"
        "</DataArray></PointData>\n"
        "<Points><DataArray type=\"Float32\" NumberOfComponents=\"3\" format=\"ascii\">"
        "0 0 0 1 0 0 0 1 0 1 1 0</DataArray></Points>\n"
        "</Piece></StructuredGrid></VTKFile>\n";
    const Mesh m = ReadVtkXml(WriteFile("xml_flat.vts", text), {});
    EXPECT_EQ(m.PointCount(), 4);
    EXPECT_EQ(m.CellCount(), 0);
    ASSERT_NE(m.FindPointField("u"), nullptr);
    ExpectInputError(
        WriteFile("xml_badextent.vts", Replace(text, "<Piece Extent=\"0 1 0 1 0 0\"",
                                               "<Piece Extent=\"0 1 0 x 0 0\"")),
        {"Extent"});
    ExpectInputError(WriteFile("xml_hugeextent.vts",
                               Replace(text, "<Piece Extent=\"0 1 0 1 0 0\"",
                                       "<Piece Extent=\"0 100000 0 100000 0 100000\"")),
                     {"<Points>"});
}

// ---------------------------------------------------------------------------------------
// Real data (../shared/data, counts from its README).

std::string Shared(const std::string& name) {
    return std::string(HPRAY_SHARED_DATA) + "/" + name;
}

struct RealFile {
    const char* name;
    std::int64_t points;
    std::map<std::pair<CellShape, int>, std::int64_t> cellsByKind;
    std::vector<std::pair<std::string, int>> pointFields;
    std::vector<std::string> cellFields;
};

std::vector<RealFile> RealFiles() {
    using S = CellShape;
    return {
        {"gmsh_boolean_tet_p4.vtu",
         16460,
         {{{S::Tet, 4}, 1170}},
         {{"analytic", 1}},
         {"region"}},
        {"mfem_escher_tet_p3.vtu",
         103825,
         {{{S::Tet, 3}, 21504}},
         {{"analytic", 1}, {"u", 1}},
         {"attribute"}},
        {"mfem_toroid_wedge_p3.vtu",
         6552,
         {{{S::Wedge, 3}, 384}},
         {{"analytic", 1}, {"u", 1}},
         {"attribute"}},
        {"mfem_toroid_hex_p3.vtu",
         12168,
         {{{S::Hex, 3}, 384}},
         {{"analytic", 1}, {"u", 1}},
         {"attribute"}},
        {"mfem_spiral_hex_p9.vtu",
         6859,
         {{{S::Hex, 9}, 8}},
         {{"analytic", 1}, {"u", 1}},
         {"attribute"}},
        {"mfem_fichera_mixed_p3.vtu",
         1946,
         {{{S::Tet, 3}, 40}, {{S::Hex, 3}, 24}, {{S::Wedge, 3}, 48}},
         {{"analytic", 1}, {"u", 1}},
         {"attribute"}},
        {"mfem_escher_quadtet_p2.vtu",
         117,
         {{{S::Tet, 2}, 42}},
         {{"analytic", 1}},
         {"material"}},
        {"dealii_step65_hex_q3.vtu",
         425984,
         {{{S::Hex, 3}, 6656}},
         {{"solution", 1}, {"material_ids", 1}},
         {}},
        {"dealii_step44_hex_q2.vtu",
         13824,
         {{{S::Hex, 2}, 512}},
         {{"displacement", 3}, {"pressure", 1}, {"dilatation", 1}},
         {}},
        {"mfem_beam_hex_elasticity_p3.vtu",
         16393,
         {{{S::Hex, 3}, 512}},
         {{"displacement", 3}, {"displacement_magnitude", 1}},
         {"attribute"}},
        {"mfem_fichera_mixed16_linear.vtu",
         31841,
         {{{S::Tet, 1}, 50400},
          {{S::Hex, 1}, 4096},
          {{S::Wedge, 1}, 24576},
          {{S::Pyramid, 1}, 11664}},
         {{"u", 1}, {"analytic", 1}},
         {"attribute"}},
        {"mfem_gmsh_t16_tets_1M.vtu",
         212956,
         {{{S::Tet, 1}, 1251511}},
         {{"u", 1}, {"analytic", 1}},
         {"attribute"}},
    };
}

bool HaveSharedData() { return fs::exists(Shared("README.md")); }

/// Meshes are read once per test binary run.
const Mesh& RealMesh(const std::string& name) {
    static std::map<std::string, Mesh> cache;
    auto it = cache.find(name);
    if (it == cache.end()) it = cache.emplace(name, ReadVtkXml(Shared(name), {})).first;
    return it->second;
}

double Analytic(double x, double y, double z) {
    return std::sin(3 * x) * std::cos(2 * y) + 0.5 * std::sin(4 * z + x * y);
}

class RealFileTest : public ::testing::TestWithParam<RealFile> {};

TEST_P(RealFileTest, CountsAndFieldsMatchTheReadme) {
    if (!HaveSharedData()) GTEST_SKIP() << "no shared data";
    const RealFile& rf = GetParam();
    const Mesh& m = RealMesh(rf.name);
    EXPECT_EQ(m.PointCount(), rf.points);
    std::map<std::pair<CellShape, int>, std::int64_t> counts;
    for (std::int64_t c = 0; c < m.CellCount(); ++c) {
        EXPECT_EQ(m.cellFamily[c], CellFamily::Lagrange);
        ++counts[{m.cellShape[c], m.cellOrder[c]}];
    }
    EXPECT_EQ(counts, rf.cellsByKind);
    ASSERT_EQ(m.pointFields.size(), rf.pointFields.size());
    for (const auto& [name, comps] : rf.pointFields) {
        const Field* f = m.FindPointField(name);
        ASSERT_NE(f, nullptr) << name;
        EXPECT_EQ(f->components, comps) << name;
    }
    ASSERT_EQ(m.cellFields.size(), rf.cellFields.size());
    for (const std::string& name : rf.cellFields)
        EXPECT_NE(m.FindCellField(name), nullptr);
    EXPECT_TRUE(m.ghost.empty());
}

/// Points that are a vertex of some cell.
std::vector<char> VertexPoints(const Mesh& m) {
    std::vector<char> vertex(m.PointCount(), 0);
    for (std::int64_t c = 0; c < m.CellCount(); ++c)
        for (const auto& v : VertexLattice(m.cellShape[c], m.cellOrder[c]))
            vertex[m.CellNodes(c)[InternalNodeIndex(m.cellShape[c], m.cellOrder[c],
                                                    m.cellFamily[c], v)]] = 1;
    return vertex;
}

TEST_P(RealFileTest, AnalyticFieldEqualsClosedFormAtTheNodes) {
    if (!HaveSharedData()) GTEST_SKIP() << "no shared data";
    const RealFile& rf = GetParam();
    const Mesh& m = RealMesh(rf.name);
    const Field* f = m.FindPointField("analytic");
    if (!f) GTEST_SKIP() << "no analytic field";
    const std::string name = rf.name;
    // Float32 data (the t16 file) carries ~7 digits in both the point and the value.
    const double exact = name == "mfem_gmsh_t16_tets_1M.vtu" ? 2e-6 : 1e-12;
    // gmsh files sample f at every node, and so do the linear and the p2 MFEM files. The
    // MFEM ParaView output of order >= 3 evaluates its interpolant (on MFEM's own nodes)
    // at VTK's equispaced nodes, which coincide with MFEM's only at the vertices;
    // elsewhere the value differs from f by the interpolation error.
    const bool everyNode =
        name.rfind("gmsh_", 0) == 0 || name.find("linear") != std::string::npos ||
        name.find("1M") != std::string::npos || name == "mfem_escher_quadtet_p2.vtu";
    const std::vector<char> vertex = VertexPoints(m);
    double worstVertex = 0, worstOther = 0;
    for (std::int64_t p = 0; p < m.PointCount(); ++p) {
        const double* x = &m.points[3 * p];
        const double e = std::abs(f->values[p] - Analytic(x[0], x[1], x[2]));
        double& worst = vertex[p] ? worstVertex : worstOther;
        worst = std::max(worst, e);
    }
    EXPECT_LT(worstVertex, exact);
    EXPECT_LT(worstOther, everyNode ? exact : 0.05);
}

/// For every cell of order >= 2, the largest turning angle (degrees) between consecutive
/// segments of its internal lattice lines: x(l) - x(l - e_d) versus x(l + e_d) - x(l).
std::vector<double> LatticeTurningAngles(const Mesh& m) {
    std::vector<double> angles;
    for (std::int64_t c = 0; c < m.CellCount(); ++c) {
        const CellShape shape = m.cellShape[c];
        const CellFamily family = m.cellFamily[c];
        const int p = m.cellOrder[c];
        if (p < 2) continue;
        const auto& lattice = LatticeNodes(shape, p, family);
        const std::int64_t* nodes = m.CellNodes(c);
        auto X = [&](int n) { return &m.points[3 * nodes[n]]; };
        double worst = 0;
        for (std::size_t n = 0; n < lattice.size(); ++n)
            for (int d = 0; d < 3; ++d) {
                LatticeIndex lo = lattice[n], hi = lattice[n];
                --lo[d];
                ++hi[d];
                const int a = InternalNodeIndex(shape, p, family, lo);
                const int b = InternalNodeIndex(shape, p, family, hi);
                if (a < 0 || b < 0) continue;
                const double* xa = X(a);
                const double* xm = X(static_cast<int>(n));
                const double* xb = X(b);
                const double u[3] = {xm[0] - xa[0], xm[1] - xa[1], xm[2] - xa[2]};
                const double v[3] = {xb[0] - xm[0], xb[1] - xm[1], xb[2] - xm[2]};
                const double cosine =
                    (u[0] * v[0] + u[1] * v[1] + u[2] * v[2]) /
                    std::sqrt((u[0] * u[0] + u[1] * u[1] + u[2] * u[2]) *
                              (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]));
                worst = std::max(worst,
                                 std::acos(std::clamp(cosine, -1.0, 1.0)) * 180 / M_PI);
            }
        angles.push_back(worst);
    }
    return angles;
}

// Along a lattice line of a smooth cell consecutive node spacings turn by about
// |x''| h / |x'| per step: a few degrees, tens in the most curved or deformed cells here
// (the order-9 spiral, step-44's compressed block). A node put on the wrong edge or face
// folds the line back on itself, beyond a right angle.
constexpr double kFoldDegrees = 90.0;

TEST_P(RealFileTest, HighOrderNodesAreOrdered) {
    if (!HaveSharedData()) GTEST_SKIP() << "no shared data";
    const std::vector<double> angles = LatticeTurningAngles(RealMesh(GetParam().name));
    const double worst =
        angles.empty() ? 0 : *std::max_element(angles.begin(), angles.end());
    EXPECT_LT(worst, kFoldDegrees);
}

INSTANTIATE_TEST_SUITE_P(SharedData, RealFileTest, ::testing::ValuesIn(RealFiles()),
                         [](const auto& info) {
                             std::string n = info.param.name;
                             n = n.substr(0, n.find('.'));
                             return n;
                         });

TEST(VtkXmlRealData, LegacyHexOrderIsNeededForDealIIFiles) {
    if (!HaveSharedData()) GTEST_SKIP() << "no shared data";
    // Trap 1: the deal.II files say version 0.1 and are valid only with the pre-VTK-9
    // swap of hex edges 10 and 11. Claim version 2.2 (same length, inline data, so
    // nothing shifts) and the swap is not applied: the nodes must then come out
    // disordered.
    for (const char* name : {"dealii_step44_hex_q2.vtu", "dealii_step65_hex_q3.vtu"}) {
        const std::vector<double> good = LatticeTurningAngles(RealMesh(name));
        ASSERT_FALSE(good.empty());
        EXPECT_LT(*std::max_element(good.begin(), good.end()), kFoldDegrees) << name;
        std::string bytes = ReadBytes(Shared(name));
        bytes = Replace(bytes, "version=\"0.1\"", "version=\"2.2\"");
        const Mesh bad = ReadVtkXml(WriteFile(std::string("xml_v22_") + name, bytes), {});
        const std::vector<double> folded = LatticeTurningAngles(bad);
        ASSERT_EQ(folded.size(), good.size());
        EXPECT_GT(*std::min_element(folded.begin(), folded.end()), kFoldDegrees) << name;
    }
}

TEST(VtkXmlRealData, DealIIStep65SolutionIsTheExactSolution) {
    if (!HaveSharedData()) GTEST_SKIP() << "no shared data";
    const Mesh& m = RealMesh("dealii_step65_hex_q3.vtu");
    const Field* u = m.FindPointField("solution");
    ASSERT_NE(u, nullptr);
    double worst = 0;
    for (std::int64_t p = 0; p < m.PointCount(); ++p) {
        const double* x = &m.points[3 * p];
        const double r2 = x[0] * x[0] + x[1] * x[1] + x[2] * x[2];
        const double exact = r2 < 0.25 ? r2 : 0.1 * r2 + 0.225;
        worst = std::max(worst, std::abs(u->values[p] - exact));
    }
    EXPECT_LT(worst, 2e-6);
}

/// Signed volume of a linear cell (internal order) from a tetrahedral split, each tet
/// oriented positively in reference coordinates.
double LinearCellVolume(const Mesh& m, std::int64_t c) {
    const CellShape shape = m.cellShape[c];
    std::vector<std::array<int, 4>> tets;
    switch (shape) {
        case CellShape::Tet:
            tets = {{0, 1, 2, 3}};
            break;
        case CellShape::Hex:  // six tets around the diagonal 0-7
            tets = {{0, 1, 3, 7}, {0, 1, 5, 7}, {0, 2, 3, 7},
                    {0, 2, 6, 7}, {0, 4, 5, 7}, {0, 4, 6, 7}};
            break;
        case CellShape::Wedge:
            tets = {{0, 1, 2, 3}, {1, 2, 3, 4}, {2, 3, 4, 5}};
            break;
        case CellShape::Pyramid:
            tets = {{0, 1, 3, 4}, {0, 3, 2, 4}};
            break;
    }
    const auto& lattice = LatticeNodes(shape, 1);
    auto det = [](const double* a, const double* b, const double* c, const double* d) {
        const double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
        const double v[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
        const double w[3] = {d[0] - a[0], d[1] - a[1], d[2] - a[2]};
        return u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0]) +
               u[2] * (v[0] * w[1] - v[1] * w[0]);
    };
    double volume = 0;
    for (const auto& t : tets) {
        std::array<double, 3> ref[4];
        for (int k = 0; k < 4; ++k) ref[k] = LatticeRefCoords(shape, 1, lattice[t[k]]);
        const double sign =
            det(ref[0].data(), ref[1].data(), ref[2].data(), ref[3].data()) > 0 ? 1 : -1;
        const double* x[4];
        for (int k = 0; k < 4; ++k) x[k] = &m.points[3 * m.CellNodes(c)[t[k]]];
        volume += sign * det(x[0], x[1], x[2], x[3]) / 6;
    }
    return volume;
}

TEST(VtkXmlRealData, LinearFicheraCellsArePositiveAndFillVolumeSeven) {
    if (!HaveSharedData()) GTEST_SKIP() << "no shared data";
    const Mesh& m = RealMesh("mfem_fichera_mixed16_linear.vtu");
    double total = 0;
    std::int64_t inverted = 0;
    for (std::int64_t c = 0; c < m.CellCount(); ++c) {
        const double v = LinearCellVolume(m, c);
        inverted += v <= 0;
        total += v;
    }
    EXPECT_EQ(inverted, 0);
    EXPECT_NEAR(total, 7.0, 1e-9);
}

// The million-tet mesh reads whole (its read time is recorded, not asserted: speed is
// measured by scripts/bench_peers.sh, never by a timed test on a shared machine).
TEST(VtkXmlRealData, MillionTetMeshReadsWhole) {
    if (!HaveSharedData()) GTEST_SKIP() << "no shared data";
    const auto t0 = std::chrono::steady_clock::now();
    const Mesh m = ReadVtkXml(Shared("mfem_gmsh_t16_tets_1M.vtu"), {});
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    EXPECT_EQ(m.CellCount(), 1251511);
    for (std::int64_t c = 0; c < m.CellCount(); c += 4099) {
        EXPECT_EQ(m.cellShape[c], CellShape::Tet);
        EXPECT_EQ(m.cellOrder[c], 1);
    }
    EXPECT_NO_THROW(m.Validate("t16"));
    RecordProperty("read_seconds", std::to_string(seconds));
}

TEST(VtkXmlRealData, FieldSelectionOnRealFile) {
    if (!HaveSharedData()) GTEST_SKIP() << "no shared data";
    ReadOptions options;
    options.fields = std::set<std::string>{"displacement.z"};
    const Mesh m = ReadVtkXml(Shared("mfem_beam_hex_elasticity_p3.vtu"), options);
    ASSERT_EQ(m.pointFields.size(), 1u);
    EXPECT_EQ(m.pointFields[0].name, "displacement");
    EXPECT_EQ(m.pointFields[0].components, 3);
    EXPECT_TRUE(m.cellFields.empty());
}

// ---------------------------------------------------------------------------------------
// Writer round trip.

/// A mesh of every shape and order 1..4, serendipity cells, private nodes placed by a
/// curved map, point and cell fields (a vector among them) and ghost flags.
Mesh MixedMesh() {
    Mesh m;
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> jitter(-0.02, 0.02);
    int cell = 0;
    auto add = [&](CellShape shape, int order, CellFamily family) {
        const auto& lattice = LatticeNodes(shape, order, family);
        std::vector<std::int64_t> nodes;
        for (const auto& ijk : lattice) {
            const auto r = LatticeRefCoords(shape, order, ijk);
            nodes.push_back(m.PointCount());
            m.points.push_back(r[0] + 0.1 * r[1] * r[1] + 3 * cell + jitter(rng));
            m.points.push_back(r[1] + 0.05 * r[2] + jitter(rng));
            m.points.push_back(r[2] + 0.1 * r[0] * r[1] + jitter(rng));
        }
        m.AddCell(shape, order, family, nodes.data(), static_cast<int>(nodes.size()));
        ++cell;
    };
    for (CellShape s :
         {CellShape::Tet, CellShape::Hex, CellShape::Wedge, CellShape::Pyramid})
        for (int p = 1; p <= 4; ++p) add(s, p, CellFamily::Lagrange);
    for (CellShape s : {CellShape::Hex, CellShape::Wedge, CellShape::Pyramid})
        add(s, 2, CellFamily::Serendipity);
    Field u{"u", Association::Point, 1, {}};
    Field v{"velocity", Association::Point, 3, {}};
    for (std::int64_t p = 0; p < m.PointCount(); ++p) {
        u.values.push_back(std::sin(m.points[3 * p]) + 1e6);
        for (int a = 0; a < 3; ++a)
            v.values.push_back(m.points[3 * p + a] * (a + 1) / 3.0);
    }
    Field id{"id & <name>", Association::Cell, 1, {}};
    Field t{"tensor", Association::Cell, 2, {}};
    for (std::int64_t c = 0; c < m.CellCount(); ++c) {
        id.values.push_back(c);
        t.values.push_back(-0.5 * c);
        t.values.push_back(1.0 / (c + 1));
    }
    m.pointFields = {u, v};
    m.cellFields = {id, t};
    for (std::int64_t c = 0; c < m.CellCount(); ++c) m.ghost.push_back(c % 3 == 0);
    return m;
}

void ExpectSameMesh(const Mesh& a, const Mesh& b) {
    EXPECT_EQ(a.points, b.points);
    EXPECT_EQ(a.cellOffsets, b.cellOffsets);
    EXPECT_EQ(a.connectivity, b.connectivity);
    EXPECT_EQ(a.cellShape, b.cellShape);
    EXPECT_EQ(a.cellOrder, b.cellOrder);
    EXPECT_EQ(a.cellFamily, b.cellFamily);
    EXPECT_EQ(a.ghost, b.ghost);
    ASSERT_EQ(a.pointFields.size(), b.pointFields.size());
    ASSERT_EQ(a.cellFields.size(), b.cellFields.size());
    for (std::size_t i = 0; i < a.pointFields.size(); ++i) {
        EXPECT_EQ(a.pointFields[i].name, b.pointFields[i].name);
        EXPECT_EQ(a.pointFields[i].association, b.pointFields[i].association);
        EXPECT_EQ(a.pointFields[i].components, b.pointFields[i].components);
        EXPECT_EQ(a.pointFields[i].values, b.pointFields[i].values);
    }
    for (std::size_t i = 0; i < a.cellFields.size(); ++i) {
        EXPECT_EQ(a.cellFields[i].name, b.cellFields[i].name);
        EXPECT_EQ(a.cellFields[i].association, b.cellFields[i].association);
        EXPECT_EQ(a.cellFields[i].components, b.cellFields[i].components);
        EXPECT_EQ(a.cellFields[i].values, b.cellFields[i].values);
    }
}

TEST(VtuWriter, RoundTripMixedMesh) {
    const Mesh m = MixedMesh();
    m.Validate("mixed");
    const std::string path = (TempDir() / "xml_roundtrip.vtu").string();
    WriteVtu(path, m);
    EXPECT_FALSE(fs::exists(path + ".tmp"));
    const Mesh back = ReadVtkXml(path, {});
    ExpectSameMesh(m, back);
    // The file says what the contract says.
    const std::string bytes = ReadBytes(path);
    const std::string head = bytes.substr(0, bytes.find("<AppendedData"));
    for (const char* s :
         {"version=\"2.2\"", "header_type=\"UInt64\"", "encoding=\"raw\"",
          "Name=\"HigherOrderDegrees\"", "Name=\"vtkGhostType\"",
          "type=\"Int64\" Name=\"connectivity\"", "type=\"UInt8\" Name=\"types\""})
        EXPECT_NE(bytes.find(s), std::string::npos) << s;
    EXPECT_EQ(head.find("format=\"ascii\""), std::string::npos);
    EXPECT_EQ(head.find("Float32"), std::string::npos);
}

/// One cell of `kind` per entry, private nodes placed by a curved map (as MixedMesh),
/// each with the source VTK type given (types empty: no source types).
Mesh CellsOfKinds(const std::vector<CellKind>& kinds, const std::vector<int>& types) {
    Mesh m;
    int cell = 0;
    for (const CellKind& kind : kinds) {
        std::vector<std::int64_t> nodes;
        for (const auto& ijk : LatticeNodes(kind.shape, kind.order, kind.family)) {
            const auto r = LatticeRefCoords(kind.shape, kind.order, ijk);
            nodes.push_back(m.PointCount());
            m.points.push_back(r[0] + 0.1 * r[1] * r[1] + 3 * cell);
            m.points.push_back(r[1] + 0.05 * r[2]);
            m.points.push_back(r[2] + 0.1 * r[0] * r[1]);
        }
        m.AddCell(kind.shape, kind.order, kind.family, nodes.data(),
                  static_cast<int>(nodes.size()));
        ++cell;
    }
    for (int t : types) m.vtkType.push_back(static_cast<std::uint8_t>(t));
    return m;
}

TEST(VtuWriter, KeepsTheSourceCellTypesAndReadsBackTheSameCells) {
    constexpr auto L = CellFamily::Lagrange;
    constexpr auto S = CellFamily::Serendipity;
    using Shape = CellShape;
    // Every type hpray reads, each with a kind it can hold; 71-74 also of order 1 (a
    // linear cell read as a Lagrange type stays one).
    const std::vector<std::pair<int, CellKind>> cases = {
        {10, {Shape::Tet, 1, L}},     {11, {Shape::Hex, 1, L}},
        {12, {Shape::Hex, 1, L}},     {13, {Shape::Wedge, 1, L}},
        {14, {Shape::Pyramid, 1, L}}, {24, {Shape::Tet, 2, L}},
        {25, {Shape::Hex, 2, S}},     {26, {Shape::Wedge, 2, S}},
        {27, {Shape::Pyramid, 2, S}}, {29, {Shape::Hex, 2, L}},
        {32, {Shape::Wedge, 2, L}},   {71, {Shape::Tet, 1, L}},
        {71, {Shape::Tet, 2, L}},     {71, {Shape::Tet, 4, L}},
        {72, {Shape::Hex, 1, L}},     {72, {Shape::Hex, 3, L}},
        {73, {Shape::Wedge, 1, L}},   {73, {Shape::Wedge, 2, L}},
        {73, {Shape::Wedge, 3, L}},   {74, {Shape::Pyramid, 1, L}},
        {74, {Shape::Pyramid, 3, L}},
    };
    std::vector<CellKind> kinds;
    std::vector<int> types;
    for (const auto& [type, kind] : cases) {
        kinds.push_back(kind);
        types.push_back(type);
    }
    const Mesh m = CellsOfKinds(kinds, types);
    m.Validate("kinds");
    const std::string path = (TempDir() / "xml_source_types.vtu").string();
    WriteVtu(path, m);
    const test::RawVtu raw(path);
    EXPECT_EQ(raw.Values<std::uint8_t>("Cells", "types"), m.vtkType);
    EXPECT_TRUE(raw.Has("CellData", "HigherOrderDegrees"));  // 71-74 need it
    // The file's node order is VTK's for the type written: the inverse of the reading
    // permutation (e.g. a VTK_WEDGE lists its first triangle the other way round than a
    // VTK_LAGRANGE_WEDGE).
    const auto conn = raw.Values<std::int64_t>("Cells", "connectivity");
    for (std::int64_t c = 0; c < m.CellCount(); ++c) {
        const CellKind kind = kinds[c];
        if (types[c] == kVtkVoxel) continue;  // no reading table: checked below
        const std::vector<int>& perm = VtkToInternal(types[c], kind);
        for (int k = 0; k < m.CellNodeCount(c); ++k)
            EXPECT_EQ(conn[m.cellOffsets[c] + perm[k]], m.CellNodes(c)[k])
                << "type " << types[c] << " node " << k;
    }
    auto fileNodes = [&](std::int64_t c) {
        return std::vector<std::int64_t>(conn.begin() + m.cellOffsets[c],
                                         conn.begin() + m.cellOffsets[c + 1]);
    };
    const std::int64_t* voxel = m.CellNodes(1);  // i fastest: the internal order
    EXPECT_EQ(fileNodes(1), std::vector<std::int64_t>(voxel, voxel + 8));
    const std::int64_t* hex = m.CellNodes(2);  // VTK_HEXAHEDRON: counterclockwise
    EXPECT_EQ(fileNodes(2), (std::vector<std::int64_t>{hex[0], hex[1], hex[3], hex[2],
                                                       hex[4], hex[5], hex[7], hex[6]}));
    const std::int64_t* wedge = m.CellNodes(3);  // VTK_WEDGE: (0,0) (0,1) (1,0) below
    EXPECT_EQ(fileNodes(3), (std::vector<std::int64_t>{wedge[0], wedge[2], wedge[1],
                                                       wedge[3], wedge[5], wedge[4]}));
    const std::int64_t* lagrangeWedge = m.CellNodes(16);  // VTK_LAGRANGE_WEDGE, order 1
    EXPECT_EQ(fileNodes(16), std::vector<std::int64_t>(lagrangeWedge, lagrangeWedge + 6));
    // Read back: the same cells in internal order, and the same source types.
    const Mesh back = ReadVtkXml(path, {});
    ExpectSameMesh(m, back);
    EXPECT_EQ(back.vtkType, m.vtkType);
}

TEST(VtuWriter, CellsOfUnknownTypeAreWrittenAsTheLinearTypesOrAsBefore) {
    constexpr auto L = CellFamily::Lagrange;
    constexpr auto S = CellFamily::Serendipity;
    using Shape = CellShape;
    // Linear cells only: VTK_TETRA, VTK_HEXAHEDRON, VTK_WEDGE, VTK_PYRAMID and no
    // HigherOrderDegrees.
    const Mesh linear = CellsOfKinds({{Shape::Tet, 1, L},
                                      {Shape::Hex, 1, L},
                                      {Shape::Wedge, 1, L},
                                      {Shape::Pyramid, 1, L}},
                                     {});
    const std::string a = (TempDir() / "xml_unknown_linear.vtu").string();
    WriteVtu(a, linear);
    const test::RawVtu rawA(a);
    EXPECT_EQ(rawA.Values<std::uint8_t>("Cells", "types"),
              (std::vector<std::uint8_t>{10, 12, 13, 14}));
    EXPECT_FALSE(rawA.Has("CellData", "HigherOrderDegrees"));
    const Mesh backA = ReadVtkXml(a, {});
    EXPECT_EQ(backA.connectivity, linear.connectivity);
    EXPECT_EQ(backA.points, linear.points);
    // ...unless asked for (the pieces of a .pvtu that declares the array).
    WriteVtu(a, linear, /*alwaysWriteDegrees=*/true);
    EXPECT_TRUE(test::RawVtu(a).Has("CellData", "HigherOrderDegrees"));
    // Curved cells as before: Lagrange 71-74 (with their degrees), serendipity 25-27; a
    // source type that cannot hold the cell (stale) is ignored.
    const Mesh curved = CellsOfKinds({{Shape::Tet, 2, L},
                                      {Shape::Hex, 2, L},
                                      {Shape::Wedge, 3, L},
                                      {Shape::Pyramid, 2, L},
                                      {Shape::Hex, 2, S},
                                      {Shape::Wedge, 2, S},
                                      {Shape::Pyramid, 2, S}},
                                     {0, 12, 0, 0, 0, 0, 0});
    const std::string b = (TempDir() / "xml_unknown_curved.vtu").string();
    WriteVtu(b, curved);
    const test::RawVtu rawB(b);
    EXPECT_EQ(rawB.Values<std::uint8_t>("Cells", "types"),
              (std::vector<std::uint8_t>{71, 72, 73, 74, 25, 26, 27}));
    EXPECT_EQ(rawB.Values<double>("CellData", "HigherOrderDegrees"),
              (std::vector<double>{2, 2, 2, 2, 2, 2, 3, 3, 3, 2, 2,
                                   2, 2, 2, 2, 2, 2, 2, 2, 2, 2}));
    const Mesh backB = ReadVtkXml(b, {});
    EXPECT_EQ(backB.connectivity, curved.connectivity);
    EXPECT_EQ(backB.cellFamily, curved.cellFamily);
}

TEST(VtuWriter, LargeMeshesAreWrittenChunkByChunkAndTheBytesSeen) {
    // Enough cells (of kinds whose VTK node order differs from the internal one, and of
    // Lagrange types, which need degrees) that the connectivity, types and degrees are
    // produced in several chunks: the file reads back into the same mesh, and the bytes
    // given to the observer are the file's, in order.
    std::vector<CellKind> kinds;
    const CellKind cycle[] = {{CellShape::Hex, 2, CellFamily::Lagrange},
                              {CellShape::Tet, 1, CellFamily::Lagrange},
                              {CellShape::Wedge, 2, CellFamily::Lagrange},
                              {CellShape::Tet, 3, CellFamily::Lagrange}};
    for (int c = 0; c < 60000; ++c) kinds.push_back(cycle[(c / 7) % 4]);
    Mesh m = CellsOfKinds(kinds, {});
    Field u;
    u.name = "u";
    for (std::int64_t p = 0; p < m.PointCount(); ++p) u.values.push_back(0.5 * p);
    m.pointFields.push_back(u);
    ASSERT_GT(m.connectivity.size(), 4u << 17);
    const std::string path = (TempDir() / "xml_chunks.vtu").string();
    std::string seen;
    WriteVtu(path, m, false,
             [&seen](const char* data, std::size_t bytes) { seen.append(data, bytes); });
    EXPECT_EQ(seen, ReadBytes(path));
    ExpectSameMesh(m, ReadVtkXml(path, {}));
}

TEST(VtuWriter, ReadersRecordTheFileCellTypes) {
    // XML, legacy and structured input: the type each cell was read as (voxels too);
    // structured grids have none.
    const Mesh lagrange = ReadVtkXml(TestData("xml_vtk_lagrange.vtu"), {});
    const test::RawVtu raw(TestData("xml_vtk_lagrange.vtu"));
    EXPECT_EQ(lagrange.vtkType, raw.Values<std::uint8_t>("Cells", "types"));
    const Mesh legacy = ReadMesh(TestData("legacy_ascii_42.vtk"));
    std::vector<std::uint8_t> legacyTypes;
    {
        std::ifstream in(TestData("legacy_ascii_42.vtk"));
        std::string word;
        while (in >> word && word != "CELL_TYPES") {
        }
        int n = 0, t = 0;
        in >> n;
        for (int i = 0; i < n && in >> t; ++i)
            if (t >= 10) legacyTypes.push_back(static_cast<std::uint8_t>(t));  // 3-D
    }
    ASSERT_FALSE(legacyTypes.empty());
    EXPECT_EQ(legacy.vtkType, legacyTypes);
    const Mesh grid = ReadVtkXml(TestData("xml_vtk_grid.vts"), {});
    EXPECT_TRUE(grid.vtkType.empty());
}

TEST(VtuWriter, RoundTripThroughParallelIndex) {
    // Two written pieces and an index: the concatenation shifts the second piece's nodes.
    const Mesh m = MixedMesh();
    const fs::path dir = TempDir() / "pvtu_rt";
    fs::create_directories(dir);
    WriteVtu((dir / "a.vtu").string(), m);
    WriteVtu((dir / "b.vtu").string(), m);
    std::ofstream(dir / "both.pvtu")
        << "<?xml version=\"1.0\"?>\n<VTKFile type=\"PUnstructuredGrid\" "
           "version=\"2.2\">\n"
           "<PUnstructuredGrid GhostLevel=\"1\">\n<Piece Source=\"a.vtu\"/>\n"
           "<Piece Source=\"./b.vtu\"/>\n</PUnstructuredGrid>\n</VTKFile>\n";
    const Mesh both = ReadVtkXml((dir / "both.pvtu").string(), {});
    ASSERT_EQ(both.PointCount(), 2 * m.PointCount());
    ASSERT_EQ(both.CellCount(), 2 * m.CellCount());
    for (std::int64_t c = 0; c < m.CellCount(); ++c)
        for (int k = 0; k < m.CellNodeCount(c); ++k)
            EXPECT_EQ(both.CellNodes(c + m.CellCount())[k],
                      m.CellNodes(c)[k] + m.PointCount());
    ASSERT_EQ(both.ghost.size(), 2 * m.ghost.size());
    EXPECT_EQ(both.pointFields[1].values.size(), 2 * m.pointFields[1].values.size());
}

TEST(VtuWriter, EmptyMeshAndUnwritablePath) {
    Mesh empty;
    const std::string path = (TempDir() / "xml_empty_mesh.vtu").string();
    WriteVtu(path, empty);
    const Mesh back = ReadVtkXml(path, {});
    EXPECT_EQ(back.PointCount(), 0);
    EXPECT_EQ(back.CellCount(), 0);
    EXPECT_THROW(WriteVtu((TempDir() / "no_such_dir" / "x.vtu").string(), empty),
                 InputError);
}

}  // namespace
}  // namespace hpray
