// Writing and reading images (OpenEXR, PNG, NumPy .npy); the image itself is in
// image/image.h.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "image/canvas.h"
#include "image/image.h"

namespace hpray {

/// Writes `image` as a one-part OpenEXR file with float32 channels R G B A Z N.X N.Y N.Z
/// iso.residual iso.id vol.error. Throws InputError(path) if the file cannot be written.
void WriteExr(const std::string& path, const Image& image);
/// Reads such a file back (for tests and tools); throws InputError on a bad file.
Image ReadExr(const std::string& path);

/// Writes the RGB composited over `background` (linear RGB), sRGB-encoded, 8 bits.
void WritePng(const std::string& path, const Image& image, const std::array<double, 3>& background);
/// Writes a picture (linear RGB, annotations included), sRGB-encoded, 8 bits.
void WritePng(const std::string& path, const Canvas& canvas);
/// Reads an 8-bit RGB/RGBA PNG into `rgb` (W*H*3 bytes, top row first).
void ReadPng(const std::string& path, int& width, int& height, std::vector<std::uint8_t>& rgb);

/// sRGB transfer function applied to a linear value in [0, 1] (clamped), result in [0, 1].
double LinearToSrgb(double linear);
/// The 8-bit sRGB code of a linear value, floor(255 LinearToSrgb(linear) + 1/2), by the
/// function itself (a power per call).
std::uint8_t EncodeSrgb8Reference(double linear);
/// The same byte for every double, from a table of the 255 smallest values of each
/// code (found once by bisection on the function itself, which is monotone) in 4096
/// cells of [0, 1]: a lookup and a comparison or two instead of a power.
std::uint8_t EncodeSrgb8(double linear);

/// Writes a float64 NumPy .npy array of shape `shape` (C order) from `data`.
void WriteNpy(const std::string& path, const std::vector<double>& data,
              const std::vector<std::size_t>& shape);
/// The same for a float32 array.
void WriteNpyFloat32(const std::string& path, const std::vector<float>& data,
              const std::vector<std::size_t>& shape);
/// Reads a float64 little-endian C-order .npy file.
std::vector<double> ReadNpy(const std::string& path, std::vector<std::size_t>& shape);

}  // namespace hpray
