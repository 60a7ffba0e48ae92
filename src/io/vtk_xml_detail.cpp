// VTK XML file loading and DataArray decoding (ascii, inline base64, appended raw/base64,
// zlib blocks, every numeric type, either byte order), straight into the destination.
#include "io/vtk_xml_detail.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <zlib.h>

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <memory>
#include <set>
#include <sstream>
#include <type_traits>

#include "io/base64.h"
#include "io/file_bytes.h"
#include "io/mesh_io.h"
#include "util/error.h"
#include "util/log.h"

namespace hpray::vtkxml {
namespace {

std::string ByteWhere(const std::string& where, std::size_t offset) {
    std::ostringstream os;
    os << where << (where.empty() ? "" : " ") << "at byte " << offset;
    return os.str();
}

std::string Quote(const std::string& s) { return "'" + s + "'"; }

bool IsXmlSpace(char c) { return c == ' ' || c == '\n' || c == '\r' || c == '\t'; }

/// Parses a whole attribute value (surrounding whitespace allowed) as an integer.
template <typename T>
bool ParseInteger(const char* text, T& value) {
    const char* p = text;
    const char* end = text + std::strlen(text);
    while (p < end && IsXmlSpace(*p)) ++p;
    while (end > p && IsXmlSpace(end[-1])) --end;
    if (p < end && *p == '+') ++p;
    auto [ptr, ec] = std::from_chars(p, end, value);
    return ec == std::errc() && ptr == end && p != end;
}

/// a * b, or false on overflow.
bool CheckedMul(std::uint64_t a, std::uint64_t b, std::uint64_t& out) {
    return !__builtin_mul_overflow(a, b, &out);
}

/// True when the file's values can be copied bit for bit into Dst.
template <typename Dst>
bool SameRepresentation(ScalarType type) {
    if constexpr (std::is_same_v<Dst, double>) return type == ScalarType::Float64;
    if constexpr (std::is_same_v<Dst, std::int64_t>) return type == ScalarType::Int64;
    return false;
}

/// The bytes of one binary array: raw bytes in the file, or base64 text decoded on
/// demand.
class BinarySource {
  public:
    static BinarySource Raw(const std::uint8_t* data, std::size_t size,
                            std::size_t fileOffset) {
        BinarySource s;
        s.raw_ = data;
        s.size_ = size;
        s.fileOffset_ = fileOffset;
        return s;
    }
    static BinarySource Base64(const char* text, std::size_t size,
                               std::size_t fileOffset) {
        BinarySource s;
        s.decoder_ = std::make_unique<base64::Decoder>(text, size);
        s.text_ = text;
        s.size_ = size;
        s.fileOffset_ = fileOffset;
        return s;
    }

    bool IsBase64() const { return decoder_ != nullptr; }
    /// An upper bound on the bytes left.
    std::size_t RemainingBound() const {
        return decoder_ ? decoder_->RemainingBound() : size_ - pos_;
    }
    /// File offset of the next byte (for base64: of the next character).
    std::size_t FileOffset() const {
        return fileOffset_ + (decoder_ ? decoder_->Position() : pos_);
    }
    bool Base64Failed() const { return decoder_ && decoder_->Failed(); }
    char BadCharacter() const {
        const std::size_t p = decoder_->Position();
        return p < size_ ? text_[p] : '?';
    }

    /// Copies (decodes) n bytes into dst; false if fewer remain.
    bool Read(std::uint8_t* dst, std::size_t n) {
        if (decoder_) return decoder_->Decode(dst, n) == n;
        if (size_ - pos_ < n) return false;
        std::memcpy(dst, raw_ + pos_, n);
        pos_ += n;
        return true;
    }
    /// A pointer to the next n bytes (decoded into `scratch` for base64); nullptr if
    /// fewer remain. The caller has checked n against RemainingBound().
    const std::uint8_t* Take(std::size_t n, std::vector<std::uint8_t>& scratch) {
        if (decoder_) {
            scratch.resize(n);
            return decoder_->Decode(scratch.data(), n) == n ? scratch.data() : nullptr;
        }
        if (size_ - pos_ < n) return nullptr;
        const std::uint8_t* p = raw_ + pos_;
        pos_ += n;
        return p;
    }

