// Image channels, the sRGB curve, and NumPy .npy (float64) reading and writing.
#include "io/image.h"

#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <limits>
#include <sstream>

#include "io/output_file.h"
#include "util/check.h"
#include "util/error.h"

namespace hpray {

double LinearToSrgb(double linear) {
    // NaN compares false everywhere; map it to black rather than propagate into 8 bits.
    if (!(linear > 0.0)) return 0.0;
    if (linear >= 1.0) return 1.0;
    if (linear <= 0.0031308) return 12.92 * linear;
    return 1.055 * std::pow(linear, 1.0 / 2.4) - 0.055;
}

std::uint8_t EncodeSrgb8Reference(double linear) {
    return static_cast<std::uint8_t>(std::floor(255.0 * LinearToSrgb(linear) + 0.5));
}

namespace {

struct SrgbTable {
    static constexpr int kCells = 4096;
    /// first[k], k = 1..255: the smallest double in (0, 1] whose code is at least k.
    double first[256];
    /// code[i]: the code of the lower end i / kCells of cell i.
    std::uint8_t code[kCells];

    SrgbTable() {
        first[0] = 0;
        for (int k = 1; k <= 255; ++k) {
            // Bisection over the doubles of (0, 1] by their bit patterns (ordered like
            // the values): lo has a code below k, hi one of at least k.
            std::uint64_t lo = 0, hi;
            const double one = 1.0;
            std::memcpy(&hi, &one, sizeof hi);
            while (hi - lo > 1) {
                const std::uint64_t mid = lo + (hi - lo) / 2;
                double v;
                std::memcpy(&v, &mid, sizeof v);
                (EncodeSrgb8Reference(v) >= k ? hi : lo) = mid;
            }
            std::memcpy(&first[k], &hi, sizeof hi);
        }
        for (int i = 0; i < kCells; ++i)
            code[i] = EncodeSrgb8Reference(static_cast<double>(i) / kCells);
    }
};

const SrgbTable& GetSrgbTable() {
    static const SrgbTable table;
    return table;
}

}  // namespace

std::uint8_t EncodeSrgb8(double linear) {
    if (!(linear > 0.0)) return 0;  // NaN too, as LinearToSrgb
    if (linear >= 1.0) return 255;
    const SrgbTable& t = GetSrgbTable();
    // i / kCells <= linear (exact products: kCells is a power of two), so the code is at
    // least code[i]; the codes whose first value lies in the cell up to linear add one
    // each.
    const int i = static_cast<int>(linear * SrgbTable::kCells);
    int c = t.code[i];
    while (c < 255 && linear >= t.first[c + 1]) ++c;
    return static_cast<std::uint8_t>(c);
}

// ---------------------------------------------------------------------------------------
// NumPy .npy
// ---------------------------------------------------------------------------------------
namespace {

constexpr char kNpyMagic[] = "\x93NUMPY";
constexpr std::size_t kNpyMagicLen = 6;
constexpr std::size_t kNpyAlign = 64;
// numpy >= 1.24 leaves room for the first axis to grow to this many digits.
constexpr std::size_t kNpyGrowthDigits = 21;

std::string ShapeRepr(const std::vector<std::size_t>& shape) {
    // Python's repr of a tuple: "()", "(7,)", "(3, 4, 5)".
    std::string s = "(";
    for (std::size_t k = 0; k < shape.size(); ++k) {
        if (k > 0) s += ", ";
        s += std::to_string(shape[k]);
    }
    if (shape.size() == 1) s += ",";
    return s + ")";
}

bool IsLittleEndianHost() {
    const std::uint16_t one = 1;
    unsigned char first = 0;
    std::memcpy(&first, &one, 1);
    return first == 1;
}

/// A minimal reader of the Python dict literal numpy writes as the .npy header.
class NpyHeaderParser {
  public:
    NpyHeaderParser(const std::string& path, const std::string& text)
        : path_(path), text_(text) {}

