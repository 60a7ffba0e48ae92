// Private to the VTK XML reader: the file held in memory, DataArray descriptions,
// decoding.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <pugixml.hpp>
#include <string>
#include <vector>

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

}  // namespace hpray::vtkxml
