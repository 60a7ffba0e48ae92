// Legacy VTK reader (.vtk, "# vtk DataFile Version 2.0".."5.1"): UNSTRUCTURED_GRID in
// ASCII or BINARY (big-endian), both CELLS layouts, POINT_DATA/CELL_DATA attributes and
// FIELDs.
//
// File layout (VTK "File Formats" guide): a version line, a title line, ASCII|BINARY,
// "DATASET UNSTRUCTURED_GRID", then keyword lines each followed by their data:
//   POINTS n type                       3n values
//   CELLS n size                        before 5.1: per cell, its node count then its ids
//   CELLS nOffsets nConnectivity        5.1: OFFSETS type + nOffsets values,
//                                       CONNECTIVITY type + nConnectivity values
//   CELL_TYPES n                        n ints
//   POINT_DATA n | CELL_DATA n          then attributes: SCALARS name type [comps] +
//                                       LOOKUP_TABLE name, VECTORS/NORMALS name type,
//                                       TENSORS[6] name type, TEXTURE_COORDINATES name
//                                       dim type, COLOR_SCALARS name comps, GLOBAL_IDS /
//                                       PEDIGREE_IDS name type, LOOKUP_TABLE name size,
//                                       FIELD name nArrays (+ per array: name comps
//                                       tuples type, values), METADATA blocks.
// Keyword lines are text in both encodings; in a BINARY file the data after a keyword
// line are raw big-endian values (int = 4 bytes, long = 8) starting right after its
// newline.
#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <sstream>
#include <string>
#include <string_view>
#include <vector>

#include "io/file_bytes.h"
#include "io/mesh_io.h"
#include "io/vtk_cells.h"
#include "util/check.h"
#include "util/error.h"
#include "util/log.h"

