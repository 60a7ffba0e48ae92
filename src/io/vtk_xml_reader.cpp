// ReadVtkXml: VTK XML UnstructuredGrid (.vtu), its parallel index (.pvtu) and
// StructuredGrid (.vts, .pvts) into the mesh model, cells converted to internal order.
#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <optional>
#include <set>
#include <sstream>

#include "io/mesh_io.h"
#include "io/vtk_cells.h"
#include "io/vtk_xml_detail.h"
#include "util/check.h"
#include "util/error.h"
#include "util/log.h"

namespace hpray {
namespace {

using vtkxml::ArrayDesc;
using vtkxml::CollectArrays;
using vtkxml::PieceArrays;
using vtkxml::RequireCount;
using vtkxml::Fail;
using vtkxml::XmlFile;

/// VTK cell types of dimension 0, 1 or 2 (vertices, lines, faces): skipped, not errors.
bool IsLowerDimensional(std::int64_t type) {
    // empty, vertex, poly-vertex, line, poly-line, triangle, strip, polygon, pixel, quad;
    // quadratic edge, triangle, quad, biquadratic quad, quadratic-linear quad,
    // biquadratic triangle, cubic line, quadratic polygon; parametric curve and
    // surfaces; higher-order edge and faces; Lagrange and Bezier curve, triangle, quad.
    static const std::array<bool, 256> kLower = [] {
        std::array<bool, 256> lower{};
        for (int t : {0,  1,  2,  3,  4,  5,  6,  7,  8,  9,  21, 22, 23, 28, 30, 34,
                      35, 36, 51, 52, 53, 54, 60, 61, 62, 63, 68, 69, 70, 75, 76, 77})
            lower[t] = true;
        return lower;
    }();
    return type >= 0 && type < 256 && kLower[type];
}

std::string PieceWhere(int index) { return "<Piece> " + std::to_string(index); }

void ReadPoints(const XmlFile& file, pugi::xml_node piece, const std::string& where,
                std::int64_t count, Mesh& mesh) {
    const pugi::xml_node node = piece.child("Points").child("DataArray");
    if (!node) {
        if (count > 0) Fail(file, where, "has no <Points> <DataArray>");
        return;
    }
    const ArrayDesc a = vtkxml::DescribeArray(file, node, where + " <Points>");
    if (a.components != 3)
        Fail(file, a.where,
             "points have " + std::to_string(a.components) + " components, expected 3");
    vtkxml::ReadArray(file, a, count, mesh.points);
}

void ReadPointFields(const XmlFile& file, const PieceArrays& arrays, std::int64_t count,
                     Mesh& mesh) {
    for (const ArrayDesc& a : arrays.pointFields) {
        Field f;
        f.name = a.name;
        f.association = Association::Point;
        f.components = a.components;
        vtkxml::ReadArray(file, a, count, f.values);
        mesh.pointFields.push_back(std::move(f));
    }
}

/// Reads the cell fields and ghost flags of `fileCells` cells and keeps those listed in
/// `kept` (all when `kept` is null).
void ReadCellFields(const XmlFile& file, const PieceArrays& arrays,
                    std::int64_t fileCells, const std::vector<std::int64_t>* kept,
                    Mesh& mesh) {
    for (const ArrayDesc& a : arrays.cellFields) {
        Field f;
        f.name = a.name;
        f.association = Association::Cell;
        f.components = a.components;
        vtkxml::ReadArray(file, a, fileCells, f.values);
        if (kept) {
            std::vector<double> filtered;
            filtered.reserve(kept->size() * a.components);
            for (std::int64_t c : *kept)
                filtered.insert(filtered.end(), f.values.begin() + c * a.components,
                                f.values.begin() + (c + 1) * a.components);
            f.values = std::move(filtered);
        }
        mesh.cellFields.push_back(std::move(f));
    }
    if (arrays.ghost) {
        const ArrayDesc& a = *arrays.ghost;
        if (a.components != 1) Fail(file, a.where, "must have 1 component");
        std::vector<std::int64_t> values;
        vtkxml::ReadArray(file, a, fileCells, values);
        const std::int64_t n = kept ? static_cast<std::int64_t>(kept->size()) : fileCells;
        mesh.ghost.resize(n);
        for (std::int64_t i = 0; i < n; ++i) {
            const std::int64_t v = values[kept ? (*kept)[i] : i];
            if (v < 0 || v > 255)
                Fail(file, a.where,
                     "value " + std::to_string(v) + " of cell " +
                         std::to_string(kept ? (*kept)[i] : i) +
                         " is not a UInt8 ghost flag");
            mesh.ghost[i] = static_cast<std::uint8_t>(v);
        }
    }
}

struct PieceResult {
    Mesh mesh;
    std::int64_t skipped = 0;  ///< cells that are not 3-D
};

const std::vector<int>& IdentityPermutation(int n) {
    static const std::vector<int> kVoxel{0, 1, 2, 3, 4, 5, 6, 7};
    HPRAY_CHECK_EQ(n, 8);
    return kVoxel;
}

PieceResult ReadUnstructuredPiece(const XmlFile& file, pugi::xml_node piece, int index,
                                  const ReadOptions& options) {
    const std::string where = PieceWhere(index);
    const std::int64_t nPoints = RequireCount(file, piece, "NumberOfPoints", where);
    const std::int64_t nCells = RequireCount(file, piece, "NumberOfCells", where);
    PieceResult result;
    Mesh& mesh = result.mesh;
    ReadPoints(file, piece, where, nPoints, mesh);
    const PieceArrays arrays = CollectArrays(file, piece, where, options);
    ReadPointFields(file, arrays, nPoints, mesh);

    // Cell topology: end offsets, types, then connectivity sized by the last offset.
    const pugi::xml_node cellsNode = piece.child("Cells");
    auto findCellArray = [&](const char* name) -> std::optional<ArrayDesc> {
        for (pugi::xml_node n : cellsNode.children("DataArray"))
            if (std::strcmp(n.attribute("Name").value(), name) == 0)
                return vtkxml::DescribeArray(file, n, where + " <Cells>");
        if (nCells > 0)
            Fail(file, where + " <Cells>",
                 std::string("has no DataArray named '") + name + "'");
        return std::nullopt;
    };
    const auto offsetsDesc = findCellArray("offsets");
    const auto typesDesc = findCellArray("types");
    const auto connDesc = findCellArray("connectivity");
    std::vector<std::int64_t> offsets, types, conn;
    if (nCells > 0) {
        if (offsetsDesc->components != 1 || typesDesc->components != 1 ||
            connDesc->components != 1)
            Fail(file, where + " <Cells>", "cell arrays must have 1 component");
        vtkxml::ReadArray(file, *offsetsDesc, -1, offsets);
        // Files store nCells end offsets; accept a leading 0 as well.
        if (static_cast<std::int64_t>(offsets.size()) == nCells + 1 && offsets[0] == 0)
            offsets.erase(offsets.begin());
        if (static_cast<std::int64_t>(offsets.size()) != nCells)
            Fail(file, offsetsDesc->where,
                 "holds " + std::to_string(offsets.size()) +
                     " values, expected NumberOfCells = " + std::to_string(nCells));
        std::int64_t previous = 0;
        for (std::int64_t c = 0; c < nCells; ++c) {
            if (offsets[c] < previous)
                Fail(file, offsetsDesc->where,
                     "offset of cell " + std::to_string(c) + " (" +
                         std::to_string(offsets[c]) +
                         ") is smaller than the previous one (" +
                         std::to_string(previous) + ")");
            previous = offsets[c];
        }
        vtkxml::ReadArray(file, *typesDesc, nCells, types);
        vtkxml::ReadArray(file, *connDesc, offsets.back(), conn);
    }

    std::vector<double> degrees;
    if (arrays.degrees && nCells > 0) {
        if (arrays.degrees->components != 3)
            Fail(file, arrays.degrees->where, "must have 3 components");
        vtkxml::ReadArray(file, *arrays.degrees, nCells, degrees);
    }
    // As VTK's reader: old files carry the pre-VTK-9 Lagrange hex order (trap 1).
    const bool legacyHex =
        VtkXmlHasLegacyLagrangeHex(file.versionMajor, file.versionMinor);

    // Classify each cell; consecutive cells usually share a kind, so cache the last one.
    struct Cached {
        std::int64_t type = -1, nodes = -1;
        int degree[3] = {-1, -1, -1};
        CellKind kind;
        const std::vector<int>* perm = nullptr;
    } cached;
    std::vector<std::int64_t> kept;
    mesh.cellOffsets.reserve(nCells + 1);
    mesh.cellShape.reserve(nCells);
    mesh.cellOrder.reserve(nCells);
    mesh.cellFamily.reserve(nCells);
    mesh.vtkType.reserve(nCells);
    mesh.connectivity.resize(conn.size());
    std::int64_t out = 0;
    for (std::int64_t c = 0; c < nCells; ++c) {
        const std::int64_t begin = c == 0 ? 0 : offsets[c - 1];
        const std::int64_t nodes = offsets[c] - begin;
        const std::int64_t type = types[c];
        if (IsLowerDimensional(type)) {
            if (kept.empty() && result.skipped == 0) {
                kept.resize(c);
                for (std::int64_t k = 0; k < c; ++k) kept[k] = k;
            }
            ++result.skipped;
            continue;
        }
        if (result.skipped > 0) kept.push_back(c);
        int degree[3] = {-1, -1, -1};
        if (!degrees.empty()) {
            for (int k = 0; k < 3; ++k) {
                const double d = degrees[3 * c + k];
                if (!(d >= 0 && d <= 1000) || d != std::floor(d))
                    Fail(file, arrays.degrees->where,
                         "value of cell " + std::to_string(c) + " is not a valid degree");
                degree[k] = static_cast<int>(d);
            }
        }
        if (type != cached.type || nodes != cached.nodes ||
            !std::equal(degree, degree + 3, cached.degree)) {
            std::string why;
            const std::optional<CellKind> kind =
                type >= 0 && type < 256
                    ? ClassifyVtkCell(static_cast<int>(type), nodes,
                                      degrees.empty() ? nullptr : degree, &why)
                    : std::nullopt;
            if (kind) {
                cached.kind = *kind;
                cached.perm = &VtkToInternal(static_cast<int>(type), *kind, legacyHex);
            } else if (type == kVtkVoxel && nodes == 8) {
                // A voxel's node order is the internal order of a linear hex.
                cached.kind = CellKind{CellShape::Hex, 1, CellFamily::Lagrange};
                cached.perm = &IdentityPermutation(8);
            } else {
                std::ostringstream os;
                os << "cell " << c << " (VTK cell type " << type << ", " << nodes
                   << " nodes): " << (why.empty() ? "not a supported 3-D cell" : why);
                Fail(file, where, os.str());
            }
            cached.type = type;
            cached.nodes = nodes;
            std::copy(degree, degree + 3, cached.degree);
        }
        const std::vector<int>& perm = *cached.perm;
        HPRAY_CHECK_EQ(static_cast<std::int64_t>(perm.size()), nodes);
        const std::int64_t* src = conn.data() + begin;
        std::int64_t* dst = mesh.connectivity.data() + out;
        for (std::size_t k = 0; k < perm.size(); ++k) {
            const std::int64_t point = src[perm[k]];
            if (point < 0 || point >= nPoints)
                Fail(file, connDesc->where,
                     "cell " + std::to_string(c) + " refers to point " +
                         std::to_string(point) + ", outside [0, " +
                         std::to_string(nPoints) + ")");
            dst[k] = point;
        }
        out += nodes;
        mesh.cellOffsets.push_back(out);
        mesh.cellShape.push_back(cached.kind.shape);
        mesh.cellOrder.push_back(static_cast<std::uint8_t>(cached.kind.order));
        mesh.cellFamily.push_back(cached.kind.family);
        mesh.vtkType.push_back(static_cast<std::uint8_t>(type));  // < 256: classified
    }
    mesh.connectivity.resize(out);
    ReadCellFields(file, arrays, nCells, result.skipped > 0 ? &kept : nullptr, mesh);
    return result;
}

PieceResult ReadStructuredPiece(const XmlFile& file, pugi::xml_node grid,
                                pugi::xml_node piece, int index,
                                const ReadOptions& options) {
    const std::string where = PieceWhere(index);
    pugi::xml_attribute extentAttr = piece.attribute("Extent");
    if (!extentAttr) extentAttr = grid.attribute("WholeExtent");
    std::istringstream is(extentAttr.value());
    long long e[6];
    for (long long& v : e)
        if (!(is >> v))
            Fail(file, where,
                 std::string("Extent '") + extentAttr.value() + "' is not six integers");
    std::int64_t n[3];
    std::uint64_t nPoints = 1;
    for (int a = 0; a < 3; ++a) {
        if (e[2 * a + 1] < e[2 * a] || e[2 * a + 1] - e[2 * a] >= (1LL << 31))
            Fail(file, where,
                 std::string("Extent '") + extentAttr.value() + "' is invalid");
        n[a] = e[2 * a + 1] - e[2 * a] + 1;
        if (__builtin_mul_overflow(nPoints, static_cast<std::uint64_t>(n[a]), &nPoints) ||
            nPoints > (1ULL << 62))
            Fail(file, where,
                 std::string("Extent '") + extentAttr.value() + "' is too large");
    }
    PieceResult result;
    Mesh& mesh = result.mesh;
    ReadPoints(file, piece, where, static_cast<std::int64_t>(nPoints), mesh);
    const PieceArrays arrays = CollectArrays(file, piece, where, options);
    ReadPointFields(file, arrays, static_cast<std::int64_t>(nPoints), mesh);

    // VTK drops dimensions of one point; a grid flat in any dimension has no 3-D cells.
    std::int64_t vtkCells = 1;
    for (std::int64_t d : n) vtkCells *= std::max<std::int64_t>(d - 1, 1);
    if (n[0] < 2 || n[1] < 2 || n[2] < 2) {
        result.skipped = vtkCells;
        const std::vector<std::int64_t> none;
        ReadCellFields(file, arrays, vtkCells, &none, mesh);
        return result;
    }
    const std::int64_t nCells = vtkCells;
    mesh.connectivity.resize(nCells * 8);
    mesh.cellOffsets.resize(nCells + 1);
    mesh.cellShape.assign(nCells, CellShape::Hex);
    mesh.cellOrder.assign(nCells, 1);
    mesh.cellFamily.assign(nCells, CellFamily::Lagrange);
    auto point = [&](std::int64_t i, std::int64_t j, std::int64_t k) {
        return i + n[0] * (j + n[1] * k);
    };
    std::int64_t c = 0;
    for (std::int64_t k = 0; k + 1 < n[2]; ++k)
        for (std::int64_t j = 0; j + 1 < n[1]; ++j)
            for (std::int64_t i = 0; i + 1 < n[0]; ++i, ++c) {
                // Internal hex order: lattice (i, j, k), i fastest.
                std::int64_t* dst = mesh.connectivity.data() + 8 * c;
                for (int dk = 0; dk < 2; ++dk)
                    for (int dj = 0; dj < 2; ++dj)
                        for (int di = 0; di < 2; ++di)
                            *dst++ = point(i + di, j + dj, k + dk);
                mesh.cellOffsets[c + 1] = 8 * (c + 1);
            }
    ReadCellFields(file, arrays, nCells, nullptr, mesh);
    return result;
}

}  // namespace

void vtkxml::AppendPiece(Mesh& into, bool first, Mesh&& piece, const std::string& source,
                         const std::string& where) {
    if (first) {
        into = std::move(piece);
        return;
    }
    auto matchFields = [&](std::vector<Field>& a, std::vector<Field>& b,
                           const char* kind) {
        if (a.size() != b.size())
            throw InputError(source, where,
                             std::string("has a different set of ") + kind +
                                 " fields than the first piece");
        for (Field& f : a) {
            auto it = std::find_if(b.begin(), b.end(),
                                   [&](const Field& g) { return g.name == f.name; });
            if (it == b.end() || it->components != f.components)
                throw InputError(
                    source, where,
                    std::string(kind) + " field '" + f.name +
                        "' is missing or has a different number of components");
            f.values.insert(f.values.end(), it->values.begin(), it->values.end());
        }
    };
    matchFields(into.pointFields, piece.pointFields, "point");
    matchFields(into.cellFields, piece.cellFields, "cell");
    const std::int64_t pointOffset = into.PointCount();
    const std::int64_t cellsBefore = into.CellCount();
    const std::int64_t connBefore = static_cast<std::int64_t>(into.connectivity.size());
    into.points.insert(into.points.end(), piece.points.begin(), piece.points.end());
    into.connectivity.reserve(into.connectivity.size() + piece.connectivity.size());
    for (std::int64_t p : piece.connectivity)
        into.connectivity.push_back(p + pointOffset);
    for (std::size_t c = 1; c < piece.cellOffsets.size(); ++c)
        into.cellOffsets.push_back(piece.cellOffsets[c] + connBefore);
    into.cellShape.insert(into.cellShape.end(), piece.cellShape.begin(),
                          piece.cellShape.end());
    into.cellOrder.insert(into.cellOrder.end(), piece.cellOrder.begin(),
                          piece.cellOrder.end());
    into.cellFamily.insert(into.cellFamily.end(), piece.cellFamily.begin(),
                           piece.cellFamily.end());
    // Per-cell byte arrays that a piece may lack: 0 (no ghost, unknown type) there.
    for (auto array : {&Mesh::ghost, &Mesh::vtkType}) {
        std::vector<std::uint8_t>& a = into.*array;
        const std::vector<std::uint8_t>& b = piece.*array;
        if (a.empty() && b.empty()) continue;
        a.resize(cellsBefore, 0);
        if (b.empty())
            a.resize(into.CellCount(), 0);
        else
            a.insert(a.end(), b.begin(), b.end());
    }
}

namespace {

using vtkxml::AppendPiece;

/// Reads every <Piece> of a serial file (UnstructuredGrid or StructuredGrid),
/// unvalidated.
PieceResult ReadSerial(const XmlFile& file, const ReadOptions& options) {
    const bool structured = file.type == "StructuredGrid";
    if (!structured && file.type != "UnstructuredGrid")
        Fail(file, "<VTKFile>",
             "type '" + file.type +
                 "' is not supported (UnstructuredGrid, PUnstructuredGrid, "
                 "StructuredGrid, "
                 "PStructuredGrid)");
    const pugi::xml_node grid = file.root.child(file.type.c_str());
    if (!grid) Fail(file, "<VTKFile>", "has no <" + file.type + "> element");
    PieceResult all;
    int index = 0;
    for (pugi::xml_node piece : grid.children("Piece")) {
        PieceResult r = structured
                            ? ReadStructuredPiece(file, grid, piece, index, options)
                            : ReadUnstructuredPiece(file, piece, index, options);
        AppendPiece(all.mesh, index == 0, std::move(r.mesh), file.path,
                    PieceWhere(index));
        all.skipped += r.skipped;
        ++index;
    }
    if (index == 0) Fail(file, "<" + file.type + ">", "has no <Piece>");
    return all;
}

void WarnSkipped(const std::string& path, std::int64_t skipped) {
    if (skipped > 0)
        log::Warn(path + ": skipped " + std::to_string(skipped) +
                  " cells that are not 3-D (vertices, lines, faces)");
}

}  // namespace

Mesh ReadVtkXml(const std::string& path, const ReadOptions& options) {
    const std::unique_ptr<XmlFile> file = vtkxml::LoadXmlFile(path);
    if (file->type != "PUnstructuredGrid" && file->type != "PStructuredGrid") {
        PieceResult r = ReadSerial(*file, options);
        WarnSkipped(path, r.skipped);
        r.mesh.Validate(path);
        return std::move(r.mesh);
    }
    // A parallel index: read each piece file (relative to this file's folder), validate
    // it under its own name, and concatenate.
    const std::string serialType = file->type.substr(1);
    const pugi::xml_node grid = file->root.child(file->type.c_str());
    if (!grid) Fail(*file, "<VTKFile>", "has no <" + file->type + "> element");
    const std::filesystem::path folder = std::filesystem::path(path).parent_path();
    Mesh mesh;
    std::int64_t skipped = 0;
    int index = 0;
    for (pugi::xml_node piece : grid.children("Piece")) {
        const std::string where = PieceWhere(index);
        const std::string source = piece.attribute("Source").value();
        if (source.empty()) Fail(*file, where, "has no Source attribute");
        const std::string piecePath = (folder / source).lexically_normal().string();
        std::error_code ec;
        if (!std::filesystem::is_regular_file(piecePath, ec))
            Fail(*file, where + " Source=\"" + source + "\"",
                 "no such file: " + piecePath);
        const std::unique_ptr<XmlFile> pieceFile = vtkxml::LoadXmlFile(piecePath);
        if (pieceFile->type != serialType)
            Fail(*pieceFile, "<VTKFile>",
                 "type '" + pieceFile->type + "' does not match the index " + path +
                     " (expected " + serialType + ")");
        PieceResult r = ReadSerial(*pieceFile, options);
        r.mesh.Validate(piecePath);
        AppendPiece(mesh, index == 0, std::move(r.mesh), piecePath, where);
        skipped += r.skipped;
        ++index;
    }
    if (index == 0) Fail(*file, "<" + file->type + ">", "has no <Piece>");
    WarnSkipped(path, skipped);
    return mesh;
}

}  // namespace hpray