  private:
    BinarySource() = default;
    const std::uint8_t* raw_ = nullptr;
    const char* text_ = nullptr;
    std::unique_ptr<base64::Decoder> decoder_;
    std::size_t size_ = 0;
    std::size_t pos_ = 0;
    std::size_t fileOffset_ = 0;
};

/// Reports why a binary read came up short.
[[noreturn]] void FailShort(const XmlFile& file, const ArrayDesc& a,
                            const BinarySource& src, const std::string& what,
                            std::uint64_t needed) {
    if (src.Base64Failed()) {
        const char c = src.BadCharacter();
        std::ostringstream os;
        os << "invalid base64 character ";
        if (c >= 0x21 && c < 0x7f)
            os << "'" << c << "'";
        else
            os << "0x" << std::hex << (static_cast<unsigned>(c) & 0xffu);
        Fail(file, ByteWhere(a.where, src.FileOffset()), os.str());
    }
    std::ostringstream os;
    os << what << " needs " << needed
       << " bytes but the data ends first (file truncated, "
       << "or wrong offsets or sizes)";
    Fail(file, ByteWhere(a.where, src.FileOffset()), os.str());
}

template <typename Dst>
Dst ParseAsciiValue(const XmlFile& file, const ArrayDesc& a, const char* begin,
                    const char* end, std::size_t index, std::size_t textOffset) {
    const char* p = begin;
    if (p < end && *p == '+' && end - p > 1 && p[1] != '-') ++p;
    auto bad = [&](const char* why) -> Dst {
        std::ostringstream os;
        os << "value " << index << " '"
           << std::string(begin, std::min<std::size_t>(end - begin, 40)) << "' " << why;
        Fail(file, ByteWhere(a.where, textOffset), os.str());
    };
    switch (a.type) {
        case ScalarType::Float32:
        case ScalarType::Float64: {
            double v = 0;
            auto [ptr, ec] = std::from_chars(p, end, v);
            if (ec == std::errc::result_out_of_range && ptr == end) {
                v = std::strtod(std::string(p, end).c_str(), nullptr);  // under/overflow
            } else if (ec != std::errc() || ptr != end) {
                return bad("is not a number");
            }
            if (a.type == ScalarType::Float32) v = static_cast<float>(v);
            return static_cast<Dst>(v);
        }
        case ScalarType::UInt64: {
            std::uint64_t v = 0;
            auto [ptr, ec] = std::from_chars(p, end, v);
            if (ec != std::errc() || ptr != end) return bad("is not a UInt64");
            return static_cast<Dst>(v);
        }
        default: {
            std::int64_t v = 0;
            auto [ptr, ec] = std::from_chars(p, end, v);
            if (ec != std::errc() || ptr != end)
                return bad(("is not an " + a.typeName).c_str());
            std::int64_t lo = 0, hi = 0;
            switch (a.type) {
                case ScalarType::Int8:
                    lo = -128;
                    hi = 127;
                    break;
                case ScalarType::UInt8:
                    lo = 0;
                    hi = 255;
                    break;
                case ScalarType::Int16:
                    lo = -32768;
                    hi = 32767;
                    break;
                case ScalarType::UInt16:
                    lo = 0;
                    hi = 65535;
                    break;
                case ScalarType::Int32:
                    lo = INT32_MIN;
                    hi = INT32_MAX;
                    break;
                case ScalarType::UInt32:
                    lo = 0;
                    hi = UINT32_MAX;
                    break;
                default:
                    lo = INT64_MIN;
                    hi = INT64_MAX;
                    break;
            }
            if (v < lo || v > hi)
                return bad(("is out of range for " + a.typeName).c_str());
            return static_cast<Dst>(v);
        }
    }
}

template <typename Dst>
void ReadAscii(const XmlFile& file, const ArrayDesc& a, bool exact,
               std::uint64_t expected, std::vector<Dst>& out) {
    const char* text = a.node.text().get();
    const std::size_t len = std::strlen(text);
    const bool inBuffer = text >= file.xmlBase;
    const std::size_t textOffset =
        inBuffer ? static_cast<std::size_t>(text - file.xmlBase) : 0;
    // Each value takes at least one character and one separator.
    if (exact && expected > (len + 1) / 2) {
        std::ostringstream os;
        os << "expected " << expected << " values but its text (" << len
           << " characters) cannot hold that many";
        Fail(file, a.where, os.str());
    }
    out.clear();
    if (exact) out.resize(expected);
    const char* p = text;
    const char* end = text + len;
    std::size_t index = 0;
    while (true) {
        while (p < end && IsXmlSpace(*p)) ++p;
        if (p == end) break;
        const char* q = p;
        while (p < end && !IsXmlSpace(*p)) ++p;
        if (exact && index >= expected) {
            std::ostringstream os;
            os << "holds more than the " << expected << " values expected";
            Fail(file, ByteWhere(a.where, textOffset + (q - text)), os.str());
        }
        const Dst v = ParseAsciiValue<Dst>(file, a, q, p, index, textOffset + (q - text));
        if (exact)
            out[index] = v;
        else
            out.push_back(v);
        ++index;
    }
    if (exact && index != expected) {
        std::ostringstream os;
        os << "holds " << index << " values, expected " << expected;
        if (a.components > 1)
            os << " (" << expected / a.components << " tuples of " << a.components << ")";
        Fail(file, a.where, os.str());
    }
    if (!exact && index % a.components != 0) {
        std::ostringstream os;
        os << "holds " << index
           << " values, not a multiple of NumberOfComponents=" << a.components;
        Fail(file, a.where, os.str());
    }
}

}  // namespace

int ScalarSize(ScalarType type) {
    switch (type) {
        case ScalarType::Int8:
        case ScalarType::UInt8:
            return 1;
        case ScalarType::Int16:
        case ScalarType::UInt16:
            return 2;
        case ScalarType::Int32:
        case ScalarType::UInt32:
        case ScalarType::Float32:
            return 4;
        case ScalarType::Int64:
        case ScalarType::UInt64:
        case ScalarType::Float64:
            return 8;
        case ScalarType::NonNumeric:
            return 0;
    }
    return 0;
}

bool IsIntegerType(ScalarType type) {
    return type != ScalarType::Float32 && type != ScalarType::Float64 &&
           type != ScalarType::NonNumeric;
}

ScalarType ParseScalarType(const std::string& name) {
    static const std::pair<const char*, ScalarType> kNames[] = {
        {"Int8", ScalarType::Int8},       {"UInt8", ScalarType::UInt8},
        {"Int16", ScalarType::Int16},     {"UInt16", ScalarType::UInt16},
        {"Int32", ScalarType::Int32},     {"UInt32", ScalarType::UInt32},
        {"Int64", ScalarType::Int64},     {"UInt64", ScalarType::UInt64},
        {"Float32", ScalarType::Float32}, {"Float64", ScalarType::Float64},
    };
    for (const auto& [n, t] : kNames)
        if (name == n) return t;
    return ScalarType::NonNumeric;
}

void Fail(const XmlFile& file, const std::string& where, const std::string& what) {
    throw InputError(file.path, where, what);
}

void ParseHeader(XmlFile& file, char* xml, std::size_t size) {
    file.xmlBase = xml;
    const pugi::xml_parse_result parsed =
        file.doc.load_buffer_inplace(xml, size, pugi::parse_default, pugi::encoding_utf8);
    if (!parsed) {
        Fail(file, ByteWhere("", static_cast<std::size_t>(parsed.offset)),
             std::string("XML error: ") + parsed.description());
    }
    file.root = file.doc.document_element();
    if (std::strcmp(file.root.name(), "VTKFile") != 0)
        Fail(file, "",
             std::string("root element is <") + file.root.name() +
                 ">, expected <VTKFile>");
    file.type = file.root.attribute("type").value();

    const std::string version = file.root.attribute("version").value();
    if (!version.empty()) {
        const auto dot = version.find('.');
        const bool ok = dot != std::string::npos &&
                        ParseInteger(version.substr(0, dot).c_str(), file.versionMajor) &&
                        ParseInteger(version.substr(dot + 1).c_str(), file.versionMinor);
        if (!ok)
            Fail(file, "<VTKFile>", "version " + Quote(version) + " is not MAJOR.MINOR");
    }

    const std::string order = file.root.attribute("byte_order").value();
    bool fileBig = HostIsBigEndian();
    if (order == "LittleEndian")
        fileBig = false;
    else if (order == "BigEndian")
        fileBig = true;
    else if (!order.empty())
        Fail(file, "<VTKFile>",
             "byte_order " + Quote(order) + " is neither LittleEndian nor BigEndian");
    file.swapBytes = fileBig != HostIsBigEndian();

    const std::string header = file.root.attribute("header_type").value();
    if (header == "UInt64")
        file.headerUInt64 = true;
    else if (!header.empty() && header != "UInt32")
        Fail(file, "<VTKFile>",
             "header_type " + Quote(header) + " is not UInt32 or UInt64");

    const std::string compressor = file.root.attribute("compressor").value();
    if (compressor == "vtkZLibDataCompressor")
        file.zlib = true;
    else if (!compressor.empty())
        Fail(file, "<VTKFile>",
             "compressor " + Quote(compressor) +
                 " is not supported (only vtkZLibDataCompressor)");
}

std::unique_ptr<XmlFile> LoadXmlFile(const std::string& path) {
    auto file = std::make_unique<XmlFile>();
    file->path = path;
    file->bytes = ReadWholeFile(path);
    std::string& bytes = file->bytes;

    // Raw appended data may hold any bytes, so the XML parser only sees what precedes it.
    const std::size_t tag = bytes.find("<AppendedData");
    char* xml = bytes.data();
    std::size_t xmlSize = bytes.size();
    if (tag != std::string::npos) {
        const std::size_t close = bytes.find('>', tag);
        if (close == std::string::npos)
            Fail(*file, ByteWhere("<AppendedData>", tag),
                 "unterminated tag (file truncated?)");
        const std::size_t marker = bytes.find_first_not_of(" \t\r\n", close + 1);
        if (marker == std::string::npos || bytes[marker] != '_')
            Fail(*file, ByteWhere("<AppendedData>", tag),
                 "the appended data does not start with the '_' marker");
        file->hasAppended = true;
        file->appendedBegin = marker + 1;
        file->xmlCopy.reserve(marker + 32);
        file->xmlCopy.assign(bytes, 0, marker);
        file->xmlCopy += "</AppendedData></VTKFile>";
        xml = file->xmlCopy.data();
        xmlSize = file->xmlCopy.size();
    }
    ParseHeader(*file, xml, xmlSize);
    if (file->hasAppended) {
        const pugi::xml_node appended = file->root.child("AppendedData");
        const std::string encoding = appended.attribute("encoding").value();
        if (encoding == "base64")
            file->appendedBase64 = true;
        else if (!encoding.empty() && encoding != "raw")
            Fail(*file, "<AppendedData>",
                 "encoding " + Quote(encoding) + " is neither raw nor base64");
        // The last closing tag ends raw data (earlier matches may be data bytes).
        const std::size_t end = file->appendedBase64
                                    ? bytes.find("</AppendedData>", file->appendedBegin)
                                    : bytes.rfind("</AppendedData>");
        if (end == std::string::npos || end < file->appendedBegin)
            Fail(*file, ByteWhere("<AppendedData>", tag),
                 "the appended data is not closed by </AppendedData> (file truncated?)");
        file->appendedEnd = end;
    }
    return file;
}

ArrayDesc DescribeArray(const XmlFile& file, pugi::xml_node node,
                        const std::string& context) {
    ArrayDesc a;
    a.node = node;
    a.name = node.attribute("Name").value();
    a.typeName = node.attribute("type").value();
    a.type = ParseScalarType(a.typeName);
    a.where =
        context + (context.empty() ? "" : " ") + "<DataArray Name=\"" + a.name + "\">";
    if (const pugi::xml_attribute nc = node.attribute("NumberOfComponents")) {
        if (!ParseInteger(nc.value(), a.components) || a.components < 1 ||
            a.components > 1000000)
            Fail(file, a.where,
                 "NumberOfComponents " + Quote(nc.value()) + " is invalid");
    }
    const std::string format = node.attribute("format").value();
    if (format == "ascii") {
        a.format = ArrayDesc::Format::Ascii;
    } else if (format == "binary") {
        a.format = ArrayDesc::Format::Binary;
    } else if (format == "appended") {
        a.format = ArrayDesc::Format::Appended;
        if (!file.hasAppended)
            Fail(file, a.where, "format is appended but there is no <AppendedData>");
        if (!ParseInteger(node.attribute("offset").value(), a.offset))
            Fail(
                file, a.where,
                "offset " + Quote(node.attribute("offset").value()) + " is not a number");
    } else {
        Fail(file, a.where,
             "format " + Quote(format) + " is not ascii, binary or appended");
    }
    return a;
}

template <typename Dst>
void ReadArray(const XmlFile& file, const ArrayDesc& a, std::int64_t tuples,
               std::vector<Dst>& out) {
    if (a.type == ScalarType::NonNumeric)
        Fail(file, a.where, "type " + Quote(a.typeName) + " is not a numeric type");
    if (std::is_integral_v<Dst> && !IsIntegerType(a.type))
        Fail(file, a.where, "type " + a.typeName + " is not an integer type");
    const bool exact = tuples >= 0;
    std::uint64_t expected = 0;  // values
    if (exact && !CheckedMul(static_cast<std::uint64_t>(tuples), a.components, expected))
        Fail(file, a.where, "declared size overflows");
    if (a.format == ArrayDesc::Format::Ascii) {
        ReadAscii(file, a, exact, expected, out);
        return;
    }

    const std::uint64_t valueSize = ScalarSize(a.type);
    const std::uint64_t tupleBytes = valueSize * a.components;
    std::uint64_t expectedBytes = 0;
    if (exact && !CheckedMul(expected, valueSize, expectedBytes))
        Fail(file, a.where, "declared size overflows");

    BinarySource src = [&] {
        if (a.format == ArrayDesc::Format::Binary) {
            const char* text = a.node.text().get();
            const std::size_t off =
                text >= file.xmlBase ? static_cast<std::size_t>(text - file.xmlBase) : 0;
            return BinarySource::Base64(text, std::strlen(text), off);
        }
        const std::size_t available = file.appendedEnd - file.appendedBegin;
        if (a.offset >= available) {
            std::ostringstream os;
            os << "appended offset " << a.offset
               << " is beyond the end of the appended data (" << available << " bytes)";
            Fail(file, a.where, os.str());
        }
        const std::size_t begin = file.appendedBegin + a.offset;
        const std::size_t size = file.appendedEnd - begin;
        if (file.appendedBase64)
            return BinarySource::Base64(file.bytes.data() + begin, size, begin);
        return BinarySource::Raw(
            reinterpret_cast<const std::uint8_t*>(file.bytes.data()) + begin, size,
            begin);
    }();

    const std::size_t headerSize = file.headerUInt64 ? 8 : 4;
    auto readWord = [&](const char* what) -> std::uint64_t {
        std::uint8_t buf[8];
        if (!src.Read(buf, headerSize)) FailShort(file, a, src, what, headerSize);
        if (headerSize == 8) {
            std::uint64_t v;
            std::memcpy(&v, buf, 8);
            return file.swapBytes ? ByteSwap(v) : v;
        }
        std::uint32_t v;
        std::memcpy(&v, buf, 4);
        return file.swapBytes ? ByteSwap(v) : v;
    };
    auto checkTotal = [&](std::uint64_t bytes, std::size_t where) {
        if (bytes % tupleBytes != 0) {
            std::ostringstream os;
            os << "holds " << bytes << " bytes, not a whole number of " << a.components
               << "-component " << a.typeName << " tuples";
            Fail(file, ByteWhere(a.where, where), os.str());
        }
        if (exact && bytes != expectedBytes) {
            std::ostringstream os;
            os << "holds " << bytes / tupleBytes << " tuples, expected " << tuples;
            Fail(file, ByteWhere(a.where, where), os.str());
        }
    };

    std::vector<std::uint8_t> scratch;
    const bool direct = SameRepresentation<Dst>(a.type) && !file.swapBytes;
    if (!file.zlib) {
        const std::size_t headerAt = src.FileOffset();
        const std::uint64_t bytes = readWord("the size header");
        checkTotal(bytes, headerAt);
        if (bytes > src.RemainingBound()) FailShort(file, a, src, "the array", bytes);
        const std::size_t n = bytes / valueSize;
        out.resize(n);
        if (direct) {
            if (!src.Read(reinterpret_cast<std::uint8_t*>(out.data()), bytes))
                FailShort(file, a, src, "the array", bytes);
        } else {
            const std::uint8_t* p = src.Take(bytes, scratch);
            if (!p) FailShort(file, a, src, "the array", bytes);
            Convert(p, a.type, n, file.swapBytes, out.data());
        }
        return;
    }

    // zlib: [nblocks, blockSize, lastPartialSize, compressedSize[nblocks]], then the
    // blocks.
    const std::size_t headerAt = src.FileOffset();
    const std::uint64_t blocks = readWord("the compression header");
    const std::uint64_t blockSize = readWord("the compression header");
    const std::uint64_t lastSize = readWord("the compression header");
    if (blocks > src.RemainingBound() / headerSize) {
        std::ostringstream os;
        os << "compression header declares " << blocks
           << " blocks, more than the data holds";
        Fail(file, ByteWhere(a.where, headerAt), os.str());
    }
    std::vector<std::uint64_t> compressed(blocks);
    std::uint64_t compressedTotal = 0;
    for (auto& c : compressed) {
        c = readWord("the compression header");
        if (__builtin_add_overflow(compressedTotal, c, &compressedTotal))
            Fail(file, ByteWhere(a.where, headerAt), "compressed sizes overflow");
    }
    if (lastSize > blockSize || (blocks > 0 && blockSize == 0)) {
        std::ostringstream os;
        os << "compression header has block size " << blockSize << " and last block size "
           << lastSize;
        Fail(file, ByteWhere(a.where, headerAt), os.str());
    }
    std::uint64_t total = 0;
    if (blocks > 0) {
        if (!CheckedMul(blocks - 1, blockSize, total) ||
            __builtin_add_overflow(total, lastSize ? lastSize : blockSize, &total))
            Fail(file, ByteWhere(a.where, headerAt), "uncompressed size overflows");
    }
    checkTotal(total, headerAt);
    const std::size_t dataAt = src.FileOffset();
    if (compressedTotal > src.RemainingBound())
        FailShort(file, a, src, "the compressed blocks", compressedTotal);
    // deflate expands at most 1032:1, so a larger claim is not backed by the data
    // present.
    for (std::uint64_t b = 0; b < blocks; ++b) {
        const std::uint64_t len = (b + 1 == blocks && lastSize) ? lastSize : blockSize;
        if (len / 1032 > compressed[b] + 1) {
            std::ostringstream os;
            os << "block " << b << " claims " << len << " bytes from " << compressed[b]
               << " compressed bytes, more than zlib can produce";
            Fail(file, ByteWhere(a.where, dataAt), os.str());
        }
    }
    const std::size_t n = total / valueSize;
    // Not zero-filled (every byte is inflated into it; its pages are first touched by
    // the threads that inflate).
    std::unique_ptr<std::uint8_t[]> inflated;
    std::uint8_t* dst;
    if (direct) {
        out.resize(n);
        dst = reinterpret_cast<std::uint8_t*>(out.data());
    } else {
        inflated.reset(new std::uint8_t[std::max<std::size_t>(total, 1)]);
        dst = inflated.get();
    }
    const auto blockLength = [&](std::uint64_t b) {
        return (b + 1 == blocks && lastSize) ? lastSize : blockSize;
    };
    const auto failBlock = [&](std::uint64_t b, int rc, uLongf produced,
                               std::size_t blockAt) {
        std::ostringstream os;
        os << "zlib block " << b << " of " << blocks << ": ";
        if (rc == Z_OK)
            os << "inflates to " << produced << " bytes, expected " << blockLength(b);
        else if (rc == Z_BUF_ERROR)
            os << "inflates to more than " << blockLength(b) << " bytes or is incomplete";
        else if (rc == Z_DATA_ERROR)
            os << "corrupt compressed data";
        else
            os << "zlib error " << rc;
        Fail(file, ByteWhere(a.where, blockAt), os.str());
    };
    if (src.IsBase64()) {
        // Decoded block by block into the one scratch buffer.
        std::uint64_t at = 0;
        for (std::uint64_t b = 0; b < blocks; ++b) {
            const std::uint64_t len = blockLength(b);
            const std::size_t blockAt = src.FileOffset();
            const std::uint8_t* c = src.Take(compressed[b], scratch);
            if (!c) FailShort(file, a, src, "a compressed block", compressed[b]);
            uLongf produced = static_cast<uLongf>(len);
            const int rc =
                uncompress(dst + at, &produced, c, static_cast<uLong>(compressed[b]));
            if (rc != Z_OK || produced != len) failBlock(b, rc, produced, blockAt);
            at += len;
        }
    } else {
        // Raw bytes stay in place: the blocks (independent zlib streams) inflate side by
        // side. The errors are those of inflating them in order: the first bad block, or
        // a block the data ends in if every block before it inflates.
        struct Block {
            const std::uint8_t* data;
            std::size_t at;  // file offset
            int rc;
            uLongf produced;
        };
        std::vector<Block> list(blocks);
        std::uint64_t present = 0;
        for (; present < blocks; ++present) {
            list[present].at = src.FileOffset();
            list[present].data = src.Take(compressed[present], scratch);
            if (!list[present].data) break;
        }
        tbb::parallel_for(
            tbb::blocked_range<std::uint64_t>(0, present, 8),
            [&](const tbb::blocked_range<std::uint64_t>& range) {
                for (std::uint64_t b = range.begin(); b < range.end(); ++b) {
                    Block& k = list[b];
                    k.produced = static_cast<uLongf>(blockLength(b));
                    k.rc = uncompress(dst + b * blockSize, &k.produced, k.data,
                                      static_cast<uLong>(compressed[b]));
                }
            });
        for (std::uint64_t b = 0; b < present; ++b)
            if (list[b].rc != Z_OK || list[b].produced != blockLength(b))
                failBlock(b, list[b].rc, list[b].produced, list[b].at);
        if (present < blocks)
            FailShort(file, a, src, "a compressed block", compressed[present]);
    }
    if (!direct) {
        out.resize(n);
        // In parallel: a million-cell mesh's connectivity is millions of values.
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, std::size_t(1) << 16),
                          [&](const tbb::blocked_range<std::size_t>& range) {
                              Convert(dst + range.begin() * valueSize, a.type,
                                      range.size(), file.swapBytes,
                                      out.data() + range.begin());
                          });
    }
}

