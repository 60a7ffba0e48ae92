// The rendered image: double-precision channels of design.md, structure of arrays.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace hpray {

/// Per-pixel channels, each W*H doubles, row-major with the top row first (pixel (i, j) at
/// index j * width + i). Colour is linear and premultiplied by alpha.
struct Image {
    int width = 0;
    int height = 0;
    std::vector<double> r, g, b, a;       ///< premultiplied RGBA
    std::vector<double> z;                ///< t of nearest isosurface hit, +inf where none
    std::vector<double> nx, ny, nz;       ///< unit normal at that hit, 0 where none
    std::vector<double> isoResidual;      ///< |f(x_hit) - C|, NaN where none
    std::vector<double> isoId;            ///< isosurface index, -1 where none
    std::vector<double> volError;         ///< estimated abs. error of RGB, 0 without volume

    /// Allocates all channels at their "empty" values (transparent black, no hit).
    void Resize(int w, int h);
    std::size_t PixelCount() const { return static_cast<std::size_t>(width) * height; }

    /// Names and pointers of every channel, in the EXR channel naming of design.md.
    std::vector<std::pair<std::string, std::vector<double>*>> Channels();
    std::vector<std::pair<std::string, const std::vector<double>*>> Channels() const;
};

/// Writes `image` as a one-part OpenEXR file with float32 channels R G B A Z N.X N.Y N.Z
/// iso.residual iso.id vol.error. Throws InputError(path) if the file cannot be written.
void WriteExr(const std::string& path, const Image& image);
/// Reads such a file back (for tests and tools); throws InputError on a bad file.
Image ReadExr(const std::string& path);

/// Writes the RGB composited over `background` (linear RGB), sRGB-encoded, 8 bits.
void WritePng(const std::string& path, const Image& image, const std::array<double, 3>& background);
/// Reads an 8-bit RGB/RGBA PNG into `rgb` (W*H*3 bytes, top row first).
void ReadPng(const std::string& path, int& width, int& height, std::vector<std::uint8_t>& rgb);

/// sRGB transfer function applied to a linear value in [0, 1] (clamped), result in [0, 1].
double LinearToSrgb(double linear);

/// Writes a float64 NumPy .npy array of shape `shape` (C order) from `data`.
void WriteNpy(const std::string& path, const std::vector<double>& data,
              const std::vector<std::size_t>& shape);
/// Reads a float64 little-endian C-order .npy file.
std::vector<double> ReadNpy(const std::string& path, std::vector<std::size_t>& shape);

}  // namespace hpray