namespace hpray {
namespace {

std::string Lower(std::string_view s) {
    std::string out(s);
    std::transform(out.begin(), out.end(), out.begin(),
                   [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    return out;
}

// VTK writes array names with %XX escapes for spaces and other special characters.
std::string DecodeName(std::string_view s) {
    std::string out;
    for (std::size_t i = 0; i < s.size(); ++i) {
        if (s[i] == '%' && i + 2 < s.size() &&
            std::isxdigit(static_cast<unsigned char>(s[i + 1])) &&
            std::isxdigit(static_cast<unsigned char>(s[i + 2]))) {
            out += static_cast<char>(
                std::stoi(std::string(s.substr(i + 1, 2)), nullptr, 16));
            i += 2;
        } else {
            out += s[i];
        }
    }
    return out;
}

// Cell types of dimension 0..2 (vtkCellType.h): skipped with one warning.
bool IsLowerDimensional(int type) {
    switch (type) {
        case 0:   // VTK_EMPTY_CELL
        case 1:   // VTK_VERTEX
        case 2:   // VTK_POLY_VERTEX
        case 3:   // VTK_LINE
        case 4:   // VTK_POLY_LINE
        case 5:   // VTK_TRIANGLE
        case 6:   // VTK_TRIANGLE_STRIP
        case 7:   // VTK_POLYGON
        case 8:   // VTK_PIXEL
        case 9:   // VTK_QUAD
        case 21:  // VTK_QUADRATIC_EDGE
        case 22:  // VTK_QUADRATIC_TRIANGLE
        case 23:  // VTK_QUADRATIC_QUAD
        case 28:  // VTK_BIQUADRATIC_QUAD
        case 30:  // VTK_QUADRATIC_POLYGON
        case 34:  // VTK_BIQUADRATIC_TRIANGLE
        case 35:  // VTK_CUBIC_LINE
        case 36:  // VTK_QUADRATIC_LINEAR_QUAD
        case 51:  // VTK_PARAMETRIC_CURVE
        case 52:  // VTK_PARAMETRIC_SURFACE
        case 53:  // VTK_PARAMETRIC_TRI_SURFACE
        case 54:  // VTK_PARAMETRIC_QUAD_SURFACE
        case 60:  // VTK_HIGHER_ORDER_EDGE
        case 61:  // VTK_HIGHER_ORDER_TRIANGLE
        case 62:  // VTK_HIGHER_ORDER_QUAD
        case 63:  // VTK_HIGHER_ORDER_POLYGON
        case 68:  // VTK_LAGRANGE_CURVE
        case 69:  // VTK_LAGRANGE_TRIANGLE
        case 70:  // VTK_LAGRANGE_QUADRILATERAL
        case 75:  // VTK_BEZIER_CURVE
        case 76:  // VTK_BEZIER_TRIANGLE
        case 77:  // VTK_BEZIER_QUADRILATERAL
            return true;
    }
    return false;
}

// A legacy data type: its size in a BINARY file and how to decode it.
enum class Kind { Int, Unsigned, Float };
struct DataType {
    std::string name;
    int bytes = 0;
    Kind kind = Kind::Float;
};

class LegacyParser {
  public:
    LegacyParser(const std::string& path, const ReadOptions& options)
        : path_(path), options_(options), buf_(ReadWholeFile(path)) {}

    Mesh Parse();

  private:
    // ---- positions and errors ----
    std::string Where(std::size_t pos) const { return ByteOrLineWhere(buf_, pos, binary_); }
    [[noreturn]] void FailAt(std::size_t pos, const std::string& message) const {
        throw InputError(path_, Where(pos), message);
    }
    [[noreturn]] void Fail(const std::string& message) const { FailAt(last_, message); }

    // ---- text ----
    static bool IsSpace(char c) {
        return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\f' || c == '\v';
    }
    // The next non-blank line, split into words; pos_ ends after its newline (where
    // binary data start). Returns false at the end of the file.
    bool NextLine(std::vector<std::string_view>* words) {
        while (pos_ < buf_.size() && IsSpace(buf_[pos_])) ++pos_;
        if (pos_ >= buf_.size()) return false;
        lineStart_ = last_ = pos_;
        std::size_t eol = buf_.find('\n', pos_);
        if (eol == std::string::npos) eol = buf_.size();
        words->clear();
        std::size_t i = pos_;
        while (i < eol) {
            while (i < eol && IsSpace(buf_[i])) ++i;
            const std::size_t start = i;
            while (i < eol && !IsSpace(buf_[i])) ++i;
            if (i > start) words->emplace_back(buf_.data() + start, i - start);
        }
        pos_ = eol < buf_.size() ? eol + 1 : eol;
        return true;
    }
    // The rest of a raw line (for the title), without the newline.
    std::string RawLine() {
        const std::size_t start = pos_;
        std::size_t eol = buf_.find('\n', pos_);
        if (eol == std::string::npos) eol = buf_.size();
        pos_ = eol < buf_.size() ? eol + 1 : eol;
        std::string line = buf_.substr(start, eol - start);
        if (!line.empty() && line.back() == '\r') line.pop_back();
        return line;
    }
    std::string_view Token(const char* what) {
        while (pos_ < buf_.size() && IsSpace(buf_[pos_])) ++pos_;
        last_ = pos_;
        if (pos_ >= buf_.size()) Fail(std::string("unexpected end of file in ") + what);
        const std::size_t start = pos_;
        while (pos_ < buf_.size() && !IsSpace(buf_[pos_])) ++pos_;
        return std::string_view(buf_.data() + start, pos_ - start);
    }
    long long ParseInt(std::string_view t, const std::string& what) const {
        long long v = 0;
        auto [end, ec] = std::from_chars(t.data(), t.data() + t.size(), v);
        if (ec != std::errc() || end != t.data() + t.size())
            Fail("expected an integer for " + what + ", found '" +
                 std::string(t.substr(0, 40)) + "'");
        return v;
    }
    double ParseReal(std::string_view t, const std::string& what) const {
        double v = 0;
        auto [end, ec] = std::from_chars(t.data(), t.data() + t.size(), v);
        if (ec == std::errc::result_out_of_range && end == t.data() + t.size()) {
            v = std::strtod(std::string(t).c_str(), nullptr);
        } else if (ec != std::errc() || end != t.data() + t.size()) {
            Fail("expected a number for " + what + ", found '" +
                 std::string(t.substr(0, 40)) + "'");
        }
        return v;
    }
    // A count on a keyword line: a non-negative integer.
    std::uint64_t Count(std::string_view t, const std::string& what) const {
        const long long v = ParseInt(t, what);
        if (v < 0) Fail(what + " must not be negative");
        return static_cast<std::uint64_t>(v);
    }
    void NeedWords(const std::vector<std::string_view>& w, std::size_t n,
                   const char* form) const {
        if (w.size() < n) FailAt(lineStart_, std::string("expected '") + form + "'");
    }

    // ---- data ----
    DataType Type(std::string_view name) const;
    // Rejects `count` values of `bytes` each (binary) or of >= 2 bytes (ASCII) that the
    // rest of the file cannot hold, before anything is allocated for them.
    void CheckCount(std::uint64_t count, int bytes, const std::string& what) const {
        const std::uint64_t left = buf_.size() - std::min(pos_, buf_.size());
        const std::uint64_t each = binary_ ? static_cast<std::uint64_t>(bytes) : 2;
        if (count > left / each) {
            std::ostringstream os;
            os << what << ": " << count << " values declared, more than the " << left
               << " bytes left in the file can hold";
            FailAt(lineStart_, os.str());
        }
    }
    // Reads one value (last_ = its position).
    double RealValue(const DataType& t, const std::string& what) {
        if (!binary_) return ParseReal(Token(what.c_str()), what);
        return static_cast<double>(BinaryValue(t, what, nullptr));
    }
    long long IntValue(const DataType& t, const std::string& what) {
        if (!binary_) {
            const std::string_view tok = Token(what.c_str());
            if (t.kind == Kind::Float) {
                const double d = ParseReal(tok, what);
                if (d != std::floor(d) || std::abs(d) > 9e15)
                    Fail("expected an integer for " + what);
                return static_cast<long long>(d);
            }
            return ParseInt(tok, what);
        }
        long long i = 0;
        const double d = BinaryValue(t, what, &i);
        if (t.kind == Kind::Float) {
            if (d != std::floor(d) || std::abs(d) > 9e15)
                Fail("expected an integer for " + what);
            return static_cast<long long>(d);
        }
        return i;
    }
    // Big-endian value; integers also returned exactly through `asInt`.
    double BinaryValue(const DataType& t, const std::string& what, long long* asInt) {
        last_ = pos_;
        if (buf_.size() - pos_ < static_cast<std::size_t>(t.bytes))
            Fail("binary data cut short in " + what);
        unsigned char b[8];
        for (int i = 0; i < t.bytes; ++i)
            b[i] = static_cast<unsigned char>(buf_[pos_ + i]);
        pos_ += t.bytes;
        std::uint64_t u = 0;
        for (int i = 0; i < t.bytes; ++i) u = (u << 8) | b[i];
        if (t.kind == Kind::Float) {
            if (t.bytes == 4) {
                const std::uint32_t u32 = static_cast<std::uint32_t>(u);
                float f;
                std::memcpy(&f, &u32, 4);
                return f;
            }
            double d;
            std::memcpy(&d, &u, 8);
            return d;
        }
        long long v;
        if (t.kind == Kind::Unsigned) {
            if (u > static_cast<std::uint64_t>(INT64_MAX))
                Fail(what + ": value too large");
            v = static_cast<long long>(u);
        } else {
            const int shift = 64 - 8 * t.bytes;  // sign-extend
            v = static_cast<long long>(u << shift) >> shift;
        }
        if (asInt) *asInt = v;
        return static_cast<double>(v);
    }
    std::vector<double> RealArray(std::uint64_t count, const DataType& t,
                                  const std::string& what, bool finite);
    std::vector<std::int64_t> IntArray(std::uint64_t count, const DataType& t,
                                       const std::string& what);
    void SkipArray(std::uint64_t count, const DataType& t, const std::string& what);

    // ---- sections ----
    void ParseHeader();
    void ParsePoints(const std::vector<std::string_view>& w);
    void ParseCells(const std::vector<std::string_view>& w);
    void ParseCellTypes(const std::vector<std::string_view>& w);
    void ParseAttribute(const std::vector<std::string_view>& w, Association assoc);
    void ParseFieldArrays(std::uint64_t arrays, Association assoc, bool datasetLevel);
    void SkipMetadata();
    void AddField(const std::string& name, Association assoc, int components,
                  std::vector<double> values, std::size_t pos);

    std::string path_;
    const ReadOptions& options_;
    std::string buf_;
    std::size_t pos_ = 0, last_ = 0, lineStart_ = 0;
    bool binary_ = false;
    int major_ = 0, minor_ = 0;

    Mesh mesh_;
    bool havePoints_ = false, haveCells_ = false, haveTypes_ = false;
    std::size_t cellsPos_ = 0;
    std::vector<std::int64_t> fileOffsets_{0}, fileConn_;  // cells as in the file
    std::vector<std::int64_t> keptCell_;  // file cell -> mesh cell, -1 if skipped
    std::uint64_t skippedCells_ = 0;
};

DataType LegacyParser::Type(std::string_view name) const {
    const std::string n = Lower(name);
    static const DataType kTypes[] = {
        {"unsigned_char", 1, Kind::Unsigned},
        {"char", 1, Kind::Int},
        {"signed_char", 1, Kind::Int},
        {"unsigned_short", 2, Kind::Unsigned},
        {"short", 2, Kind::Int},
        {"unsigned_int", 4, Kind::Unsigned},
        {"int", 4, Kind::Int},
        {"unsigned_long", 8, Kind::Unsigned},
        {"long", 8, Kind::Int},
        {"unsigned_long_long", 8, Kind::Unsigned},
        {"long_long", 8, Kind::Int},
        {"float", 4, Kind::Float},
        {"double", 8, Kind::Float},
        {"vtkidtype", 8, Kind::Int},
        {"vtktypeint8", 1, Kind::Int},
        {"vtktypeuint8", 1, Kind::Unsigned},
        {"vtktypeint16", 2, Kind::Int},
        {"vtktypeuint16", 2, Kind::Unsigned},
        {"vtktypeint32", 4, Kind::Int},
        {"vtktypeuint32", 4, Kind::Unsigned},
        {"vtktypeint64", 8, Kind::Int},
        {"vtktypeuint64", 8, Kind::Unsigned},
        {"vtktypefloat32", 4, Kind::Float},
        {"vtktypefloat64", 8, Kind::Float},
    };
    for (const DataType& t : kTypes)
        if (t.name == n) return t;
    Fail("data type '" + std::string(name) +
         "' is not supported (numeric types only: char .. double, vtktypeint64, ...)");
}

std::vector<double> LegacyParser::RealArray(std::uint64_t count, const DataType& t,
                                            const std::string& what, bool finite) {
    CheckCount(count, t.bytes, what);
    std::vector<double> v;
    v.reserve(count);
    for (std::uint64_t i = 0; i < count; ++i) {
        const double x = RealValue(t, what);
        if (finite && !std::isfinite(x)) Fail(what + " has a NaN or infinite value");
        v.push_back(x);
    }
    return v;
}

std::vector<std::int64_t> LegacyParser::IntArray(std::uint64_t count, const DataType& t,
                                                 const std::string& what) {
    CheckCount(count, t.bytes, what);
    std::vector<std::int64_t> v;
    v.reserve(count);
    for (std::uint64_t i = 0; i < count; ++i) v.push_back(IntValue(t, what));
    return v;
}

void LegacyParser::SkipArray(std::uint64_t count, const DataType& t,
                             const std::string& what) {
    CheckCount(count, t.bytes, what);
    if (binary_) {
        pos_ += count * t.bytes;
    } else {
        for (std::uint64_t i = 0; i < count; ++i) Token(what.c_str());
    }
}

void LegacyParser::ParseHeader() {
    static const char kMagic[] = "# vtk DataFile Version";
    const std::string first = RawLine();
    if (first.compare(0, sizeof(kMagic) - 1, kMagic) != 0)
        FailAt(0,
               "not a legacy VTK file: the first line must be '# vtk DataFile Version "
               "x.y'");
    const std::string version = first.substr(sizeof(kMagic) - 1);
    if (std::sscanf(version.c_str(), " %d.%d", &major_, &minor_) != 2 || major_ < 1 ||
        major_ > 5)
        FailAt(0,
               "unsupported legacy VTK version '" + version + "' (expected 2.0 .. 5.1)");
    RawLine();  // title
    std::vector<std::string_view> w;
    if (!NextLine(&w))
        FailAt(buf_.size(), "unexpected end of file: expected ASCII or BINARY");
    const std::string format = Lower(w[0]);
    if (format == "binary") {
        binary_ = true;
    } else if (format != "ascii") {
        Fail("expected ASCII or BINARY, found '" + std::string(w[0]) + "'");
    }
    if (!NextLine(&w)) FailAt(buf_.size(), "unexpected end of file: expected DATASET");
    if (Lower(w[0]) != "dataset")
        Fail("expected 'DATASET UNSTRUCTURED_GRID', found '" + std::string(w[0]) + "'");
    NeedWords(w, 2, "DATASET kind");
    if (Lower(w[1]) != "unstructured_grid")
        Fail("dataset " + std::string(w[1]) +
             " is not supported: hpray reads legacy VTK files of DATASET "
             "UNSTRUCTURED_GRID");
}

void LegacyParser::ParsePoints(const std::vector<std::string_view>& w) {
    if (havePoints_) Fail("a second POINTS section");
    NeedWords(w, 3, "POINTS n dataType");
    const std::uint64_t n = Count(w[1], "the point count");
    const DataType t = Type(w[2]);
    if (n > buf_.size()) CheckCount(n, t.bytes, "POINTS");  // also guards 3 * n overflow
    mesh_.points = RealArray(3 * n, t, "POINTS", true);
    havePoints_ = true;
}

void LegacyParser::ParseCells(const std::vector<std::string_view>& w) {
    if (haveCells_) Fail("a second CELLS section");
    NeedWords(w, 3, "CELLS n size");
    cellsPos_ = lineStart_;
    const std::uint64_t a = Count(w[1], "the cell count");
    const std::uint64_t b = Count(w[2], "the CELLS size");
    const std::int64_t points = mesh_.PointCount();
    auto checkId = [&](std::int64_t id) {
        if (havePoints_ && (id < 0 || id >= points))
            Fail("point index " + std::to_string(id) + " is outside [0, " +
                 std::to_string(points) + ")");
    };
    // Version 5.1 layout: OFFSETS and CONNECTIVITY arrays follow.
    const std::size_t save = pos_, saveLine = lineStart_;
    std::vector<std::string_view> next;
    const bool newLayout =
        NextLine(&next) && !next.empty() && Lower(next[0]) == "offsets";
    if (newLayout) {
        NeedWords(next, 2, "OFFSETS dataType");
        const DataType ot = Type(next[1]);
        std::vector<std::int64_t> offsets = IntArray(a, ot, "OFFSETS");
        const std::size_t offsetsEnd = last_;
        if (!NextLine(&next) || next.empty() || Lower(next[0]) != "connectivity")
            Fail("expected 'CONNECTIVITY dataType' after the OFFSETS");
        NeedWords(next, 2, "CONNECTIVITY dataType");
        const DataType ct = Type(next[1]);
        if (offsets.empty() && b > 0)
            FailAt(cellsPos_, "CELLS: no offsets for the connectivity");
        if (!offsets.empty()) {
            if (offsets[0] != 0) FailAt(cellsPos_, "OFFSETS must start at 0");
            for (std::size_t i = 1; i < offsets.size(); ++i)
                if (offsets[i] < offsets[i - 1])
                    FailAt(offsetsEnd,
                           "OFFSETS decrease at cell " + std::to_string(i - 1));
            if (static_cast<std::uint64_t>(offsets.back()) != b)
                FailAt(offsetsEnd, "the last offset " + std::to_string(offsets.back()) +
                                       " differs from the connectivity size " +
                                       std::to_string(b));
            fileOffsets_ = std::move(offsets);
        }
        CheckCount(b, ct.bytes, "CONNECTIVITY");
        fileConn_.reserve(b);
        for (std::uint64_t i = 0; i < b; ++i) {
            fileConn_.push_back(IntValue(ct, "CONNECTIVITY"));
            checkId(fileConn_.back());
        }
    } else {
        pos_ = save;
        lineStart_ = last_ = saveLine;
        const DataType it{"int", 4, Kind::Int};
        CheckCount(b, 4, "CELLS");
        if (a > b) FailAt(cellsPos_, "CELLS: more cells than size values");
        fileOffsets_.reserve(a + 1);
        fileConn_.reserve(b - a);
        std::uint64_t used = 0;
        for (std::uint64_t c = 0; c < a; ++c) {
            const long long count = IntValue(it, "CELLS");
            if (count < 0 || static_cast<std::uint64_t>(count) + 1 > b - used)
                Fail("cell " + std::to_string(c) + " has " + std::to_string(count) +
                     " points, more than the CELLS size leaves");
            for (long long k = 0; k < count; ++k) {
                fileConn_.push_back(IntValue(it, "CELLS"));
                checkId(fileConn_.back());
            }
            used += count + 1;
            fileOffsets_.push_back(static_cast<std::int64_t>(fileConn_.size()));
        }
        if (used != b)
            FailAt(cellsPos_, "CELLS size " + std::to_string(b) + " but the cells use " +
                                  std::to_string(used) + " values");
    }
    haveCells_ = true;
}

void LegacyParser::ParseCellTypes(const std::vector<std::string_view>& w) {
    if (!haveCells_) Fail("CELL_TYPES before CELLS");
    if (!havePoints_) Fail("CELL_TYPES before POINTS");
    if (haveTypes_) Fail("a second CELL_TYPES section");
    NeedWords(w, 2, "CELL_TYPES n");
    const std::uint64_t n = Count(w[1], "the cell type count");
    const std::uint64_t cells = fileOffsets_.size() - 1;
    if (n != cells)
        Fail("CELL_TYPES has " + std::to_string(n) + " entries for " +
             std::to_string(cells) + " cells");
    const DataType it{"int", 4, Kind::Int};
    CheckCount(n, 4, "CELL_TYPES");
    const bool legacyHex = major_ < 5 || (major_ == 5 && minor_ < 1);
    const std::int64_t points = mesh_.PointCount();
    keptCell_.assign(n, -1);
    mesh_.vtkType.reserve(n);
    std::vector<std::int64_t> nodes, internal;
    for (std::uint64_t c = 0; c < n; ++c) {
        int type = static_cast<int>(IntValue(it, "CELL_TYPES"));
        const std::int64_t* ids = fileConn_.data() + fileOffsets_[c];
        const std::int64_t count = fileOffsets_[c + 1] - fileOffsets_[c];
        if (IsLowerDimensional(type)) {
            ++skippedCells_;
            continue;
        }
        nodes.assign(ids, ids + count);
        const int fileType = type;  // kept so a writer can use the same type
        if (type == kVtkVoxel &&
            count == 8) {  // a voxel is a hexahedron numbered i fastest
            nodes = {ids[0], ids[1], ids[3], ids[2], ids[4], ids[5], ids[7], ids[6]};
            type = kVtkHexahedron;
        }
        std::string why;
        const std::optional<CellKind> kind = ClassifyVtkCell(type, count, nullptr, &why);
        if (!kind) Fail("cell " + std::to_string(c) + ": " + why);
        for (std::int64_t id : nodes)
            if (id < 0 || id >= points)
                FailAt(cellsPos_, "cell " + std::to_string(c) + " uses point index " +
                                      std::to_string(id) + ", outside [0, " +
                                      std::to_string(points) + ")");
        const std::vector<int>& perm = VtkToInternal(type, *kind, legacyHex);
        internal.resize(perm.size());
        for (std::size_t k = 0; k < perm.size(); ++k) internal[k] = nodes[perm[k]];
        keptCell_[c] = mesh_.CellCount();
        mesh_.AddCell(kind->shape, kind->order, kind->family, internal.data(),
                      static_cast<int>(internal.size()));
        // A type ClassifyVtkCell accepted (or the voxel) is below 256.
        mesh_.vtkType.push_back(static_cast<std::uint8_t>(fileType));
    }
    haveTypes_ = true;
    fileConn_.clear();
    fileConn_.shrink_to_fit();
}

void LegacyParser::AddField(const std::string& name, Association assoc, int components,
                            std::vector<double> values, std::size_t pos) {
    auto& fields = assoc == Association::Point ? mesh_.pointFields : mesh_.cellFields;
    for (const Field& f : fields)
        if (f.name == name) {
            log::Warn(path_ + ": " + Where(pos) + ": a second array named '" + name +
                      "' is ignored");
            return;
        }
    Field f;
    f.name = name;
    f.association = assoc;
    f.components = components;
    if (assoc == Association::Cell) {  // keep the values of the cells that were kept
        std::vector<double> kept;
        kept.reserve(static_cast<std::size_t>(mesh_.CellCount()) * components);
        for (std::size_t c = 0; c < keptCell_.size(); ++c)
            if (keptCell_[c] >= 0)
                kept.insert(kept.end(), values.begin() + c * components,
                            values.begin() + (c + 1) * components);
        values = std::move(kept);
    }
    f.values = std::move(values);
    fields.push_back(std::move(f));
}

void LegacyParser::SkipMetadata() {
    // METADATA is followed by COMPONENT_NAMES / INFORMATION blocks and ends at a blank
    // line.
    while (pos_ < buf_.size()) {
        std::size_t eol = buf_.find('\n', pos_);
        if (eol == std::string::npos) eol = buf_.size();
        const bool blank = std::all_of(buf_.begin() + pos_, buf_.begin() + eol, IsSpace);
        pos_ = eol < buf_.size() ? eol + 1 : eol;
        if (blank) return;
    }
}

void LegacyParser::ParseFieldArrays(std::uint64_t arrays, Association assoc,
                                    bool datasetLevel) {
    const std::uint64_t entities = assoc == Association::Point
                                       ? static_cast<std::uint64_t>(mesh_.PointCount())
                                       : keptCell_.size();
    std::vector<std::string_view> w;
    for (std::uint64_t a = 0; a < arrays; ++a) {
        if (!NextLine(&w)) FailAt(buf_.size(), "unexpected end of file in FIELD");
        if (Lower(w[0]) == "metadata") {  // belongs to the previous array
            SkipMetadata();
            --a;
            continue;
        }
        if (Lower(w[0]) == "null_array") continue;
        NeedWords(w, 4, "arrayName numComponents numTuples dataType");
        const std::string name = DecodeName(w[0]);
        const std::size_t at = lineStart_;
        const std::uint64_t comps = Count(w[1], "numComponents");
        const std::uint64_t tuples = Count(w[2], "numTuples");
        const std::string typeName = Lower(w[3]);
        if (typeName == "string" || typeName == "utf8_string" || typeName == "variant") {
            if (binary_ || (!datasetLevel && options_.Wants(name)))
                Fail("FIELD array '" + name + "' of type " + typeName +
                     " is not supported (numeric arrays only)");
            for (std::uint64_t i = 0; i < comps * tuples; ++i) {  // one string per line
                std::vector<std::string_view> s;
                if (!NextLine(&s)) FailAt(buf_.size(), "unexpected end of file in FIELD");
            }
            continue;
        }
        const DataType t = Type(w[3]);
        if (comps == 0 || comps > 1024) Fail("numComponents must be 1..1024");
        if (tuples > buf_.size()) CheckCount(tuples, t.bytes, "FIELD '" + name + "'");
        if (datasetLevel || !options_.Wants(name)) {
            SkipArray(comps * tuples, t, "FIELD array '" + name + "'");
            continue;
        }
        if (tuples != entities)
            FailAt(at, "FIELD array '" + name + "' has " + std::to_string(tuples) +
                           " tuples for " + std::to_string(entities) +
                           (assoc == Association::Point ? " points" : " cells"));
        AddField(name, assoc, static_cast<int>(comps),
                 RealArray(comps * tuples, t, "FIELD array '" + name + "'", true), at);
    }
}

void LegacyParser::ParseAttribute(const std::vector<std::string_view>& w,
                                  Association assoc) {
    const std::string key = Lower(w[0]);
    const std::uint64_t entities = assoc == Association::Point
                                       ? static_cast<std::uint64_t>(mesh_.PointCount())
                                       : keptCell_.size();
    const std::size_t at = lineStart_;
    std::string name;
    int comps = 1;
    DataType t;
    if (key == "scalars") {
        NeedWords(w, 3, "SCALARS name dataType [numComp]");
        name = DecodeName(w[1]);
        t = Type(w[2]);
        if (w.size() > 3) {
            const long long c = ParseInt(w[3], "numComp");
            if (c < 1 || c > 4) Fail("SCALARS numComp must be 1..4");
            comps = static_cast<int>(c);
        }
        std::vector<std::string_view> lut;
        if (!NextLine(&lut) || Lower(lut[0]) != "lookup_table")
            Fail("expected 'LOOKUP_TABLE name' after SCALARS " + name);
    } else if (key == "vectors" || key == "normals") {
        NeedWords(w, 3, "VECTORS name dataType");
        name = DecodeName(w[1]);
        t = Type(w[2]);
        comps = 3;
    } else if (key == "tensors" || key == "tensors6") {
        NeedWords(w, 3, "TENSORS name dataType");
        name = DecodeName(w[1]);
        t = Type(w[2]);
        comps = key == "tensors" ? 9 : 6;
    } else if (key == "texture_coordinates") {
        NeedWords(w, 4, "TEXTURE_COORDINATES name dim dataType");
        name = DecodeName(w[1]);
        const long long d = ParseInt(w[2], "dim");
        if (d < 1 || d > 3) Fail("TEXTURE_COORDINATES dim must be 1..3");
        comps = static_cast<int>(d);
        t = Type(w[3]);
    } else if (key == "global_ids" || key == "pedigree_ids") {
        NeedWords(w, 3, "GLOBAL_IDS name dataType");
        name = DecodeName(w[1]);
        t = Type(w[2]);
    } else if (key == "color_scalars") {
        NeedWords(w, 3, "COLOR_SCALARS name nValues");
        name = DecodeName(w[1]);
        const long long c = ParseInt(w[2], "nValues");
        if (c < 1 || c > 4) Fail("COLOR_SCALARS nValues must be 1..4");
        comps = static_cast<int>(c);
        // ASCII: floats in [0, 1]; BINARY: unsigned chars (value / 255).
        t = binary_ ? DataType{"unsigned_char", 1, Kind::Unsigned}
                    : DataType{"float", 4, Kind::Float};
    } else if (key == "lookup_table") {  // a colour table, not data: skip
        NeedWords(w, 3, "LOOKUP_TABLE name size");
        const std::uint64_t size = Count(w[2], "the table size");
        if (size > buf_.size()) CheckCount(size, 4, "LOOKUP_TABLE");
        SkipArray(4 * size,
                  binary_ ? DataType{"unsigned_char", 1, Kind::Unsigned}
                          : DataType{"float", 4, Kind::Float},
                  "LOOKUP_TABLE");
        return;
    } else if (key == "field") {
        NeedWords(w, 3, "FIELD name numArrays");
        ParseFieldArrays(Count(w[2], "numArrays"), assoc, false);
        return;
    } else {
        Fail("unknown keyword '" + std::string(w[0]) + "'");
    }
    const std::string what = std::string(w[0]) + " " + name;
    if (entities > buf_.size()) CheckCount(entities, t.bytes, what);
    const std::uint64_t count = entities * comps;
    if (!options_.Wants(name)) {
        SkipArray(count, t, what);
        return;
    }
    std::vector<double> values = RealArray(count, t, what, true);
    if (key == "color_scalars" && binary_)
        for (double& v : values) v /= 255.0;
    AddField(name, assoc, comps, std::move(values), at);
}

Mesh LegacyParser::Parse() {
    ParseHeader();
    std::vector<std::string_view> w;
    bool inData = false;
    Association assoc = Association::Point;
    while (NextLine(&w)) {
        const std::string key = Lower(w[0]);
        if (key == "points") {
            ParsePoints(w);
        } else if (key == "cells") {
            ParseCells(w);
        } else if (key == "cell_types") {
            ParseCellTypes(w);
        } else if (key == "point_data" || key == "cell_data") {
            NeedWords(w, 2, "POINT_DATA n");
            const std::uint64_t n = Count(w[1], "the entity count");
            if (key == "point_data") {
                if (!havePoints_) Fail("POINT_DATA before POINTS");
                if (n != static_cast<std::uint64_t>(mesh_.PointCount()))
                    Fail("POINT_DATA " + std::to_string(n) + " for " +
                         std::to_string(mesh_.PointCount()) + " points");
                assoc = Association::Point;
            } else {
                if (!haveTypes_) Fail("CELL_DATA before CELL_TYPES");
                if (n != keptCell_.size())
                    Fail("CELL_DATA " + std::to_string(n) + " for " +
                         std::to_string(keptCell_.size()) + " cells");
                assoc = Association::Cell;
            }
            inData = true;
        } else if (key == "metadata") {
            SkipMetadata();
        } else if (key == "field" && !inData) {  // dataset field data (e.g. TIME): skip
            NeedWords(w, 3, "FIELD name numArrays");
            ParseFieldArrays(Count(w[2], "numArrays"), assoc, true);
        } else if (inData) {
            ParseAttribute(w, assoc);
        } else {
            Fail("unexpected keyword '" + std::string(w[0]) + "'");
        }
    }
    if (!havePoints_) FailAt(buf_.size(), "no POINTS section");
    if (haveCells_ && !haveTypes_) FailAt(buf_.size(), "CELLS without CELL_TYPES");
    if (skippedCells_ > 0)
        log::Warn(path_ + ": skipped " + std::to_string(skippedCells_) +
                  " cells of dimension below 3 (and their cell data)");
    mesh_.Validate(path_);
    return std::move(mesh_);
}

}  // namespace

Mesh ReadVtkLegacy(const std::string& path, const ReadOptions& options) {
    LegacyParser parser(path, options);
    return parser.Parse();
}

}  // namespace hpray
