// Tests of the image outputs: OpenEXR channels, sRGB PNG compositing, NumPy .npy.
#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <set>
#include <sstream>
#include <string>

#include "io/image.h"
#include "util/error.h"

namespace hpray {
namespace {

namespace fs = std::filesystem;

/// A fresh, empty folder per test under the system temporary folder.
class ImageIoTest : public ::testing::Test {
  protected:
    void SetUp() override {
        const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
        dir_ = fs::temp_directory_path() /
               ("hpray_test_image_" + std::string(info->name()) + "_" +
                std::to_string(static_cast<long>(::getpid())));
        fs::remove_all(dir_);
        fs::create_directories(dir_);
    }
    void TearDown() override { fs::remove_all(dir_); }
    std::string Path(const std::string& name) const { return (dir_ / name).string(); }

    fs::path dir_;
};

std::string ReadBytes(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    std::ostringstream os;
    os << in.rdbuf();
    return os.str();
}

void WriteBytes(const std::string& path, const std::string& bytes) {
    std::ofstream out(path, std::ios::binary);
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

/// Closed-form sRGB encoding (IEC 61966-2-1) of a linear value in [0, 1] to 8 bits.
int Srgb8(double linear) {
    const double s = linear <= 0.0031308 ? 12.92 * linear
                                         : 1.055 * std::pow(linear, 1.0 / 2.4) - 0.055;
    return static_cast<int>(std::lround(255.0 * s));
}

/// An image whose every channel holds distinct float32-representable values, with the
/// "no hit" special values (+inf Z, NaN residual, id -1) at some pixels.
Image MakeTestImage(int w, int h) {
    Image image;
    image.Resize(w, h);
    for (int j = 0; j < h; ++j) {
        for (int i = 0; i < w; ++i) {
            const std::size_t p = static_cast<std::size_t>(j) * w + i;
            const double base = 0.125 * i + 0.0625 * j;  // exact binary fractions
            image.r[p] = base;
            image.g[p] = base + 1.0;
            image.b[p] = base + 2.0;
            image.a[p] = 0.5 + 0.03125 * ((i + j) % 16);
            image.nx[p] = 0.25 * (i % 3);
            image.ny[p] = -0.5 * (j % 2);
            image.nz[p] = 0.75;
            image.volError[p] = std::ldexp(1.0, -20 - (i % 5));
            if ((i + 2 * j) % 3 == 0) {
                image.z[p] = std::numeric_limits<double>::infinity();
                image.isoResidual[p] = std::numeric_limits<double>::quiet_NaN();
                image.isoId[p] = -1.0;
            } else {
                image.z[p] = 1.5 + 0.25 * i + 8.0 * j;
                image.isoResidual[p] = std::ldexp(3.0, -40 + (j % 7));
                image.isoId[p] = static_cast<double>((i + j) % 4);
            }
        }
    }
    return image;
}

TEST(ImageTest, ResizeSetsEmptyValues) {
    Image image;
    image.Resize(3, 2);
    EXPECT_EQ(image.PixelCount(), 6u);
    for (const auto& [name, channel] : image.Channels()) {
        ASSERT_EQ(channel->size(), 6u) << name;
    }
    for (std::size_t p = 0; p < 6; ++p) {
        EXPECT_EQ(image.r[p], 0.0);
        EXPECT_EQ(image.a[p], 0.0);
        EXPECT_TRUE(std::isinf(image.z[p]) && image.z[p] > 0);
        EXPECT_EQ(image.nx[p], 0.0);
        EXPECT_TRUE(std::isnan(image.isoResidual[p]));
        EXPECT_EQ(image.isoId[p], -1.0);
        EXPECT_EQ(image.volError[p], 0.0);
    }
}

TEST(ImageTest, ChannelNamesAreTheDesignNames) {
    const std::vector<std::string> expected = {
        "R",      "G",        "B", "A", "Z", "N.X", "N.Y", "N.Z", "iso.residual",
        "iso.id", "vol.error"};
    Image image;
    image.Resize(1, 1);
    std::vector<std::string> names;
    for (const auto& [name, channel] : image.Channels()) names.push_back(name);
    EXPECT_EQ(names, expected);
    // The const overload points at the same storage.
    const Image& constImage = image;
    const auto constChannels = constImage.Channels();
    const auto channels = image.Channels();
    ASSERT_EQ(constChannels.size(), channels.size());
    for (std::size_t c = 0; c < channels.size(); ++c)
        EXPECT_EQ(constChannels[c].second, channels[c].second);
}

TEST_F(ImageIoTest, ExrRoundTripPreservesEveryChannel) {
    const Image image = MakeTestImage(7, 5);
    const std::string path = Path("sub/dir/frame.exr");  // parent folders are created
    WriteExr(path, image);
    EXPECT_TRUE(fs::exists(path));
    EXPECT_FALSE(fs::exists(path + ".tmp"));

    const Image back = ReadExr(path);
    ASSERT_EQ(back.width, 7);
    ASSERT_EQ(back.height, 5);
    const auto expected = image.Channels();
    const auto actual = back.Channels();
    for (std::size_t c = 0; c < expected.size(); ++c) {
        const auto& name = expected[c].first;
        for (std::size_t p = 0; p < image.PixelCount(); ++p) {
            const double want = (*expected[c].second)[p];
            const double got = (*actual[c].second)[p];
            if (std::isnan(want)) {
                EXPECT_TRUE(std::isnan(got)) << name << " pixel " << p;
            } else {
                EXPECT_EQ(got, want) << name << " pixel " << p;
            }
        }
    }
}

TEST_F(ImageIoTest, ExrHasExactlyTheDesignChannelsAsFloat32) {
    const std::string path = Path("frame.exr");
    WriteExr(path, MakeTestImage(4, 3));
    // Inspect the file with OpenEXR directly rather than through ReadExr.
    Imf::InputFile file(path.c_str());
    std::set<std::string> names;
    for (auto it = file.header().channels().begin(); it != file.header().channels().end();
         ++it) {
        names.insert(it.name());
        EXPECT_EQ(it.channel().type, Imf::FLOAT) << it.name();
    }
    const std::set<std::string> expected = {
        "R",      "G",        "B", "A", "Z", "N.X", "N.Y", "N.Z", "iso.residual",
        "iso.id", "vol.error"};
    EXPECT_EQ(names, expected);
    EXPECT_FALSE(file.header().hasTileDescription());
    const Imath::Box2i window = file.header().dataWindow();
    EXPECT_EQ(window.max.x - window.min.x + 1, 4);
    EXPECT_EQ(window.max.y - window.min.y + 1, 3);
}

TEST_F(ImageIoTest, ExrRoundsDoublesToNearestFloat) {
    Image image;
    image.Resize(1, 1);
    image.r[0] = 0.1;  // not representable: stored as the nearest float
    image.z[0] = 1.0 + 1e-12;
    WriteExr(Path("f.exr"), image);
    const Image back = ReadExr(Path("f.exr"));
    EXPECT_EQ(back.r[0], static_cast<double>(0.1f));
    EXPECT_EQ(back.z[0], 1.0);
}

TEST_F(ImageIoTest, ExrReaderRejectsMalformedFiles) {
    EXPECT_THROW(ReadExr(Path("missing.exr")), InputError);

    WriteBytes(Path("garbage.exr"), std::string(1000, 'x'));
    EXPECT_THROW(ReadExr(Path("garbage.exr")), InputError);

    WriteBytes(Path("empty.exr"), "");
    EXPECT_THROW(ReadExr(Path("empty.exr")), InputError);

    WriteExr(Path("good.exr"), MakeTestImage(16, 40));
    const std::string bytes = ReadBytes(Path("good.exr"));
    for (std::size_t keep :
         {std::size_t{8}, std::size_t{100}, bytes.size() / 2, bytes.size() - 10}) {
        WriteBytes(Path("cut.exr"), bytes.substr(0, keep));
        EXPECT_THROW(ReadExr(Path("cut.exr")), InputError) << "kept " << keep << " bytes";
    }
}

TEST_F(ImageIoTest, ExrWriterReportsUnwritablePath) {
    WriteBytes(Path("file"), "x");
    // A regular file where a folder is needed.
    try {
        WriteExr(Path("file/frame.exr"), MakeTestImage(2, 2));
        FAIL() << "expected InputError";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("file/frame.exr"), std::string::npos)
            << e.what();
    }
}

TEST(SrgbTest, MatchesTheClosedFormCurve) {
    EXPECT_EQ(LinearToSrgb(0.0), 0.0);
    EXPECT_EQ(LinearToSrgb(1.0), 1.0);
    EXPECT_EQ(LinearToSrgb(-0.5), 0.0);
    EXPECT_EQ(LinearToSrgb(7.0), 1.0);
    EXPECT_EQ(LinearToSrgb(std::numeric_limits<double>::quiet_NaN()), 0.0);
    EXPECT_DOUBLE_EQ(LinearToSrgb(0.002), 12.92 * 0.002);  // linear segment
    EXPECT_NEAR(LinearToSrgb(0.5), 1.055 * std::pow(0.5, 1.0 / 2.4) - 0.055, 1e-15);
    // The two pieces meet (continuity at the breakpoint to 1e-7, a property of the
    // standard's rounded constants).
    EXPECT_NEAR(LinearToSrgb(0.0031308), LinearToSrgb(0.0031308 + 1e-12), 1e-7);
    // Monotone.
    double previous = -1.0;
    for (int k = 0; k <= 1000; ++k) {
        const double s = LinearToSrgb(k / 1000.0);
        EXPECT_GT(s, previous) << k;
        previous = s;
    }
}

TEST(SrgbTest, TheTableEncoderGivesTheFunctionsByteForEveryValue) {
    // Special values.
    const double inf = std::numeric_limits<double>::infinity();
    for (double v : {0.0, -0.0, -1e-300, 4.9e-324, 1e-300, 0.0031308, 0.5, 1.0,
                     std::nextafter(1.0, 0.0), 1.5, inf, -inf,
                     std::numeric_limits<double>::quiet_NaN()})
        EXPECT_EQ(EncodeSrgb8(v), EncodeSrgb8Reference(v)) << v;
    // Around every code's first value (found here by bisection on the values, apart
    // from the encoder's own search), a few doubles on either side.
    int checked = 0;
    for (int k = 1; k <= 255; ++k) {
        double lo = 0, hi = 1;
        for (int it = 0; it < 200 && std::nextafter(lo, 1.0) < hi; ++it) {
            const double mid = lo + 0.5 * (hi - lo);
            (EncodeSrgb8Reference(mid) >= k ? hi : lo) = mid;
        }
        ASSERT_GE(EncodeSrgb8Reference(hi), k);
        ASSERT_LT(EncodeSrgb8Reference(std::nextafter(hi, 0.0)), k);
        double v = hi;
        for (int s = 0; s < 8; ++s) v = std::nextafter(v, 0.0);
        for (int s = 0; s < 17; ++s, v = std::nextafter(v, 1.0)) {
            ASSERT_EQ(EncodeSrgb8(v), EncodeSrgb8Reference(v))
                << "code " << k << " at " << v;
            ++checked;
        }
    }
    // Random values, uniform and spread over many decades.
    std::mt19937_64 rng(3);
    std::uniform_real_distribution<double> unit(0, 1), decades(-14, 0.1);
    for (int i = 0; i < 2000000; ++i) {
        const double a = unit(rng), b = std::pow(10.0, decades(rng));
        ASSERT_EQ(EncodeSrgb8(a), EncodeSrgb8Reference(a)) << a;
        ASSERT_EQ(EncodeSrgb8(b), EncodeSrgb8Reference(b)) << b;
        checked += 2;
    }
    EXPECT_EQ(checked, 255 * 17 + 4000000);
}

TEST(SrgbTest, TheBytesNeverFallAsTheValueRises) {
    // What the table encoder relies on: each code is reached once and kept.
    int previous = 0;
    for (int i = 0; i <= 4000000; ++i) {
        const int c = EncodeSrgb8Reference(i / 4000000.0);
        ASSERT_GE(c, previous) << i;
        previous = c;
    }
    EXPECT_EQ(previous, 255);
    // And across the joint of the curve's two pieces, ulp by ulp.
    double v = 0.0031308;
    for (int s = 0; s < 1000; ++s) v = std::nextafter(v, 0.0);
    previous = EncodeSrgb8Reference(v);
    for (int s = 0; s < 2000; ++s, v = std::nextafter(v, 1.0)) {
        ASSERT_GE(EncodeSrgb8Reference(v), previous);
        previous = EncodeSrgb8Reference(v);
    }
}

TEST_F(ImageIoTest, PngCompositesOverBackgroundAndEncodesSrgb) {
    const std::array<double, 3> background = {0.2, 0.5, 1.0};
    Image image;
    image.Resize(4, 2);
    // (0,0): fully transparent -> the background.
    // (1,0): opaque premultiplied colour -> the colour itself.
    image.r[1] = 0.5;
    image.g[1] = 0.0;
    image.b[1] = 1.0;
    image.a[1] = 1.0;
    // (2,0): half-transparent premultiplied (0.1, 0.2, 0.3), a = 0.5.
    image.r[2] = 0.1;
    image.g[2] = 0.2;
    image.b[2] = 0.3;
    image.a[2] = 0.5;
    // (3,0): colour beyond 1 clamps to white.
    image.r[3] = 3.0;
    image.g[3] = 3.0;
    image.b[3] = 3.0;
    image.a[3] = 1.0;
    // (0,1): tiny linear value on the linear segment of the curve.
    image.r[4] = 0.001;
    image.a[4] = 1.0;

    const std::string path = Path("out/frame.png");
    WritePng(path, image, background);
    EXPECT_FALSE(fs::exists(path + ".tmp"));

    int w = 0, h = 0;
    std::vector<std::uint8_t> rgb;
    ReadPng(path, w, h, rgb);
    ASSERT_EQ(w, 4);
    ASSERT_EQ(h, 2);
    ASSERT_EQ(rgb.size(), 24u);
    auto pixel = [&](int i, int j, int c) {
        return static_cast<int>(rgb[3 * (j * w + i) + c]);
    };

    EXPECT_EQ(pixel(0, 0, 0), Srgb8(0.2));
    EXPECT_EQ(pixel(0, 0, 1), Srgb8(0.5));
    EXPECT_EQ(pixel(0, 0, 2), 255);
    EXPECT_EQ(pixel(1, 0, 0), 188);  // linear 0.5 -> sRGB 0.7354 -> 187.5 -> 188
    EXPECT_EQ(pixel(1, 0, 1), 0);
    EXPECT_EQ(pixel(1, 0, 2), 255);
    EXPECT_EQ(pixel(2, 0, 0), Srgb8(0.1 + 0.5 * 0.2));
    EXPECT_EQ(pixel(2, 0, 1), Srgb8(0.2 + 0.5 * 0.5));
    EXPECT_EQ(pixel(2, 0, 2), Srgb8(0.3 + 0.5 * 1.0));
    EXPECT_EQ(pixel(3, 0, 0), 255);
    EXPECT_EQ(pixel(0, 1, 0), static_cast<int>(std::lround(255 * 12.92 * 0.001)));  // 3
    EXPECT_EQ(pixel(0, 1, 1), 0);
    // Transparent pixels of the second row show the background.
    EXPECT_EQ(pixel(3, 1, 1), Srgb8(0.5));
    EXPECT_EQ(Srgb8(0.5), 188);
}

TEST_F(ImageIoTest, PngRoundTripOfEveryByteValue) {
    // Linear values whose sRGB encodings land exactly on every 8-bit code.
    Image image;
    image.Resize(256, 1);
    for (int k = 0; k < 256; ++k) {
        const double s = k / 255.0;
        const double linear =
            s <= 0.04045 ? s / 12.92 : std::pow((s + 0.055) / 1.055, 2.4);
        image.r[k] = linear;
        image.g[k] = linear;
        image.b[k] = 1.0 - linear;
        image.a[k] = 1.0;
    }
    WritePng(Path("ramp.png"), image, {0.0, 0.0, 0.0});
    int w = 0, h = 0;
    std::vector<std::uint8_t> rgb;
    ReadPng(Path("ramp.png"), w, h, rgb);
    ASSERT_EQ(w, 256);
    ASSERT_EQ(h, 1);
    for (int k = 0; k < 256; ++k) {
        EXPECT_EQ(rgb[3 * k + 0], k);
        EXPECT_EQ(rgb[3 * k + 1], k);
        EXPECT_EQ(rgb[3 * k + 2], Srgb8(1.0 - image.r[k]));
    }
}

TEST_F(ImageIoTest, PngReaderRejectsMalformedFiles) {
    WriteBytes(Path("garbage.png"), std::string(500, 'z'));
    Image image = MakeTestImage(30, 20);
    WritePng(Path("good.png"), image, {1, 1, 1});
    const std::string bytes = ReadBytes(Path("good.png"));
    WriteBytes(Path("cut.png"), bytes.substr(0, bytes.size() / 2));
    WriteBytes(Path("header-only.png"), bytes.substr(0, 40));
    for (const char* name :
         {"missing.png", "garbage.png", "cut.png", "header-only.png"}) {
        int w = 0, h = 0;
        std::vector<std::uint8_t> rgb;
        EXPECT_THROW(ReadPng(Path(name), w, h, rgb), InputError) << name;
    }
}

/// The shape of a (H, W, 5) hits array with distinct values, NaN and +inf included.
std::vector<double> HitsLikeData(std::size_t h, std::size_t w) {
    std::vector<double> data(h * w * 5);
    for (std::size_t k = 0; k < data.size(); ++k) data[k] = 0.1 * k - 3.0 + 1e-13 * k * k;
    data[0] = std::numeric_limits<double>::infinity();
    data[4] = std::numeric_limits<double>::quiet_NaN();
    return data;
}

TEST_F(ImageIoTest, NpyRoundTrip) {
    const std::vector<double> data = HitsLikeData(3, 4);
    const std::string path = Path("nested/hits.npy");
    WriteNpy(path, data, {3, 4, 5});
    EXPECT_FALSE(fs::exists(path + ".tmp"));
    std::vector<std::size_t> shape;
    const std::vector<double> back = ReadNpy(path, shape);
    EXPECT_EQ(shape, (std::vector<std::size_t>{3, 4, 5}));
    ASSERT_EQ(back.size(), data.size());
    EXPECT_TRUE(std::isinf(back[0]) && back[0] > 0);
    EXPECT_TRUE(std::isnan(back[4]));
    for (std::size_t k = 5; k < data.size(); ++k) EXPECT_EQ(back[k], data[k]) << k;

    // One- and zero-dimensional shapes too.
    WriteNpy(Path("v.npy"), {1.0, 2.0, 3.0}, {3});
    EXPECT_EQ(ReadNpy(Path("v.npy"), shape), (std::vector<double>{1.0, 2.0, 3.0}));
    EXPECT_EQ(shape, (std::vector<std::size_t>{3}));
    WriteNpy(Path("s.npy"), {42.0}, {});
    EXPECT_EQ(ReadNpy(Path("s.npy"), shape), (std::vector<double>{42.0}));
    EXPECT_TRUE(shape.empty());
}

TEST_F(ImageIoTest, NpyHeaderBytesFollowTheFormat) {
    const std::size_t h = 6, w = 11;
    WriteNpy(Path("hits.npy"), HitsLikeData(h, w), {h, w, 5});
    const std::string bytes = ReadBytes(Path("hits.npy"));
    ASSERT_GE(bytes.size(), 10u);
    EXPECT_EQ(bytes.substr(0, 6), std::string("\x93NUMPY", 6));
    EXPECT_EQ(bytes[6], '\x01');  // version 1.0
    EXPECT_EQ(bytes[7], '\x00');
    const std::size_t headerLen =
        static_cast<unsigned char>(bytes[8]) |
        (static_cast<std::size_t>(static_cast<unsigned char>(bytes[9])) << 8);
    const std::size_t dataOffset = 10 + headerLen;
    EXPECT_EQ(dataOffset % 64, 0u);
    ASSERT_EQ(bytes.size(), dataOffset + h * w * 5 * 8);
    const std::string header = bytes.substr(10, headerLen);
    const std::string dict =
        "{'descr': '<f8', 'fortran_order': False, 'shape': (6, 11, 5), }";
    EXPECT_EQ(header.substr(0, dict.size()), dict);
    EXPECT_EQ(header.back(), '\n');
    // Padding between the dict and the newline is spaces only.
    for (std::size_t k = dict.size(); k + 1 < header.size(); ++k)
        EXPECT_EQ(header[k], ' ') << k;
    // Little-endian IEEE doubles, C order: the element (1, 2, 3) of the array.
    const std::vector<double> data = HitsLikeData(h, w);
    const std::size_t flat = (1 * w + 2) * 5 + 3;
    double value = 0.0;
    std::memcpy(&value, bytes.data() + dataOffset + 8 * flat, 8);
    EXPECT_EQ(value, data[flat]);
}

TEST_F(ImageIoTest, NpyReaderRejectsMalformedFiles) {
    WriteNpy(Path("good.npy"), HitsLikeData(2, 2), {2, 2, 5});
    const std::string good = ReadBytes(Path("good.npy"));
    std::vector<std::size_t> shape;

    EXPECT_THROW(ReadNpy(Path("missing.npy"), shape), InputError);
    WriteBytes(Path("short.npy"), good.substr(0, 5));
    EXPECT_THROW(ReadNpy(Path("short.npy"), shape), InputError);
    WriteBytes(Path("truncated.npy"), good.substr(0, good.size() - 8));
    EXPECT_THROW(ReadNpy(Path("truncated.npy"), shape), InputError);
    WriteBytes(Path("header-cut.npy"), good.substr(0, 40));
    EXPECT_THROW(ReadNpy(Path("header-cut.npy"), shape), InputError);

    // A header with `dict` (length field consistent) followed by `dataBytes` zero bytes.
    auto npy = [&](const std::string& dict, std::size_t dataBytes) {
        std::string bytes("\x93NUMPY\x01\x00", 8);
        const std::string header = dict + "\n";
        bytes += static_cast<char>(header.size() & 0xff);
        bytes += static_cast<char>(header.size() >> 8);
        return bytes + header + std::string(dataBytes, '\0');
    };
    auto expectError = [&](const std::string& bytes, const std::string& fragment) {
        WriteBytes(Path("bad.npy"), bytes);
        try {
            ReadNpy(Path("bad.npy"), shape);
            ADD_FAILURE() << "accepted: " << bytes.substr(0, 80);
        } catch (const InputError& e) {
            EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos)
                << e.what();
        }
    };
    // The helper itself makes readable files.
    WriteBytes(Path("ok.npy"),
               npy("{'descr': '<f8', 'fortran_order': False, 'shape': (2, 3), }", 48));
    EXPECT_EQ(ReadNpy(Path("ok.npy"), shape).size(), 6u);

