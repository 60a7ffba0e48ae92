// WriteVtu: VTK XML UnstructuredGrid, version 2.2, appended raw binary with UInt64
// headers.
#include "io/vtu_writer.h"

#include <algorithm>
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

void WriteVtu(const std::string& path, const Mesh& mesh, bool alwaysWriteDegrees,
              const std::function<void(const char* data, std::size_t bytes)>& written) {
    const std::int64_t nCells = mesh.CellCount();
    HPRAY_CHECK(mesh.vtkType.empty() ||
                static_cast<std::int64_t>(mesh.vtkType.size()) == nCells);
    HPRAY_CHECK(mesh.cellOffsets.size() == static_cast<std::size_t>(nCells) + 1 &&
                mesh.cellOffsets[0] == 0);

    // Cells in the VTK order of the type each is written as; HigherOrderDegrees for the
    // Lagrange types. The arrays that differ from the mesh's own (connectivity in VTK
    // node order, types, degrees) are produced a chunk of cells at a time while the file
    // is written, through one buffer, instead of being copied whole first; when every
    // cell keeps its node order the connectivity is written straight from the mesh. The
    // written type and node permutation of the last (kind, source type) seen: meshes hold
    // long runs of one kind, so the lookups run once per run, not per cell.
    struct Last {
        int shape = -1, order = -1, family = -1, source = -1;
        int type = 0;
        const std::vector<int>* perm = nullptr;
        bool identity = true;  ///< perm[k] == k for every node
    };
    // Updates `last` for cell c; true when it changed.
    auto lookup = [&mesh](std::int64_t c, Last& last) {
        const CellKind kind{mesh.cellShape[c], mesh.cellOrder[c], mesh.cellFamily[c]};
        const int source = mesh.vtkType.empty() ? 0 : mesh.vtkType[c];
        bool changed = false;
        if (static_cast<int>(kind.shape) != last.shape || kind.order != last.order ||
            static_cast<int>(kind.family) != last.family || source != last.source) {
            last.shape = static_cast<int>(kind.shape);
            last.order = kind.order;
            last.family = static_cast<int>(kind.family);
            last.source = source;
            last.type = VtkTypeToWrite(kind, source);
            last.perm = &InternalToVtk(last.type, kind);
            last.identity = true;
            for (std::size_t k = 0; k < last.perm->size(); ++k)
                last.identity &= (*last.perm)[k] == static_cast<int>(k);
            changed = true;
        }
        HPRAY_CHECK_EQ(static_cast<int>(last.perm->size()), mesh.CellNodeCount(c));
        return changed;
    };
    bool anyLagrange = alwaysWriteDegrees;
    bool sameOrder = true;  // every cell's VTK node order is its internal order
    {
        Last last;
        for (std::int64_t c = 0; c < nCells; ++c)
            if (lookup(c, last)) {
                anyLagrange |= VtkTypeNeedsDegrees(last.type);
                sameOrder &= last.identity;
            }
    }

    // What an appended array's bytes come from: the mesh, or one of the generated arrays.
    enum class Source { Data, Degrees, Connectivity, Types };
    struct Item {
        Block* block;
        Source source;
    };
    std::vector<Block> pointData, cellData;
    for (const Field& f : mesh.pointFields)
        pointData.push_back(MakeBlock("Float64", f.name, f.components, f.values));
    for (const Field& f : mesh.cellFields)
        cellData.push_back(MakeBlock("Float64", f.name, f.components, f.values));
    Block degrees{"Float64",
                  "HigherOrderDegrees",
                  3,
                  nullptr,
                  3 * sizeof(double) * static_cast<std::uint64_t>(nCells),
                  0};
    Block ghost = MakeBlock("UInt8", "vtkGhostType", 1, mesh.ghost);
    Block points = MakeBlock("Float64", "Points", 3, mesh.points);
    Block conn = MakeBlock("Int64", "connectivity", 1, mesh.connectivity);
    Block offs{"Int64",
               "offsets",
               1,
               mesh.cellOffsets.data() + 1,
               sizeof(std::int64_t) * static_cast<std::uint64_t>(nCells),
               0};
    Block typ{"UInt8", "types", 1, nullptr, static_cast<std::uint64_t>(nCells), 0};

    // Appended in this order; the cell data's tags list the fields, the degrees and the
    // ghost flags in the same order.
    std::vector<Item> order;
    for (Block& b : pointData) order.push_back({&b, Source::Data});
    for (Block& b : cellData) order.push_back({&b, Source::Data});
    if (anyLagrange) order.push_back({&degrees, Source::Degrees});
    if (!mesh.ghost.empty()) order.push_back({&ghost, Source::Data});
    order.push_back({&points, Source::Data});
    order.push_back({&conn, sameOrder ? Source::Data : Source::Connectivity});
    order.push_back({&offs, Source::Data});
    order.push_back({&typ, Source::Types});
    std::uint64_t offset = 0;
    for (const Item& item : order) {
        item.block->offset = offset;
        offset += sizeof(std::uint64_t) + item.block->bytes;
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
    if (anyLagrange) WriteArrayTag(xml, degrees, "        ");
    if (!mesh.ghost.empty()) WriteArrayTag(xml, ghost, "        ");
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
        auto emit = [&](const void* data, std::size_t bytes) {
            out.write(static_cast<const char*>(data),
                      static_cast<std::streamsize>(bytes));
            if (written) written(static_cast<const char*>(data), bytes);
        };
        const std::string head = xml.str();
        emit(head.data(), head.size());
        // The generated arrays, a chunk of whole cells at a time (at least one cell).
        constexpr std::int64_t kChunkValues = std::int64_t(1) << 17;
        std::vector<std::int64_t> chunk;
        auto generate = [&](Source source) {
            Last last;
            for (std::int64_t first = 0; first < nCells;) {
                std::int64_t end = std::min(nCells, first + kChunkValues / 3);
                if (source == Source::Connectivity) {
                    end = first + 1;
                    while (end < nCells &&
                           mesh.cellOffsets[end + 1] - mesh.cellOffsets[first] <=
                               kChunkValues)
                        ++end;
                }
                const std::int64_t values =
                    source == Source::Connectivity
                        ? mesh.cellOffsets[end] - mesh.cellOffsets[first]
                        : kChunkValues;
                if (static_cast<std::size_t>(values) > chunk.size())
                    chunk.resize(
                        static_cast<std::size_t>(std::max(values, kChunkValues)));
                std::size_t bytes = 0;
                if (source == Source::Degrees) {
                    auto* d = reinterpret_cast<double*>(chunk.data());
                    for (std::int64_t c = first; c < end; ++c)
                        for (int k = 0; k < 3; ++k) *d++ = mesh.cellOrder[c];
                    bytes = 3 * sizeof(double) * static_cast<std::size_t>(end - first);
                } else if (source == Source::Types) {
                    auto* t = reinterpret_cast<std::uint8_t*>(chunk.data());
                    for (std::int64_t c = first; c < end; ++c) {
                        lookup(c, last);
                        *t++ = static_cast<std::uint8_t>(last.type);
                    }
                    bytes = static_cast<std::size_t>(end - first);
                } else {
                    std::int64_t* o = chunk.data();
                    for (std::int64_t c = first; c < end; ++c) {
                        lookup(c, last);
                        const std::int64_t* nodes = mesh.CellNodes(c);
                        for (const int k : *last.perm) *o++ = nodes[k];
                    }
                    bytes =
                        sizeof(std::int64_t) * static_cast<std::size_t>(o - chunk.data());
                }
                emit(chunk.data(), bytes);
                first = end;
            }
        };
        for (const Item& item : order) {
            const std::uint64_t size = item.block->bytes;
            emit(&size, sizeof(size));
            if (item.source != Source::Data) {
                generate(item.source);
            } else if (size > 0) {
                emit(item.block->data, size);
            }
        }
        const char* tail = "\n  </AppendedData>\n</VTKFile>\n";
        emit(tail, std::strlen(tail));
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
