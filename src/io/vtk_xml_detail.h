// Private to the VTK XML reader: the file held in memory, DataArray descriptions,
// decoding.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <memory>
#include <optional>
#include <pugixml.hpp>
#include <string>
#include <type_traits>
#include <vector>

#include "mesh/mesh.h"

namespace hpray {
struct ReadOptions;
}

namespace hpray::vtkxml {

/// VTK's numeric array types; NonNumeric covers String, Bit and anything unknown.
// clang-format off
enum class ScalarType : std::uint8_t {
    Int8, UInt8, Int16, UInt16, Int32, UInt32, Int64, UInt64, Float32, Float64, NonNumeric
};
// clang-format on
/// Bytes per value (0 for NonNumeric).
int ScalarSize(ScalarType type);
bool IsIntegerType(ScalarType type);
/// Maps a `type` attribute ("Float32", "Int64", ...) to its ScalarType.
ScalarType ParseScalarType(const std::string& name);

/// `v` with its bytes reversed.
template <typename T>
T ByteSwap(T v) {
    if constexpr (sizeof(T) == 1) {
        return v;
    } else {
        using U = std::conditional_t<
            sizeof(T) == 2, std::uint16_t,
            std::conditional_t<sizeof(T) == 4, std::uint32_t, std::uint64_t>>;
        U u;
        std::memcpy(&u, &v, sizeof(T));
        if constexpr (sizeof(T) == 2) u = __builtin_bswap16(u);
        if constexpr (sizeof(T) == 4) u = __builtin_bswap32(u);
        if constexpr (sizeof(T) == 8) u = __builtin_bswap64(u);
        std::memcpy(&v, &u, sizeof(T));
        return v;
    }
}

/// Converts n values of type Src at `src` (byte-swapped first if `swap`) to Dst.
template <typename Src, typename Dst>
void ConvertTyped(const std::uint8_t* src, std::size_t n, bool swap, Dst* dst) {
    if (swap) {
        for (std::size_t i = 0; i < n; ++i) {
            Src v;
            std::memcpy(&v, src + i * sizeof(Src), sizeof(Src));
            dst[i] = static_cast<Dst>(ByteSwap(v));
        }
    } else {
        for (std::size_t i = 0; i < n; ++i) {
            Src v;
            std::memcpy(&v, src + i * sizeof(Src), sizeof(Src));
            dst[i] = static_cast<Dst>(v);
        }
    }
}

/// Converts n values of `type` at `src` to Dst. Integer Dst only from integer types (the
/// caller checks), so no float-to-integer conversion happens here.
template <typename Dst>
void Convert(const std::uint8_t* src, ScalarType type, std::size_t n, bool swap,
             Dst* dst) {
    switch (type) {
        case ScalarType::Int8:
            ConvertTyped<std::int8_t>(src, n, swap, dst);
            break;
        case ScalarType::UInt8:
            ConvertTyped<std::uint8_t>(src, n, swap, dst);
            break;
        case ScalarType::Int16:
            ConvertTyped<std::int16_t>(src, n, swap, dst);
            break;
        case ScalarType::UInt16:
            ConvertTyped<std::uint16_t>(src, n, swap, dst);
            break;
        case ScalarType::Int32:
            ConvertTyped<std::int32_t>(src, n, swap, dst);
            break;
        case ScalarType::UInt32:
            ConvertTyped<std::uint32_t>(src, n, swap, dst);
            break;
        case ScalarType::Int64:
            ConvertTyped<std::int64_t>(src, n, swap, dst);
            break;
        case ScalarType::UInt64:
            ConvertTyped<std::uint64_t>(src, n, swap, dst);
            break;
        case ScalarType::Float32:
            if constexpr (std::is_floating_point_v<Dst>)
                ConvertTyped<float>(src, n, swap, dst);
            break;
        case ScalarType::Float64:
            if constexpr (std::is_floating_point_v<Dst>)
                ConvertTyped<double>(src, n, swap, dst);
            break;
        case ScalarType::NonNumeric:
            break;
    }
}

/// A VTK XML file in memory with its parsed XML header.
struct XmlFile {
    std::string path;
    /// The whole file. Parsed in place by pugixml when there is no appended data block.
    std::string bytes;
    /// The XML part only (everything before the appended data, closed again) when the
    /// file has an <AppendedData> block; pugixml parses this copy in place.
    std::string xmlCopy;
    /// Start of the buffer pugixml parsed: text pointers minus this are file offsets.
    const char* xmlBase = nullptr;
    pugi::xml_document doc;
    pugi::xml_node root;  ///< <VTKFile>
    std::string type;     ///< VTKFile's type attribute, e.g. "UnstructuredGrid"
    int versionMajor = 0;
    int versionMinor = 0;
    bool headerUInt64 = false;  ///< header_type="UInt64" (default UInt32)
    bool zlib = false;          ///< compressor="vtkZLibDataCompressor"
    bool swapBytes = false;     ///< the file's byte order differs from the host's
    bool hasAppended = false;
    bool appendedBase64 = false;
    std::size_t appendedBegin = 0;  ///< file offset of the byte after the '_' marker
    std::size_t appendedEnd = 0;    ///< file offset where the appended data ends
};

/// Reads `path` and parses its XML part (never the raw appended bytes). Checks the root
/// element, byte order, header type and compressor. Throws InputError naming the file.
std::unique_ptr<XmlFile> LoadXmlFile(const std::string& path);

/// Parses the XML text `xml` (size bytes, modified in place; it becomes file.xmlBase) into
/// file.doc and reads the <VTKFile> attributes: type, version, byte order, header type,
/// compressor. Fail with the file and a byte offset or the attribute on error.
void ParseHeader(XmlFile& file, char* xml, std::size_t size);

/// Throws InputError(file.path, where, what).
[[noreturn]] void Fail(const XmlFile& file, const std::string& where,
                       const std::string& what);

/// One <DataArray> element, described but not decoded.
struct ArrayDesc {
    pugi::xml_node node;
    std::string name;
    std::string typeName;
    ScalarType type = ScalarType::NonNumeric;
    int components = 1;
    enum class Format : std::uint8_t { Ascii, Binary, Appended } format = Format::Ascii;
    std::uint64_t offset = 0;  ///< appended: offset after the '_' marker
    std::string where;         ///< e.g. "<Piece> 0 <DataArray Name=\"u\">"
};

/// Describes a <DataArray>; `context` prefixes the position (e.g. "<Piece> 0").
ArrayDesc DescribeArray(const XmlFile& file, pugi::xml_node node,
                        const std::string& context);

/// Decodes `array` into `out` (resized to the value count), converting every value to
/// Dst (double or std::int64_t; integer destinations require an integer array type).
/// `tuples` >= 0 requires exactly that many tuples; < 0 accepts any whole number. Sizes
/// are checked against the data present before anything is allocated. Throws InputError
/// naming the file, the element and, for binary data, the byte offset.
template <typename Dst>
void ReadArray(const XmlFile& file, const ArrayDesc& array, std::int64_t tuples,
               std::vector<Dst>& out);

extern template void ReadArray<double>(const XmlFile&, const ArrayDesc&, std::int64_t,
                                       std::vector<double>&);
extern template void ReadArray<std::int64_t>(const XmlFile&, const ArrayDesc&,
                                             std::int64_t, std::vector<std::int64_t>&);

/// A non-negative integer attribute of `node` (NumberOfPoints, NumberOfCells), or Fail.
std::int64_t RequireCount(const XmlFile& file, pugi::xml_node node, const char* attribute,
                          const std::string& where);

/// The arrays of one piece that are not geometry.
struct PieceArrays {
    std::vector<ArrayDesc> pointFields;
    std::vector<ArrayDesc> cellFields;
    std::optional<ArrayDesc> ghost;
    std::optional<ArrayDesc> degrees;
};

/// The field arrays of a <Piece>: <PointData> and <CellData> DataArrays except the
/// ghost flags and the HigherOrderDegrees (returned apart), non-numeric arrays skipped,
/// and, when `options.fields` is set, only the arrays it names ("u.x" selects "u"); a
/// name that no array has is an error listing the available ones.
PieceArrays CollectArrays(const XmlFile& file, pugi::xml_node piece,
                          const std::string& where, const ReadOptions& options);

/// Appends `piece` to `into` (`first`: `into` becomes `piece`): points, cells (indices
/// shifted), fields matched by name, ghost and type bytes. Pieces of a .pvtu and parts of
/// one time step of a .pvd. Throws InputError(source, where) when the field sets differ.
void AppendPiece(Mesh& into, bool first, Mesh&& piece, const std::string& source,
                 const std::string& where);

}  // namespace hpray::vtkxml