    expectError(npy("{'descr': '<f4', 'fortran_order': False, 'shape': (2,), }", 8),
                "<f4");
    expectError(npy("{'descr': '<f8', 'fortran_order': True, 'shape': (2,), }", 16),
                "Fortran");
    // A declared shape far larger than the data is refused before allocating.
    expectError(npy("{'descr': '<f8', 'fortran_order': False, 'shape': (99999999999, "
                    "99999, 5), }",
                    64),
                "exceeds the file size");
    expectError(npy("{'descr': '<f8', 'fortran_order': False, 'shape': "
                    "(18446744073709551615, 3), }",
                    64),
                "exceeds the file size");
    expectError(npy("{'descr': '<f8', 'fortran_order': False, 'shape': "
                    "(184467440737095516150,), }",
                    64),
                "too large");
    expectError(npy("{'descr': '<f8', 'fortran_order': False, 'shape': (3,), }", 16),
                "exceeds the file size");
    expectError(npy("{'descr': '<f8', 'fortran_order': False, 'shape': (3,), }", 32),
                "needs 24 data bytes, file has 32");
    expectError(npy("{'descr': '<f8', 'fortran_order': False, 'shap': (3,), }", 24),
                "shap");
    expectError(npy("{'descr': '<f8', 'fortran_order': False, }", 24), "lacks");
    expectError(npy("{'descr': '<f8', 'fortran_order': False, 'shape': (3,", 24),
                "expected a size");
    expectError(npy("{'descr': '<f8", 24), "unterminated");
    std::string badMagic = good;
    badMagic[3] = 'X';
    expectError(badMagic, "magic");
    std::string badLength = good;
    badLength[9] = '\x7f';
    expectError(badLength, "header length");
}

bool PythonHasNumpy() {
    if (!fs::exists("/usr/bin/python3")) return false;
    return std::system("/usr/bin/python3 -c 'import numpy' >/dev/null 2>&1") == 0;
}

TEST_F(ImageIoTest, NumpyLoadsTheWrittenFile) {
    if (!PythonHasNumpy()) GTEST_SKIP() << "/usr/bin/python3 with numpy not available";
    const std::size_t h = 3, w = 4;
    const std::vector<double> data = HitsLikeData(h, w);
    const std::string path = Path("hits.npy");
    WriteNpy(path, data, {h, w, 5});
    // numpy checks the shape, dtype, order and a few values (computed by the same formula
    // as HitsLikeData) and writes its own file of the same array for a byte comparison.
    const std::string numpyPath = Path("numpy.npy");
    const std::string script =
        "import numpy as np, sys\n"
        "a = np.load(sys.argv[1])\n"
        "assert a.shape == (3, 4, 5), a.shape\n"
        "assert a.dtype == np.float64 and a.flags['C_CONTIGUOUS']\n"
        "assert np.isinf(a[0, 0, 0]) and a[0, 0, 0] > 0\n"
        "assert np.isnan(a[0, 0, 4])\n"
        "k = np.arange(60, dtype=np.float64)\n"
        "want = (0.1 * k - 3.0 + 1e-13 * k * k).reshape(3, 4, 5)\n"
        "assert a[2, 3, 4] == want[2, 3, 4] and a[1, 2, 3] == want[1, 2, 3]\n"
        "assert (a.ravel()[5:] == want.ravel()[5:]).all()\n"
        "np.save(sys.argv[2], a)\n";
    WriteBytes(Path("check.py"), script);
    const std::string command =
        "/usr/bin/python3 " + Path("check.py") + " " + path + " " + numpyPath;
    ASSERT_EQ(std::system(command.c_str()), 0) << command;
    // numpy.save of the same array writes the same header and data bytes.
    EXPECT_EQ(ReadBytes(numpyPath), ReadBytes(path));
}

}  // namespace
}  // namespace hpray
