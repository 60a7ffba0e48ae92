// Streamed gmsh input of the partitioner: the stream equals ReadGmsh on real and written
// MSH 4.1 files (binary and ASCII, sparse and shuffled tags, split and stale data
// sections, tag tables on disk), a partition of a .msh equals the partition of the same
// mesh as an appended .vtu, peak memory of `hpray partition` on a binary .msh 4x the
// limit, and malformed binary files rejected with the file and byte offset.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <numeric>
#include <optional>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "gmsh_stream.h"
#include "io/gmsh_nodes.h"
#include "io/mesh_io.h"
#include "io/vtu_writer.h"
#include "mesh/builtin.h"
#include "partition.h"
#include "partition_test_util.h"
#include "util/error.h"

namespace hpray {
namespace {

namespace fs = std::filesystem;
using test::ScratchDir;

const std::string kData = HPRAY_SHARED_DATA;

// ------------------------------------------------------------------ a MSH 4.1 writer

/// How WriteMsh lays out a mesh.
struct MshLayout {
    bool binary = true;
    bool swap = false;  ///< binary in the other byte order
    int sizeT = 8;
    enum class Tags { Dense, Sparse, Shuffled } nodeTags = Tags::Dense;
    bool shuffledElementTags = false;
    int nodeBlocks = 1;
    bool parametricBlock = false;  ///< the first node block on a curve, with u per node
    bool lowerElements = false;    ///< line and triangle blocks around the cells
    bool splitData = false;        ///< data entries shuffled, in two sections of a step
    bool staleData = false;        ///< older time steps before and after the latest
    bool extraSections = false;    ///< $PhysicalNames, $Entities, an unknown section
};

/// Byte offsets WriteMsh reports (binary files).
struct MshOffsets {
    std::uint64_t nodeCount = 0;      ///< numNodes in the $Nodes header
    std::uint64_t firstCell = 0;      ///< tag of the first 3-D element
    std::uint64_t secondCell = 0;     ///< tag of the second 3-D element
    std::uint64_t firstNodeData = 0;  ///< tag of the first $NodeData entry
    std::uint64_t secondNodeTag = 0;  ///< the second node tag of the first block
};

/// Gmsh type of an internal cell kind.
int GmshTypeOf(CellShape shape, int order, CellFamily family) {
    for (int t = 1; t <= 140; ++t)
        if (const auto k = ClassifyGmshType(t))
            if (k->shape == shape && k->order == order && k->family == family) return t;
    ADD_FAILURE() << "no gmsh type";
    return 0;
}

/// Buffered output of text or raw numbers.
class MshOut {
  public:
    MshOut(const std::string& path, const MshLayout& l)
        : out_(path, std::ios::binary | std::ios::trunc), l_(l) {}
    ~MshOut() { Flush(); }
    void Text(const std::string& s) { buf_ += s; }
    void Size(std::uint64_t v) {
        if (!l_.binary) return Word(std::to_string(v));
        if (l_.sizeT == 4) return Raw(static_cast<std::uint32_t>(v));
        Raw(v);
    }
    void Int(std::int32_t v) { l_.binary ? Raw(v) : Word(std::to_string(v)); }
    void Double(double v) {
        if (l_.binary) return Raw(v);
        char b[40];
        std::snprintf(b, sizeof b, "%.17g", v);
        Word(b);
    }
    void Eol() {
        if (!l_.binary) buf_ += '\n';
    }
    void Header(const std::string& s) { buf_ += "$" + s + "\n"; }
    void Footer(const std::string& s) {
        if (l_.binary) buf_ += "\n";
        buf_ += "$End" + s + "\n";
    }
    std::uint64_t Pos() const { return written_ + buf_.size(); }
    void Flush() {
        out_.write(buf_.data(), static_cast<std::streamsize>(buf_.size()));
        written_ += buf_.size();
        buf_.clear();
    }
    void MaybeFlush() {
        if (buf_.size() > (1u << 20)) Flush();
    }

