// WriteVtu: VTK XML UnstructuredGrid, version 2.2, appended raw binary with UInt64
// headers.
#include "io/vtu_writer.h"

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "io/file_bytes.h"
#include "io/vtk_cells.h"
#include "util/check.h"
#include "util/error.h"

namespace hpray {
namespace {

/// One appended array: its XML attributes and where its bytes come from.
struct Block {
    std::string type;  ///< "Float64", "Int64", "UInt8"
    std::string name;
    int components = 1;
    const void* data = nullptr;
    std::uint64_t bytes = 0;
    std::uint64_t offset = 0;  ///< after the '_' marker
};

template <typename T>
Block MakeBlock(const char* type, const std::string& name, int components,
                const std::vector<T>& values) {
    Block b;
    b.type = type;
    b.name = name;
    b.components = components;
    b.data = values.data();
    b.bytes = values.size() * sizeof(T);
    return b;
}

void WriteArrayTag(std::ostream& os, const Block& b, const char* indent) {
    os << indent << "<DataArray type=\"" << b.type << "\" Name=\"" << XmlEscape(b.name)
       << "\"";
    if (b.components != 1) os << " NumberOfComponents=\"" << b.components << "\"";
    os << " format=\"appended\" offset=\"" << b.offset << "\"/>\n";
}

}  // namespace

std::string XmlEscape(const std::string& s) {
    std::string out;
    for (char c : s) {
        switch (c) {
            case '&':
                out += "&amp;";
                break;
            case '<':
                out += "&lt;";
                break;
            case '>':
                out += "&gt;";
                break;
            case '"':
                out += "&quot;";
                break;
            case '\'':
                out += "&apos;";
                break;
            default:
                out += c;
        }
    }
    return out;
}

void WriteVtu(const std::string& path, const Mesh& mesh, bool alwaysWriteDegrees) {
    const std::int64_t nCells = mesh.CellCount();
    HPRAY_CHECK(mesh.vtkType.empty() ||
                static_cast<std::int64_t>(mesh.vtkType.size()) == nCells);

    // Cells in the VTK order of the type each is written as; HigherOrderDegrees for the
    // Lagrange types.
    std::vector<std::int64_t> connectivity(mesh.connectivity.size());
    std::vector<std::int64_t> offsets(nCells);
    std::vector<std::uint8_t> types(nCells);
    std::vector<double> degrees(3 * nCells);
    bool anyLagrange = alwaysWriteDegrees;
    // The written type and node permutation of the last (kind, source type) seen: meshes
    // hold long runs of one kind, so the lookups run once per run, not per cell.
    struct Last {
        int shape = -1, order = -1, family = -1, source = -1;
        int type = 0;
        const std::vector<int>* perm = nullptr;
    } last;
    for (std::int64_t c = 0; c < nCells; ++c) {
        const CellKind kind{mesh.cellShape[c], mesh.cellOrder[c], mesh.cellFamily[c]};
        const std::int64_t* nodes = mesh.CellNodes(c);
        std::int64_t* out = connectivity.data() + mesh.cellOffsets[c];
        const int count = mesh.CellNodeCount(c);
        const int source = mesh.vtkType.empty() ? 0 : mesh.vtkType[c];
        if (static_cast<int>(kind.shape) != last.shape || kind.order != last.order ||
            static_cast<int>(kind.family) != last.family || source != last.source) {
            last.shape = static_cast<int>(kind.shape);
            last.order = kind.order;
            last.family = static_cast<int>(kind.family);
            last.source = source;
            last.type = VtkTypeToWrite(kind, source);
            last.perm = &InternalToVtk(last.type, kind);
            anyLagrange |= VtkTypeNeedsDegrees(last.type);
        }
        const std::vector<int>& perm = *last.perm;
        HPRAY_CHECK_EQ(static_cast<int>(perm.size()), count);
        for (int k = 0; k < count; ++k) out[k] = nodes[perm[k]];
        types[c] = static_cast<std::uint8_t>(last.type);
        offsets[c] = mesh.cellOffsets[c + 1];
        for (int k = 0; k < 3; ++k) degrees[3 * c + k] = kind.order;
    }

    std::vector<Block> pointData, cellData;
    for (const Field& f : mesh.pointFields)
        pointData.push_back(MakeBlock("Float64", f.name, f.components, f.values));
    for (const Field& f : mesh.cellFields)
        cellData.push_back(MakeBlock("Float64", f.name, f.components, f.values));
    if (anyLagrange)
        cellData.push_back(MakeBlock("Float64", "HigherOrderDegrees", 3, degrees));
    if (!mesh.ghost.empty())
        cellData.push_back(MakeBlock("UInt8", "vtkGhostType", 1, mesh.ghost));
    Block points = MakeBlock("Float64", "Points", 3, mesh.points);
    Block conn = MakeBlock("Int64", "connectivity", 1, connectivity);
    Block offs = MakeBlock("Int64", "offsets", 1, offsets);
    Block typ = MakeBlock("UInt8", "types", 1, types);

    std::vector<Block*> order;
    for (Block& b : pointData) order.push_back(&b);
    for (Block& b : cellData) order.push_back(&b);
    for (Block* b : {&points, &conn, &offs, &typ}) order.push_back(b);
    std::uint64_t offset = 0;
    for (Block* b : order) {
        b->offset = offset;
        offset += sizeof(std::uint64_t) + b->bytes;
    }

    std::ostringstream xml;
    xml << "<?xml version=\"1.0\"?>\n"
        << "<VTKFile type=\"UnstructuredGrid\" version=\"2.2\" byte_order=\""
        << (HostIsBigEndian() ? "BigEndian" : "LittleEndian")
        << "\" header_type=\"UInt64\">\n"
        << "  <UnstructuredGrid>\n"
        << "    <Piece NumberOfPoints=\"" << mesh.PointCount() << "\" NumberOfCells=\""
        << nCells << "\">\n";
    xml << "      <PointData>\n";
    for (const Block& b : pointData) WriteArrayTag(xml, b, "        ");
    xml << "      </PointData>\n";
    xml << "      <CellData"
        << (anyLagrange ? " HigherOrderDegrees=\"HigherOrderDegrees\"" : "") << ">\n";
    for (const Block& b : cellData) WriteArrayTag(xml, b, "        ");
    xml << "      </CellData>\n";
    xml << "      <Points>\n";
    WriteArrayTag(xml, points, "        ");
    xml << "      </Points>\n      <Cells>\n";
    for (const Block* b : {&conn, &offs, &typ}) WriteArrayTag(xml, *b, "        ");
    xml << "      </Cells>\n    </Piece>\n  </UnstructuredGrid>\n"
        << "  <AppendedData encoding=\"raw\">\n   _";

    const std::string tmp = path + ".tmp";
    auto fail = [&](const std::string& what) {
        const std::string reason = std::strerror(errno);
        std::error_code ec;
        std::filesystem::remove(tmp, ec);
        throw InputError(path, "", what + ": " + reason);
    };
    {
        std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
        if (!out) fail("cannot create " + tmp);
        const std::string head = xml.str();
        out.write(head.data(), static_cast<std::streamsize>(head.size()));
        for (const Block* b : order) {
            const std::uint64_t size = b->bytes;
            out.write(reinterpret_cast<const char*>(&size), sizeof(size));
            if (size > 0)
                out.write(static_cast<const char*>(b->data),
                          static_cast<std::streamsize>(size));
        }
        const char* tail = "\n  </AppendedData>\n</VTKFile>\n";
        out.write(tail, static_cast<std::streamsize>(std::strlen(tail)));
        out.close();
        if (!out) fail("cannot write " + tmp);
    }
    std::error_code ec;
    std::filesystem::rename(tmp, path, ec);
    if (ec) {
        std::filesystem::remove(tmp, ec);
        throw InputError(path, "", "cannot rename " + tmp + ": " + ec.message());
    }
}

}  // namespace hpray