    void Parse(std::string& descr, bool& fortranOrder, std::vector<std::size_t>& shape) {
        bool haveDescr = false, haveOrder = false, haveShape = false;
        Expect('{');
        while (true) {
            SkipSpace();
            if (Peek() == '}') break;
            const std::string key = ParseString();
            Expect(':');
            SkipSpace();
            if (key == "descr") {
                descr = ParseString();
                haveDescr = true;
            } else if (key == "fortran_order") {
                fortranOrder = ParseBool();
                haveOrder = true;
            } else if (key == "shape") {
                shape = ParseTuple();
                haveShape = true;
            } else {
                Fail("unexpected key '" + key + "'");
            }
            SkipSpace();
            if (Peek() == ',') {
                ++pos_;
                continue;
            }
            SkipSpace();
            if (Peek() != '}') Fail("expected ',' or '}'");
        }
        if (!haveDescr || !haveOrder || !haveShape)
            Fail("header lacks one of 'descr', 'fortran_order', 'shape'");
    }

  private:
    [[noreturn]] void Fail(const std::string& what) const {
        throw InputError(path_, "byte " + std::to_string(10 + pos_),
                         "malformed .npy header: " + what);
    }
    char Peek() const { return pos_ < text_.size() ? text_[pos_] : '\0'; }
    void SkipSpace() {
        while (pos_ < text_.size() &&
               std::isspace(static_cast<unsigned char>(text_[pos_])))
            ++pos_;
    }
    void Expect(char c) {
        SkipSpace();
        if (Peek() != c) Fail(std::string("expected '") + c + "'");
        ++pos_;
    }
    std::string ParseString() {
        SkipSpace();
        const char quote = Peek();
        if (quote != '\'' && quote != '"') Fail("expected a quoted string");
        const std::size_t end = text_.find(quote, pos_ + 1);
        if (end == std::string::npos) Fail("unterminated string");
        std::string s = text_.substr(pos_ + 1, end - pos_ - 1);
        pos_ = end + 1;
        return s;
    }
    bool ParseBool() {
        if (text_.compare(pos_, 4, "True") == 0) {
            pos_ += 4;
            return true;
        }
        if (text_.compare(pos_, 5, "False") == 0) {
            pos_ += 5;
            return false;
        }
        Fail("expected True or False");
    }
    std::vector<std::size_t> ParseTuple() {
        std::vector<std::size_t> out;
        Expect('(');
        while (true) {
            SkipSpace();
            if (Peek() == ')') {
                ++pos_;
                return out;
            }
            if (!std::isdigit(static_cast<unsigned char>(Peek())))
                Fail("expected a size");
            std::size_t value = 0;
            while (std::isdigit(static_cast<unsigned char>(Peek()))) {
                const std::size_t digit = static_cast<std::size_t>(Peek() - '0');
                if (value > (std::numeric_limits<std::size_t>::max() - digit) / 10)
                    Fail("size too large");
                value = value * 10 + digit;
                ++pos_;
            }
            out.push_back(value);
            SkipSpace();
            if (Peek() == ',') {
                ++pos_;
            } else if (Peek() != ')') {
                Fail("expected ',' or ')'");
            }
        }
    }