  private:
    template <typename T>
    void Raw(T v) {
        char b[sizeof(T)];
        std::memcpy(b, &v, sizeof(T));
        if (l_.swap) std::reverse(b, b + sizeof(T));
        buf_.append(b, sizeof(T));
    }
    void Word(const std::string& w) {
        if (!buf_.empty() && buf_.back() != '\n') buf_ += ' ';
        buf_ += w;
    }
    std::ofstream out_;
    const MshLayout& l_;
    std::string buf_;
    std::uint64_t written_ = 0;
};

/// Writes `mesh` (internal node order) as MSH 4.1 with its point fields as $NodeData
/// and its cell fields as $ElementData, laid out as `l` says.
MshOffsets WriteMsh(const std::string& path, const Mesh& mesh, const MshLayout& l,
                    unsigned seed = 1) {
    std::mt19937_64 rng(seed);
    MshOffsets off;
    const std::int64_t np = mesh.PointCount(), nc = mesh.CellCount();
    std::vector<std::uint64_t> nodeTag(np);
    for (std::int64_t i = 0; i < np; ++i)
        nodeTag[i] = l.nodeTags == MshLayout::Tags::Sparse ? 17 + 5 * i : i + 1;
    if (l.nodeTags == MshLayout::Tags::Shuffled)
        std::shuffle(nodeTag.begin(), nodeTag.end(), rng);
    const int lower = l.lowerElements ? 3 : 0;  // lines before, triangles after the cells
    std::vector<std::uint64_t> cellTag(nc);
    std::iota(cellTag.begin(), cellTag.end(), std::uint64_t(1 + lower));
    if (l.shuffledElementTags) std::shuffle(cellTag.begin(), cellTag.end(), rng);

    MshOut o(path, l);
    o.Text(l.binary ? "$MeshFormat\n4.1 1 " + std::to_string(l.sizeT) + "\n"
                    : "$MeshFormat\n4.1 0 " + std::to_string(l.sizeT) + "\n");
    if (l.binary) {
        o.Int(1);
        o.Text("\n");
    }
    o.Text("$EndMeshFormat\n");
    if (l.extraSections) {
        o.Text("$PhysicalNames\n1\n3 1 \"the volume\"\n$EndPhysicalNames\n");
        o.Header("Entities");
        for (std::uint64_t c : {0, 0, 0, 1}) o.Size(c);
        o.Eol();
        o.Int(1);
        for (int k = 0; k < 6; ++k) o.Double(k);
        o.Size(1);
        o.Int(1);
        o.Size(0);
        o.Eol();
        o.Footer("Entities");
        o.Text("$SomethingElse\n$End of nothing\n$EndSomethingElse\n");
    }

    // Nodes.
    o.Header("Nodes");
    const int blocks = static_cast<int>(std::min<std::int64_t>(l.nodeBlocks, np));
    o.Size(blocks);
    off.nodeCount = o.Pos();
    o.Size(np);
    o.Size(*std::min_element(nodeTag.begin(), nodeTag.end()));
    o.Size(*std::max_element(nodeTag.begin(), nodeTag.end()));
    o.Eol();
    for (int b = 0; b < blocks; ++b) {
        const std::int64_t first = np * b / blocks, last = np * (b + 1) / blocks;
        const bool parametric = l.parametricBlock && b == 0;
        o.Int(parametric ? 1 : 3);
        o.Int(b + 1);
        o.Int(parametric ? 1 : 0);
        o.Size(last - first);
        o.Eol();
        for (std::int64_t i = first; i < last; ++i) {
            if (b == 0 && i == first + 1) off.secondNodeTag = o.Pos();
            o.Size(nodeTag[i]);
            o.Eol();
        }
        for (std::int64_t i = first; i < last; ++i) {
            for (int d = 0; d < 3; ++d) o.Double(mesh.points[3 * i + d]);
            if (parametric) o.Double(0.25);
            o.Eol();
            o.MaybeFlush();
        }
    }
    o.Footer("Nodes");

    // Elements: consecutive cells of one type form a block.
    std::vector<std::pair<std::int64_t, std::int64_t>> runs;
    for (std::int64_t c = 0; c < nc; ++c) {
        const bool same = c > 0 && mesh.cellShape[c] == mesh.cellShape[c - 1] &&
                          mesh.cellOrder[c] == mesh.cellOrder[c - 1] &&
                          mesh.cellFamily[c] == mesh.cellFamily[c - 1];
        if (same)
            runs.back().second = c + 1;
        else
            runs.push_back({c, c + 1});
    }
    o.Header("Elements");
    o.Size(runs.size() + (lower ? 2 : 0));
    o.Size(nc + lower + (lower ? 1 : 0));
    o.Size(1);
    o.Size(nc + lower + (lower ? 1 : 0));
    o.Eol();
    if (lower) {  // three line elements on the first nodes
        o.Int(1);
        o.Int(1);
        o.Int(1);
        o.Size(lower);
        o.Eol();
        for (int e = 0; e < lower; ++e) {
            o.Size(1 + e);
            o.Size(nodeTag[e % np]);
            o.Size(nodeTag[(e + 1) % np]);
            o.Eol();
        }
    }
    for (const auto& [first, last] : runs) {
        const int type = GmshTypeOf(mesh.cellShape[first], mesh.cellOrder[first],
                                    mesh.cellFamily[first]);
        const std::vector<int>& perm = GmshToInternal(type);
        o.Int(3);
        o.Int(1);
        o.Int(type);
        o.Size(last - first);
        o.Eol();
        std::vector<std::int64_t> file(perm.size());
        for (std::int64_t c = first; c < last; ++c) {
            if (c == 0) off.firstCell = o.Pos();
            if (c == 1) off.secondCell = o.Pos();
            o.Size(cellTag[c]);
            const std::int64_t* nodes = mesh.CellNodes(c);
            for (std::size_t k = 0; k < perm.size(); ++k) file[perm[k]] = nodes[k];
            for (std::int64_t p : file) o.Size(nodeTag[p]);
            o.Eol();
            o.MaybeFlush();
        }
    }
    if (lower) {  // one triangle
        o.Int(2);
        o.Int(1);
        o.Int(2);
        o.Size(1);
        o.Eol();
        o.Size(nc + lower + 1);
        for (int k = 0; k < 3; ++k) o.Size(nodeTag[k % np]);
        o.Eol();
    }
    o.Footer("Elements");

    // Data sections.
    auto section = [&](const std::string& kind, const Field& f, long long step,
                       const std::vector<std::int64_t>& entities, bool garbage) {
        o.Header(kind);
        o.Text("1\n\"" + f.name + "\"\n1\n0.0\n3\n" + std::to_string(step) + "\n" +
               std::to_string(f.components) + "\n" + std::to_string(entities.size()) +
               "\n");
        const bool point = kind == "NodeData";
        for (std::int64_t e : entities) {
            if (point && off.firstNodeData == 0) off.firstNodeData = o.Pos();
            o.Int(static_cast<std::int32_t>(point ? nodeTag[e] : cellTag[e]));
            for (int k = 0; k < f.components; ++k)
                o.Double(garbage ? 1e6 + k : f.values[e * f.components + k]);
            o.Eol();
            o.MaybeFlush();
        }
        o.Footer(kind);
    };
    auto fieldSections = [&](const std::string& kind, const Field& f, std::int64_t n) {
        std::vector<std::int64_t> all(n);
        std::iota(all.begin(), all.end(), 0);
        if (l.staleData) section(kind, f, 0, all, true);
        if (l.splitData) {
            std::shuffle(all.begin(), all.end(), rng);
            const std::vector<std::int64_t> a(all.begin(), all.begin() + n / 2),
                b(all.begin() + n / 3, all.end());  // overlapping halves
            section(kind, f, 1, a, false);
            section(kind, f, 1, b, false);
        } else {
            section(kind, f, 1, all, false);
        }
        if (l.staleData) section(kind, f, 0, all, true);
    };
    for (const Field& f : mesh.pointFields) fieldSections("NodeData", f, np);
    for (const Field& f : mesh.cellFields) fieldSections("ElementData", f, nc);
    return off;
}

// ------------------------------------------------------------------ stream helpers

/// Collects a streamed mesh back into a Mesh with its fields.
class CollectSink : public partition::MeshSink {
  public:
    void Fields(const std::vector<partition::StreamField>& pf,
                const std::vector<partition::StreamField>& cf) override {
        pointFields = pf;
        cellFields = cf;
        for (const auto& f : pf) pointComps += f.components;
        for (const auto& f : cf) cellComps += f.components;
        if (onFields) onFields();
    }
    void Points(std::int64_t count, const double* xyz, const double* values) override {
        mesh.points.insert(mesh.points.end(), xyz, xyz + 3 * count);
        pointValues.insert(pointValues.end(), values, values + count * pointComps);
    }
    void Cell(CellShape shape, int order, CellFamily family, const std::int64_t* nodes,
              int count, const double* values, std::uint8_t vtkType) override {
        ASSERT_LT(*std::max_element(nodes, nodes + count), mesh.PointCount());
        mesh.AddCell(shape, order, family, nodes, count);
        mesh.vtkType.push_back(vtkType);
        cellValues.insert(cellValues.end(), values, values + cellComps);
    }
    Mesh mesh;
    std::vector<partition::StreamField> pointFields, cellFields;
    int pointComps = 0, cellComps = 0;
    std::vector<double> pointValues, cellValues;
    std::function<void()> onFields;
};

/// Everything the sink received equals `ref` (geometry, cells, the named fields).
void ExpectSinkEquals(const CollectSink& sink, const Mesh& ref) {
    EXPECT_EQ(sink.mesh.points, ref.points);
    EXPECT_EQ(sink.mesh.connectivity, ref.connectivity);
    EXPECT_EQ(sink.mesh.cellOffsets, ref.cellOffsets);
    EXPECT_EQ(sink.mesh.cellShape, ref.cellShape);
    EXPECT_EQ(sink.mesh.cellOrder, ref.cellOrder);
    EXPECT_EQ(sink.mesh.cellFamily, ref.cellFamily);
    EXPECT_EQ(sink.mesh.vtkType, ref.vtkType);
    auto compare = [](const std::vector<partition::StreamField>& fields, int stride,
                      const std::vector<double>& values, const std::vector<Field>& refs,
                      std::int64_t n) {
        ASSERT_EQ(fields.size(), refs.size());
        int offset = 0;
        for (std::size_t i = 0; i < fields.size(); ++i) {
            const Field& r = refs[i];  // both in name order
            ASSERT_EQ(fields[i].name, r.name);
            ASSERT_EQ(fields[i].components, r.components);
            for (std::int64_t e = 0; e < n; ++e)
                for (int k = 0; k < r.components; ++k)
                    ASSERT_EQ(values[e * stride + offset + k],
                              r.values[e * r.components + k])
                        << r.name << " entity " << e;
            offset += r.components;
        }
    };
    compare(sink.pointFields, sink.pointComps, sink.pointValues, ref.pointFields,
            ref.PointCount());
    compare(sink.cellFields, sink.cellComps, sink.cellValues, ref.cellFields,
            ref.CellCount());
}

partition::StreamStats Stream(const std::string& path, CollectSink& sink,
                              const std::string& spill, std::size_t mapBytes = 1 << 20,
                              const ReadOptions& options = {}) {
    partition::GmshStreamOptions o;
    o.bufferBytes = 4096;  // the minimum is raised to 64 KiB: blocks still cross it
    o.mapBytes = mapBytes;
    o.spillDir = spill;
    return partition::StreamGmsh(path, options, o, sink);
}

/// A shared gmsh mesh with two more fields: a 3-component point field and a cell field.
Mesh WithMoreFields(const std::string& file) {
    Mesh m = ReadGmsh(kData + "/" + file, {});
    Field vec{"grad", Association::Point, 3, {}};
    for (std::int64_t i = 0; i < m.PointCount(); ++i)
        for (int d = 0; d < 3; ++d) vec.values.push_back(std::cos(m.points[3 * i + d]));
    Field region{"region", Association::Cell, 1, {}};
    for (std::int64_t c = 0; c < m.CellCount(); ++c) region.values.push_back(c % 7 + 0.5);
    // Name order, as readers list them.
    m.pointFields.push_back(std::move(vec));
    std::sort(m.pointFields.begin(), m.pointFields.end(),
              [](const Field& a, const Field& b) { return a.name < b.name; });
    m.cellFields.push_back(std::move(region));
    return m;
}

bool HasSpillFile(const std::string& dir, const std::string& part) {
    for (const auto& e : fs::directory_iterator(dir))
        if (e.path().filename().string().find(part) != std::string::npos) return true;
    return false;
}

// ------------------------------------------------------------------ stream = ReadGmsh

TEST(GmshStream, EqualsReadGmshOnTheSharedAsciiFiles) {
    ScratchDir dir("gmsh_stream_shared");
    for (const char* file : {"gmsh_hybrid_pyr_p3.msh", "gmsh_pripyrtet_p2.msh"}) {
        SCOPED_TRACE(file);
        const Mesh ref = ReadGmsh(kData + "/" + file, {});
        CollectSink sink;
        const auto stats = Stream(kData + "/" + file, sink, dir.str());
        EXPECT_TRUE(stats.streamed);
        EXPECT_EQ(stats.cells, ref.CellCount());
        EXPECT_EQ(stats.points, ref.PointCount());
        ExpectSinkEquals(sink, ref);
    }
    // Counts of data/README.md; the field is the documented analytic function.
    CollectSink sink;
    Stream(kData + "/gmsh_pripyrtet_p2.msh", sink, dir.str());
    EXPECT_EQ(sink.mesh.PointCount(), 805);
    EXPECT_EQ(sink.mesh.CellCount(), 12 + 135 + 15);
    ASSERT_EQ(sink.pointComps, 1);
    for (std::int64_t i = 0; i < sink.mesh.PointCount(); ++i) {
        const double x = sink.mesh.points[3 * i], y = sink.mesh.points[3 * i + 1],
                     z = sink.mesh.points[3 * i + 2];
        EXPECT_NEAR(sink.pointValues[i],
                    std::sin(3 * x) * std::cos(2 * y) + 0.5 * std::sin(4 * z + x * y),
                    1e-12);
    }
    // The gmsh-written partitioned binary file (entities, partitioned entities).
    const std::string part =
        std::string(HPRAY_TEST_DATA) + "/gmsh_partitioned_binary.msh";
    CollectSink psink;
    Stream(part, psink, dir.str());
    ExpectSinkEquals(psink, ReadGmsh(part, {}));
    EXPECT_TRUE(fs::is_empty(dir.str()));  // spill files removed
}

TEST(GmshStream, WrittenLayoutsEqualReadGmshAndTheMesh) {
    ScratchDir dir("gmsh_stream_layouts");
    using Tags = MshLayout::Tags;
    std::vector<MshLayout> layouts(7);
    layouts[1].nodeTags = Tags::Sparse;
    layouts[1].nodeBlocks = 3;
    layouts[1].parametricBlock = true;
    layouts[1].lowerElements = true;
    layouts[1].extraSections = true;
    layouts[2].nodeTags = Tags::Shuffled;
    layouts[2].shuffledElementTags = true;
    layouts[2].splitData = true;
    layouts[2].staleData = true;
    layouts[2].sizeT = 4;
    layouts[3] = layouts[2];
    layouts[3].binary = false;
    layouts[4] = layouts[1];
    layouts[4].swap = true;  // a big-endian file
    layouts[5].binary = false;
    layouts[5].nodeBlocks = 4;
    layouts[6] = layouts[2];
    layouts[6].nodeBlocks = 5;
    for (const char* file : {"gmsh_pripyrtet_p2.msh", "gmsh_hybrid_pyr_p3.msh"}) {
        const Mesh mesh = WithMoreFields(file);
        for (std::size_t i = 0; i < layouts.size(); ++i) {
            // The hybrid file is larger: only the two tag-scrambling layouts.
            if (std::string(file) == "gmsh_hybrid_pyr_p3.msh" && i != 2 && i != 3)
                continue;
            SCOPED_TRACE(std::string(file) + " layout " + std::to_string(i));
            const std::string path = dir / ("l" + std::to_string(i) + ".msh");
            WriteMsh(path, mesh, layouts[i], static_cast<unsigned>(i));
            const Mesh ref = ReadGmsh(path, {});
            ASSERT_EQ(ref.points, mesh.points);
            // Runs in memory, then a table on disk (no memory for runs).
            for (const std::size_t mapBytes : {std::size_t(1) << 24, std::size_t(0)}) {
                const std::string spill = dir / "spill";
                fs::create_directories(spill);
                CollectSink sink;
                bool table = false;
                sink.onFields = [&] { table = HasSpillFile(spill, "node-tags"); };
                Stream(path, sink, spill, mapBytes);
                ExpectSinkEquals(sink, ref);
                ExpectSinkEquals(sink, mesh);
                // Dense tags stay one run even without memory for more.
                EXPECT_EQ(table, mapBytes == 0 && layouts[i].nodeTags != Tags::Dense);
                EXPECT_TRUE(fs::is_empty(spill));
            }
        }
    }
}

TEST(GmshStream, FieldSelection) {
    ScratchDir dir("gmsh_stream_fields");
    const Mesh mesh = WithMoreFields("gmsh_pripyrtet_p2.msh");
    MshLayout l;
    l.nodeTags = MshLayout::Tags::Shuffled;
    l.shuffledElementTags = true;
    const std::string path = dir / "f.msh";
    WriteMsh(path, mesh, l);
    struct Case {
        std::set<std::string> want;
        std::vector<std::string> point, cell;
    };
    for (const Case& c :
         {Case{{"analytic"}, {"analytic"}, {}}, Case{{"grad.y"}, {"grad"}, {}},
          Case{{"grad[2]", "region"}, {"grad"}, {"region"}},
          Case{{"region"}, {}, {"region"}}}) {
        ReadOptions o;
        o.fields = c.want;
        CollectSink sink;
        Stream(path, sink, dir.str(), 1 << 20, o);
        std::vector<std::string> point, cell;
        for (const auto& f : sink.pointFields) point.push_back(f.name);
        for (const auto& f : sink.cellFields) cell.push_back(f.name);
        EXPECT_EQ(point, c.point);
        EXPECT_EQ(cell, c.cell);
        // The values are those of the field in the mesh.
        if (c.want.count("region")) {
            for (std::int64_t e = 0; e < mesh.CellCount(); ++e)
                ASSERT_EQ(sink.cellValues[e], e % 7 + 0.5);
        }
    }
    ReadOptions bad;
    bad.fields = std::set<std::string>{"nope"};
    CollectSink sink;
    try {
        Stream(path, sink, dir.str(), 1 << 20, bad);
        FAIL() << "no error";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("'nope' does not exist"), std::string::npos)
            << e.what();
        EXPECT_NE(std::string(e.what()).find("analytic"), std::string::npos);
    }
}

// ------------------------------------------------------------------ partitions

/// The bricks of two partitions are the same: tree, boxes, counts, costs, ranges and
/// every brick's cells, ghosts, points and field values.
void ExpectSamePartition(const std::string& a, const std::string& b) {
    const partition::Partition p = partition::ReadPartition(a);
    const partition::Partition q = partition::ReadPartition(b);
    ASSERT_EQ(p.bricks.size(), q.bricks.size());
    EXPECT_EQ(p.manifest.at("tree"), q.manifest.at("tree"));
    EXPECT_EQ(p.manifest.at("fields"), q.manifest.at("fields"));
    EXPECT_EQ(p.tree.box.lo, q.tree.box.lo);
    EXPECT_EQ(p.tree.box.hi, q.tree.box.hi);
    for (std::size_t i = 0; i < p.bricks.size(); ++i) {
        SCOPED_TRACE("brick " + std::to_string(i));
        const int b = static_cast<int>(i);
        EXPECT_EQ(p.bricks[i].cells, q.bricks[i].cells);
        EXPECT_EQ(p.bricks[i].ghosts, q.bricks[i].ghosts);
        EXPECT_EQ(p.bricks[i].cost, q.bricks[i].cost);
        EXPECT_EQ(p.bricks[i].ranges, q.bricks[i].ranges);
        const Mesh x = partition::LoadBrick(p, b), y = partition::LoadBrick(q, b);
        EXPECT_EQ(x.points, y.points);
        EXPECT_EQ(x.connectivity, y.connectivity);
        EXPECT_EQ(x.cellShape, y.cellShape);
        EXPECT_EQ(x.cellOrder, y.cellOrder);
        EXPECT_EQ(x.ghost, y.ghost);
        ASSERT_EQ(x.pointFields.size(), y.pointFields.size());
        ASSERT_EQ(x.cellFields.size(), y.cellFields.size());
        for (std::size_t f = 0; f < x.pointFields.size(); ++f) {
            EXPECT_EQ(x.pointFields[f].name, y.pointFields[f].name);
            EXPECT_EQ(x.pointFields[f].values, y.pointFields[f].values);
        }
        for (std::size_t f = 0; f < x.cellFields.size(); ++f) {
            EXPECT_EQ(x.cellFields[f].name, y.cellFields[f].name);
            EXPECT_EQ(x.cellFields[f].values, y.cellFields[f].values);
        }
    }
}

TEST(GmshStream, PartitionEqualsThePartitionOfTheMeshReadWhole) {
    ScratchDir dir("gmsh_stream_partition");
    struct Case {
        const char* file;
        int bricks;
        std::optional<std::vector<std::string>> fields;
    };
    for (const Case& c : {Case{"gmsh_hybrid_pyr_p3.msh", 5, std::nullopt},
                          Case{"gmsh_pripyrtet_p2.msh", 3, std::nullopt},
                          Case{"gmsh_pripyrtet_p2.msh", 4,
                               std::vector<std::string>{"grad.x", "region"}}}) {
        SCOPED_TRACE(c.file);
        const std::string base = dir / (std::string(c.file) + std::to_string(c.bricks));
        partition::PartitionOptions o;
        o.bricks = c.bricks;
        o.fields = c.fields;
        // The shared ASCII file itself, against its whole-read mesh as an appended .vtu.
        {
            const std::string vtu = base + "-whole.vtu";
            WriteVtu(vtu, ReadGmsh(kData + "/" + c.file, {}));
            o.fields = c.fields ? std::optional<std::vector<std::string>>(
                                      std::vector<std::string>{"analytic"})
                                : std::nullopt;
            o.outDir = base + "-ascii";
            const auto report = partition::PartitionMesh(kData + "/" + c.file, o);
            EXPECT_TRUE(report.streamed);
            o.outDir = base + "-ascii-ref";
            partition::PartitionMesh(vtu, o);
            ExpectSamePartition(base + "-ascii", base + "-ascii-ref");
        }
        // A binary file with scrambled tags and more fields, against ReadGmsh of it.
        MshLayout l;
        l.nodeTags = MshLayout::Tags::Shuffled;
        l.shuffledElementTags = true;
        l.splitData = true;
        l.lowerElements = true;
        const std::string msh = base + ".msh";
        WriteMsh(msh, WithMoreFields(c.file), l);
        const std::string vtu = base + ".vtu";
        WriteVtu(vtu, ReadGmsh(msh, {}));
        o.fields = c.fields;
        o.outDir = base + "-msh";
        partition::PartitionMesh(msh, o);
        o.outDir = base + "-vtu";
        partition::PartitionMesh(vtu, o);
        ExpectSamePartition(base + "-msh", base + "-vtu");
        const partition::Partition p = partition::ReadPartition(base + "-msh");
        EXPECT_TRUE(p.manifest.at("stats").at("streamed").get<bool>());
        EXPECT_EQ(p.manifest.at("fields").size(), c.fields ? 2u : 3u);
    }
}

// ------------------------------------------------------------------ the command

struct ChildResult {
    int code = -1;
    long maxRssKiB = 0;
    std::string output;
};

/// Runs hpray with `args`; exit status, peak RSS and output of the child.
ChildResult RunHpray(const std::vector<std::string>& args) {
    const std::string log =
        fs::temp_directory_path() /
        ("hpray_test_gmsh_child_" + std::to_string(::getpid()) + ".log");
    const pid_t pid = ::fork();
    if (pid == 0) {
        const int fd = ::open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
        ::dup2(fd, 1);
        ::dup2(fd, 2);
        std::vector<char*> argv{const_cast<char*>(HPRAY_BINARY)};
        for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
        argv.push_back(nullptr);
        ::execv(HPRAY_BINARY, argv.data());
        ::_exit(127);
    }
    ChildResult r;
    int status = 0;
    struct rusage usage {};
    ::wait4(pid, &status, 0, &usage);
    r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -WTERMSIG(status);
    r.maxRssKiB = usage.ru_maxrss;
    std::ifstream in(log);
    r.output.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
    fs::remove(log);
    return r;
}

TEST(GmshStream, PeakMemoryOfABinaryMshFourTimesTheLimit) {
    ScratchDir dir("gmsh_stream_rss");
    // cube-tets-66: 1.44M linear tets, u = x + 2y + 3z; node tags 17 + 5i (runs of one:
    // the node map goes to the table on disk).
    const std::string input = dir / "cube.msh";
    const int n = 66;
    std::int64_t cells = 0;
    double uMin = 1e300, uMax = -1e300;
    {
        const Mesh mesh = MakeBuiltin("builtin:cube-tets-" + std::to_string(n));
        cells = mesh.CellCount();
        ASSERT_EQ(cells, 5ll * n * n * n);
        for (double v : mesh.FindPointField("u")->values) {
            uMin = std::min(uMin, v);
            uMax = std::max(uMax, v);
        }
        MshLayout l;
        l.nodeTags = MshLayout::Tags::Sparse;
        l.nodeBlocks = 7;
        WriteMsh(input, mesh, l);
    }
    const std::size_t limit = std::size_t(16) << 20;
    ASSERT_GE(fs::file_size(input), 4 * limit);
    const ChildResult r = RunHpray({"partition", input, "--bricks", "24", "--out",
                                    dir / "p", "--memory-limit", "16M"});
    ASSERT_EQ(r.code, 0) << r.output;
    const double peakMiB = r.maxRssKiB / 1024.0;
    RecordProperty("peak_rss_mib", std::to_string(peakMiB));
    EXPECT_LE(peakMiB, 16.0 + 64.0) << r.output;
    const partition::Partition p = partition::ReadPartition(dir / "p");
    ASSERT_EQ(p.bricks.size(), 24u);
    EXPECT_TRUE(p.manifest.at("stats").at("streamed").get<bool>());
    std::int64_t owned = 0;
    double lo = 1e300, hi = -1e300;
    for (const auto& b : p.bricks) {
        owned += b.cells - b.ghosts;
        lo = std::min(lo, b.ranges.at("u")[0]);
        hi = std::max(hi, b.ranges.at("u")[1]);
    }
    EXPECT_EQ(owned, cells);
    // Linear cells: the brick ranges are the nodal extremes, 0 and 6 on the unit cube.
    EXPECT_EQ(lo, uMin);
    EXPECT_EQ(hi, uMax);
    EXPECT_NEAR(uMin, 0.0, 1e-12);
    EXPECT_NEAR(uMax, 6.0, 1e-12);
}

// ------------------------------------------------------------------ malformed input

/// The InputError of streaming `path`, or "" when it streams.
std::string StreamError(const std::string& path, const std::string& spill,
                        std::string* where = nullptr, std::size_t mapBytes = 1 << 20) {
    CollectSink sink;
    try {
        Stream(path, sink, spill, mapBytes);
    } catch (const InputError& e) {
        if (where) *where = e.where();
        return e.what();
    }
    return "";
}

std::string ReadBytes(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    return std::string((std::istreambuf_iterator<char>(in)),
                       std::istreambuf_iterator<char>());
}

void WriteBytes(const std::string& path, const std::string& bytes) {
    std::ofstream(path, std::ios::binary | std::ios::trunc) << bytes;
}

TEST(GmshStream, MalformedBinaryFilesNameTheFileAndByte) {
    ScratchDir dir("gmsh_stream_bad");
    const std::string spill = dir / "spill";
    fs::create_directories(spill);
    const Mesh mesh = WithMoreFields("gmsh_pripyrtet_p2.msh");
    MshLayout l;
    l.nodeTags = MshLayout::Tags::Sparse;
    l.lowerElements = true;
    const std::string good = dir / "good.msh";
    const MshOffsets off = WriteMsh(good, mesh, l);
    const std::string bytes = ReadBytes(good);
    ASSERT_EQ(StreamError(good, spill), "");

    struct Case {
        std::string name, content, message, where;
    };
    std::vector<Case> cases;
    auto patch = [&](std::uint64_t at, std::uint64_t value, int size) {
        std::string s = bytes;
        std::memcpy(&s[at], &value, size);
        return s;
    };
    // Cut inside the nodes, the elements and the data.
    for (const char* marker : {"$EndNodes", "$EndElements", "$EndNodeData"}) {
        const std::size_t at = bytes.find(marker);
        ASSERT_NE(at, std::string::npos);
        cases.push_back({std::string("cut_") + (marker + 4), bytes.substr(0, at - 100),
                         "left in the file", "byte"});
    }
    cases.push_back({"huge_count", patch(off.nodeCount, 1000000000000ull, 8),
                     "node count 1000000000000",
                     "byte " + std::to_string(off.nodeCount)});
    // The first cell's first node: an undefined tag (reported at the element's tag).
    cases.push_back({"undefined_node", patch(off.firstCell + 8, 4, 8),
                     "references undefined node tag 4",
                     "byte " + std::to_string(off.firstCell)});
    // The first $NodeData entry names an undefined node.
    cases.push_back({"undefined_data_node", patch(off.firstNodeData, 3, 4),
                     "undefined node tag 3",
                     "byte " + std::to_string(off.firstNodeData)});
    // The second node repeats the first node's tag (17).
    cases.push_back({"duplicate_node", patch(off.secondNodeTag, 17, 8),
                     "node tag 17 is defined twice",
                     "byte " + std::to_string(off.secondNodeTag)});
    for (const Case& c : cases) {
        SCOPED_TRACE(c.name);
        const std::string path = dir / (c.name + ".msh");
        WriteBytes(path, c.content);
        std::string where;
        const std::string error = StreamError(path, spill, &where);
        EXPECT_NE(error.find(path), std::string::npos) << error;
        EXPECT_NE(error.find(c.message), std::string::npos) << error;
        EXPECT_EQ(where.rfind(c.where, 0), 0u) << error;
        // The table on disk reports the same problems.
        EXPECT_EQ(StreamError(path, spill, nullptr, 0), error);
        // The whole-file reader agrees on the position.
        try {
            ReadGmsh(path, {});
            ADD_FAILURE() << "ReadGmsh accepts " << c.name;
        } catch (const InputError& e) {
            EXPECT_EQ(e.where(), where) << e.what();
        }
        EXPECT_TRUE(fs::is_empty(spill));
    }
    // Element tags defined twice: an error when element data is to be read, as the data
    // could not be attributed; without cell fields the tags are not needed.
    {
        const std::string path = dir / "duplicate_element.msh";
        std::uint64_t first = 0;
        std::memcpy(&first, &bytes[off.firstCell], 8);
        WriteBytes(path, patch(off.secondCell, first, 8));
        const std::string error = StreamError(path, spill);
        EXPECT_NE(
            error.find("element tag " + std::to_string(first) + " is defined twice"),
            std::string::npos)
            << error;
        ReadOptions pointOnly;
        pointOnly.fields = std::set<std::string>{"analytic"};
        CollectSink sink;
        EXPECT_NO_THROW(Stream(path, sink, spill, 1 << 20, pointOnly));
        EXPECT_EQ(sink.mesh.CellCount(), mesh.CellCount());
    }
    // ASCII: the line of a bad coordinate, as the whole-file reader reports it.
    {
        MshLayout a;
        a.binary = false;
        const std::string path = dir / "bad_ascii.msh";
        WriteMsh(path, mesh, a);
        std::string text = ReadBytes(path);
        const std::size_t at = text.find('\n', text.find("$Nodes") + 40) + 1;
        text.insert(at + text.substr(at).find(' ') + 1, "x");  // "x0.25" is no number
        WriteBytes(path, text);
        std::string where;
        const std::string error = StreamError(path, spill, &where);
        EXPECT_NE(error.find("a node coordinate"), std::string::npos) << error;
        EXPECT_EQ(where.rfind("line ", 0), 0u) << error;
        try {
            ReadGmsh(path, {});
            ADD_FAILURE() << "ReadGmsh accepts it";
        } catch (const InputError& e) {
            EXPECT_EQ(e.where(), where) << e.what();
        }
    }
    // The command exits 2 and names the file and the byte.
    const std::string path = dir / "undefined_node.msh";
    const ChildResult r =
        RunHpray({"partition", path, "--bricks", "2", "--out", dir / "out"});
    EXPECT_EQ(r.code, 2) << r.output;
    EXPECT_NE(r.output.find(path + ": byte " + std::to_string(off.firstCell)),
              std::string::npos)
        << r.output;
}

TEST(GmshStream, CorruptedBytesNeverCrash) {
    ScratchDir dir("gmsh_stream_fuzz");
    const std::string spill = dir / "spill";
    fs::create_directories(spill);
    const Mesh mesh = WithMoreFields("gmsh_pripyrtet_p2.msh");
    MshLayout l;
    l.nodeTags = MshLayout::Tags::Shuffled;
    l.splitData = true;
    const std::string good = dir / "good.msh";
    WriteMsh(good, mesh, l);
    const std::string bytes = ReadBytes(good);
    std::mt19937_64 rng(7);
    const std::string path = dir / "fuzz.msh";
    int accepted = 0;
    for (int i = 0; i < 150; ++i) {
        std::string s = bytes;
        if (i % 3 == 0) {
            s.resize(rng() % s.size());
        } else {
            for (int k = 0; k < 4; ++k) s[rng() % s.size()] = static_cast<char>(rng());
        }
        WriteBytes(path, s);
        // Either streams or is an InputError; never another exception, never a crash.
        const std::string error = StreamError(path, spill, nullptr, i % 2 ? 0 : 1 << 20);
        if (error.empty()) {
            ++accepted;
        } else {
            EXPECT_NE(error.find(path), std::string::npos) << error;
        }
    }
    RecordProperty("accepted", accepted);
    EXPECT_TRUE(fs::is_empty(spill));
}

}  // namespace
}  // namespace hpray
