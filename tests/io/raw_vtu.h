// Test helper: the arrays of a .vtu with appended raw data (as WriteVtu writes it),
// decoded from the file's bytes with pugixml and memcpy instead of hpray's reader, so a
// test sees the cell types and node order that VTK, ParaView and VisIt will see, not
// what hpray's converting reader makes of them.
#pragma once

#include <cstdint>
#include <cstring>
#include <fstream>
#include <iterator>
#include <pugixml.hpp>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

namespace hpray::test {

/// One .vtu held in memory: its XML header parsed, its appended block located. Only
/// what WriteVtu produces is accepted (one piece, little-endian, uncompressed appended
/// raw data with UInt32 or UInt64 block headers); anything else throws
/// std::runtime_error, which fails the calling test.
class RawVtu {
  public:
    explicit RawVtu(const std::string& path) : path_(path) {
        std::ifstream in(path, std::ios::binary);
        if (!in) Fail("cannot open");
        bytes_.assign(std::istreambuf_iterator<char>(in),
                      std::istreambuf_iterator<char>());
        const std::size_t appended = bytes_.find("<AppendedData");
        if (appended == std::string::npos) Fail("no <AppendedData>");
        const std::string tag = "<AppendedData encoding=\"raw\">";
        if (bytes_.compare(appended, tag.size(), tag) != 0)
            Fail("appended data is not raw");
        base_ = bytes_.find('_', appended);
        if (base_ == std::string::npos) Fail("no '_' marker");
        ++base_;
        // The XML before the appended block, closed again, is a whole document.
        const std::string xml = bytes_.substr(0, appended) + "</VTKFile>";
        if (!doc_.load_string(xml.c_str())) Fail("the XML header does not parse");
        const pugi::xml_node root = doc_.child("VTKFile");
        if (std::string(root.attribute("type").value()) != "UnstructuredGrid")
            Fail("not an UnstructuredGrid");
        if (std::string(root.attribute("byte_order").value()) != "LittleEndian")
            Fail("not little-endian");
        if (root.attribute("compressor")) Fail("compressed");
        const std::string header = root.attribute("header_type").value();
        if (header != "UInt64" && header != "UInt32" && !header.empty())
            Fail("header_type " + header);
        header64_ = header == "UInt64";
        piece_ = root.child("UnstructuredGrid").child("Piece");
        if (!piece_ || piece_.next_sibling("Piece")) Fail("not exactly one <Piece>");
    }

    std::int64_t Cells() const { return piece_.attribute("NumberOfCells").as_llong(-1); }

    /// Whether <`section`> ("Cells", "CellData", "PointData", "Points") of the piece
    /// has a DataArray named `name`.
    bool Has(const char* section, const char* name) const {
        return static_cast<bool>(Find(section, name));
    }

    /// The values of DataArray `name` in <`section`>, whose type must be T's VTK name.
    template <typename T>
    std::vector<T> Values(const char* section, const char* name) const {
        const pugi::xml_node node = Find(section, name);
        if (!node) Fail(std::string("no DataArray ") + name + " in <" + section + ">");
        if (std::string(node.attribute("type").value()) != TypeName<T>())
            Fail(std::string(name) + " is of type " + node.attribute("type").value());
        if (std::string(node.attribute("format").value()) != "appended")
            Fail(std::string(name) + " is not appended");
        const std::size_t at = base_ + node.attribute("offset").as_ullong();
        const std::size_t headerBytes = header64_ ? 8 : 4;
        if (at + headerBytes > bytes_.size()) Fail(std::string(name) + ": past the end");
        std::uint64_t size = 0;
        if (header64_) {
            std::memcpy(&size, bytes_.data() + at, 8);
        } else {
            std::uint32_t size32 = 0;
            std::memcpy(&size32, bytes_.data() + at, 4);
            size = size32;
        }
        if (size % sizeof(T) != 0 || at + headerBytes + size > bytes_.size())
            Fail(std::string(name) + ": bad block size");
        std::vector<T> values(size / sizeof(T));
        std::memcpy(values.data(), bytes_.data() + at + headerBytes, size);
        return values;
    }

  private:
    template <typename T>
    static const char* TypeName() {
        if constexpr (std::is_same_v<T, std::uint8_t>) return "UInt8";
        if constexpr (std::is_same_v<T, std::int32_t>) return "Int32";
        if constexpr (std::is_same_v<T, std::int64_t>) return "Int64";
        if constexpr (std::is_same_v<T, double>) return "Float64";
        return "?";
    }

    pugi::xml_node Find(const char* section, const char* name) const {
        for (pugi::xml_node n : piece_.child(section).children("DataArray"))
            if (std::string(n.attribute("Name").value()) == name) return n;
        return {};
    }

    [[noreturn]] void Fail(const std::string& what) const {
        throw std::runtime_error(path_ + ": " + what);
    }

    std::string path_;
    std::string bytes_;
    pugi::xml_document doc_;
    pugi::xml_node piece_;
    std::size_t base_ = 0;
    bool header64_ = false;
};

}  // namespace hpray::test
