// 8-bit sRGB PNG output (RGB composited over the background) and input, via libpng.
#include <png.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <system_error>

#include "io/image.h"
#include "io/output_file.h"
#include "util/check.h"
#include "util/error.h"

namespace hpray {

namespace {

// A deflate stream cannot expand by more than ~1:1032, and every pixel costs at least one
// byte before compression; a header declaring more pixels than this per file byte is bad.
constexpr unsigned long long kMaxPixelsPerFileByte = 4096;
constexpr png_uint_32 kMaxExtent = 1u << 16;

/// Releases libpng's state of a simplified-API read if it is abandoned early.
class PngImageGuard {
  public:
    explicit PngImageGuard(png_image& image) : image_(image) {}
    ~PngImageGuard() { png_image_free(&image_); }
    PngImageGuard(const PngImageGuard&) = delete;
    PngImageGuard& operator=(const PngImageGuard&) = delete;

  private:
    png_image& image_;
};

/// Writes 8-bit sRGB samples, 3 per pixel, top row first.
void WriteRgb8(const std::string& path, int width, int height,
               const std::vector<std::uint8_t>& rgb) {
    png_image png;
    std::memset(&png, 0, sizeof(png));
    png.version = PNG_IMAGE_VERSION;
    png.width = static_cast<png_uint_32>(width);
    png.height = static_cast<png_uint_32>(height);
    png.format = PNG_FORMAT_RGB;  // 8-bit sRGB: libpng records an sRGB chunk
    // libpng's fast setting (fast deflate, simple filters): t16's 1024^2 picture in 20 ms
    // against 65 ms, for a file of 281 kB against 147 kB (the quick start's: 25 kB
    // against 19 kB).
    png.flags = PNG_IMAGE_FLAG_FAST;

    const std::string tmp = detail::BeginOutputFile(path);
    const int ok = png_image_write_to_file(&png, tmp.c_str(), 0, rgb.data(),
                                           static_cast<png_int_32>(3 * width), nullptr);
    if (!ok) {
        const std::string message = png.message;
        png_image_free(&png);
        detail::AbandonOutputFile(tmp);
        throw InputError(path, "", "cannot write PNG file: " + message);
    }
    detail::CommitOutputFile(tmp, path);
}

}  // namespace

void WritePng(const std::string& path, const Image& image,
              const std::array<double, 3>& background) {
    HPRAY_CHECK(image.width >= 1 && image.height >= 1);
    const std::size_t n = image.PixelCount();
    HPRAY_CHECK(image.r.size() == n && image.g.size() == n && image.b.size() == n &&
                image.a.size() == n);

    // Premultiplied colour over an opaque background: out = c + (1 - a) * background
    // (Canvas::Over, without a picture in memory: 3 bytes a pixel).
    std::vector<std::uint8_t> rgb(3 * n);
    for (std::size_t p = 0; p < n; ++p) {
        const double transmit = 1.0 - image.a[p];
        rgb[3 * p + 0] = EncodeSrgb8(image.r[p] + transmit * background[0]);
        rgb[3 * p + 1] = EncodeSrgb8(image.g[p] + transmit * background[1]);
        rgb[3 * p + 2] = EncodeSrgb8(image.b[p] + transmit * background[2]);
    }
    WriteRgb8(path, image.width, image.height, rgb);
}

void WritePng(const std::string& path, const Canvas& canvas) {
    HPRAY_CHECK(canvas.width >= 1 && canvas.height >= 1);
    const std::size_t n = static_cast<std::size_t>(canvas.width) * canvas.height;
    HPRAY_CHECK(canvas.rgb.size() == 3 * n);
    std::vector<std::uint8_t> rgb(3 * n);
    for (std::size_t k = 0; k < 3 * n; ++k) rgb[k] = EncodeSrgb8(canvas.rgb[k]);
    WriteRgb8(path, canvas.width, canvas.height, rgb);
}

void ReadPng(const std::string& path, int& width, int& height,
             std::vector<std::uint8_t>& rgb) {
    std::error_code ec;
    const auto fileSize = std::filesystem::file_size(path, ec);
    if (ec) throw InputError(path, "", "cannot open file: " + ec.message());

    png_image png;
    std::memset(&png, 0, sizeof(png));
    png.version = PNG_IMAGE_VERSION;
    PngImageGuard guard(png);
    if (!png_image_begin_read_from_file(&png, path.c_str()))
        throw InputError(path, "header",
                         std::string("not a readable PNG: ") + png.message);
    if (png.format & PNG_FORMAT_FLAG_LINEAR)
        throw InputError(path, "header", "16-bit PNG files are not supported");
    if (png.width < 1 || png.height < 1 || png.width > kMaxExtent ||
        png.height > kMaxExtent ||
        static_cast<unsigned long long>(png.width) * png.height >
            static_cast<unsigned long long>(fileSize) * kMaxPixelsPerFileByte)
        throw InputError(path, "IHDR",
                         "implausible image size " + std::to_string(png.width) + " x " +
                             std::to_string(png.height));

    // Read as RGBA (no compositing or gamma change of 8-bit samples), then drop alpha.
    png.format = PNG_FORMAT_RGBA;
    std::vector<std::uint8_t> rgba(PNG_IMAGE_SIZE(png));
    if (!png_image_finish_read(&png, nullptr, rgba.data(), 0, nullptr))
        throw InputError(path, "data", std::string("cannot decode PNG: ") + png.message);

    width = static_cast<int>(png.width);
    height = static_cast<int>(png.height);
    const std::size_t n = static_cast<std::size_t>(width) * height;
    rgb.resize(3 * n);
    for (std::size_t p = 0; p < n; ++p) {
        rgb[3 * p + 0] = rgba[4 * p + 0];
        rgb[3 * p + 1] = rgba[4 * p + 1];
        rgb[3 * p + 2] = rgba[4 * p + 2];
    }
}

}  // namespace hpray