template void ReadArray<double>(const XmlFile&, const ArrayDesc&, std::int64_t,
                                std::vector<double>&);
template void ReadArray<std::int64_t>(const XmlFile&, const ArrayDesc&, std::int64_t,
                                      std::vector<std::int64_t>&);

namespace {

constexpr const char* kGhostName = "vtkGhostType";
constexpr const char* kDegreesName = "HigherOrderDegrees";

/// "u.x" -> "u", "u[2]" -> "u", "u.magnitude" -> "u"; "" when there is no suffix.
std::string StripComponent(const std::string& name) {
    if (!name.empty() && name.back() == ']') {
        const auto b = name.rfind('[');
        if (b != std::string::npos && b > 0) return name.substr(0, b);
    }
    const auto dot = name.rfind('.');
    if (dot != std::string::npos && dot > 0) return name.substr(0, dot);
    return "";
}

}  // namespace

std::int64_t RequireCount(const XmlFile& file, pugi::xml_node node, const char* attribute,
                          const std::string& where) {
    const pugi::xml_attribute attr = node.attribute(attribute);
    const char* text = attr.value();
    while (*text == ' ' || *text == '\t' || *text == '\n' || *text == '\r') ++text;
    char* end = nullptr;
    errno = 0;
    const long long value = std::strtoll(text, &end, 10);
    while (end && (*end == ' ' || *end == '\t' || *end == '\n' || *end == '\r')) ++end;
    if (!attr || end == text || *end != '\0' || errno != 0 || value < 0)
        Fail(file, where,
             std::string(attribute) + " '" + attr.value() +
                 "' is not a non-negative integer");
    return value;
}