    const std::string& path_;
    const std::string& text_;
    std::size_t pos_ = 0;
};

}  // namespace

namespace {
/// Writes a C-order little-endian array of `count` elements of `itemSize` bytes with NumPy
/// type `descr`: byte for byte what numpy.save writes (format 1.0).
void WriteNpyBytes(const std::string& path, const char* descr, const void* data,
                   std::size_t itemSize, std::size_t count,
                   const std::vector<std::size_t>& shape) {
    std::size_t expected = 1;
    for (std::size_t extent : shape) expected *= extent;
    HPRAY_CHECK_EQ(expected, count);
    HPRAY_CHECK(IsLittleEndianHost());
    std::string dict = std::string("{'descr': '") + descr +
                       "', 'fortran_order': False, 'shape': " + ShapeRepr(shape) + ", }";
    if (!shape.empty()) {
        const std::size_t digits = std::to_string(shape[0]).size();
        if (digits < kNpyGrowthDigits) dict.append(kNpyGrowthDigits - digits, ' ');
    }
    const std::size_t withNewline = dict.size() + 1;
    const std::size_t pad = kNpyAlign - (kNpyMagicLen + 4 + withNewline) % kNpyAlign;
    const std::size_t headerLen = withNewline + pad;
    if (headerLen > 0xffff)
        throw InputError(path, "", "array has too many dimensions for .npy format 1.0");
    std::string header(kNpyMagic, kNpyMagicLen);
    header += '\x01';
    header += '\x00';
    header += static_cast<char>(headerLen & 0xff);
    header += static_cast<char>((headerLen >> 8) & 0xff);
    header += dict;
    header.append(pad, ' ');
    header += '\n';

    const std::string tmp = detail::BeginOutputFile(path);
    {
        std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
        if (out) {
            out.write(header.data(), static_cast<std::streamsize>(header.size()));
            out.write(static_cast<const char*>(data),
                      static_cast<std::streamsize>(count * itemSize));
            out.flush();
        }
        if (!out) {
            detail::AbandonOutputFile(tmp);
            throw InputError(path, "", "cannot write '" + tmp + "'");
        }
    }
    detail::CommitOutputFile(tmp, path);
}
}  // namespace

void WriteNpy(const std::string& path, const std::vector<double>& data,
              const std::vector<std::size_t>& shape) {
    WriteNpyBytes(path, "<f8", data.data(), sizeof(double), data.size(), shape);
}

void WriteNpyFloat32(const std::string& path, const std::vector<float>& data,
              const std::vector<std::size_t>& shape) {
    WriteNpyBytes(path, "<f4", data.data(), sizeof(float), data.size(), shape);
}

std::vector<double> ReadNpy(const std::string& path, std::vector<std::size_t>& shape) {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw InputError(path, "", "cannot open file");
    in.seekg(0, std::ios::end);
    const std::streamoff fileSize = in.tellg();
    in.seekg(0, std::ios::beg);
    if (fileSize < 10) throw InputError(path, "byte 0", "too short for a .npy file");

    unsigned char prefix[10];
    in.read(reinterpret_cast<char*>(prefix), 10);
    if (std::memcmp(prefix, kNpyMagic, kNpyMagicLen) != 0)
        throw InputError(path, "byte 0", "not a .npy file (bad magic)");
    const int major = prefix[6];
    std::size_t headerLen = 0;
    std::size_t prefixLen = 10;
    if (major == 1) {
        headerLen = prefix[8] | (static_cast<std::size_t>(prefix[9]) << 8);
    } else if (major == 2 || major == 3) {
        unsigned char more[2];
        if (fileSize < 12) throw InputError(path, "byte 8", "truncated header length");
        in.read(reinterpret_cast<char*>(more), 2);
        headerLen = prefix[8] | (static_cast<std::size_t>(prefix[9]) << 8) |
                    (static_cast<std::size_t>(more[0]) << 16) |
                    (static_cast<std::size_t>(more[1]) << 24);
        prefixLen = 12;
    } else {
        throw InputError(path, "byte 6",
                         "unsupported .npy version " + std::to_string(major));
    }
    const std::size_t size = static_cast<std::size_t>(fileSize);
    if (headerLen > size - prefixLen)
        throw InputError(path, "byte 8", "header length exceeds the file size");
    std::string headerText(headerLen, '\0');
    in.read(headerText.data(), static_cast<std::streamsize>(headerLen));
    if (!in) throw InputError(path, "byte 10", "cannot read header");

    std::string descr;
    bool fortranOrder = false;
    std::vector<std::size_t> parsedShape;
    NpyHeaderParser(path, headerText).Parse(descr, fortranOrder, parsedShape);
    if (descr != "<f8")
        throw InputError(path, "header", "dtype '" + descr + "' is not '<f8' (float64)");
    if (fortranOrder)
        throw InputError(path, "header", "Fortran-order arrays unsupported");
    HPRAY_CHECK(IsLittleEndianHost());

    // Validate the declared size against the bytes actually present before allocating.
    const std::size_t available = size - prefixLen - headerLen;
    std::size_t count = 1;
    for (std::size_t extent : parsedShape) {
        if (extent != 0 && count > available / sizeof(double) / extent)
            throw InputError(
                path, "header",
                "shape " + ShapeRepr(parsedShape) + " exceeds the file size");
        count *= extent;
    }
    if (count * sizeof(double) != available)
        throw InputError(path, "header",
                         "shape " + ShapeRepr(parsedShape) + " needs " +
                             std::to_string(count * sizeof(double)) +
                             " data bytes, file has " + std::to_string(available));
    std::vector<double> data(count);
    in.read(reinterpret_cast<char*>(data.data()),
            static_cast<std::streamsize>(count * sizeof(double)));
    if (!in) throw InputError(path, "data", "cannot read array data");
    shape = std::move(parsedShape);
    return data;
}

}  // namespace hpray