PieceArrays CollectArrays(const XmlFile& file, pugi::xml_node piece,
                          const std::string& where, const ReadOptions& options) {
    PieceArrays arrays;
    std::vector<std::string> available;
    // <CellData HigherOrderDegrees="name"> may name the degrees array; VTK's writers call
    // it HigherOrderDegrees.
    std::string degreesName = piece.child("CellData").attribute(kDegreesName).value();
    if (degreesName.empty()) degreesName = kDegreesName;
    auto collect = [&](const char* element, std::vector<ArrayDesc>& out, bool cellData) {
        for (pugi::xml_node n : piece.child(element).children("DataArray")) {
            ArrayDesc a = DescribeArray(file, n, where + " <" + element + ">");
            if (cellData && a.name == kGhostName) {
                arrays.ghost = a;
                continue;
            }
            if (cellData && a.name == degreesName) {
                arrays.degrees = a;
                continue;
            }
            if (a.name == kGhostName || a.name == kDegreesName) continue;  // point ghosts
            if (a.type == ScalarType::NonNumeric) {
                log::Debug(file.path + ": skipping non-numeric array '" + a.name + "'");
                continue;
            }
            available.push_back(a.name);
            out.push_back(std::move(a));
        }
    };
    collect("PointData", arrays.pointFields, false);
    collect("CellData", arrays.cellFields, true);
    if (!options.fields) return arrays;

    // Keep only the requested arrays; a component name selects its whole array.
    std::set<std::string> selected;
    auto exists = [&](const std::string& n) {
        return std::find(available.begin(), available.end(), n) != available.end();
    };
    for (const std::string& name : *options.fields) {
        if (exists(name)) {
            selected.insert(name);
            continue;
        }
        const std::string base = StripComponent(name);
        if (!base.empty() && exists(base)) {
            selected.insert(base);
            continue;
        }
        std::string list;
        for (const std::string& n : available) list += (list.empty() ? "" : ", ") + n;
        Fail(file, where,
             "field '" + name + "' does not exist; available: " +
                 (list.empty() ? std::string("(none)") : list));
    }
    auto keep = [&](std::vector<ArrayDesc>& v) {
        v.erase(
            std::remove_if(v.begin(), v.end(),
                           [&](const ArrayDesc& a) { return !selected.count(a.name); }),
            v.end());
    };
    keep(arrays.pointFields);
    keep(arrays.cellFields);
    return arrays;
}

}  // namespace hpray::vtkxml
