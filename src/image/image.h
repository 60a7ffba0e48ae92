// The rendered image and its pixels: the channel layout of every output (double
// precision, structure of arrays), one pixel record for a ray's result and the
// compositor's messages, and the 'over' operator that combines pieces of a ray. Below io/
// (which writes images) and the compositor (which sends them between ranks).
#pragma once

#include <cstddef>
#include <limits>
#include <string>
#include <utility>
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

    /// Names and pointers of every channel, in the EXR channel naming of docs/contracts.md.
    std::vector<std::pair<std::string, std::vector<double>*>> Channels();
    std::vector<std::pair<std::string, const std::vector<double>*>> Channels() const;
};

/// Doubles per pixel on the wire and in Pixel, in the channel order of Image.
constexpr int kChannels = 11;
/// Bytes per active pixel on the wire (run headers excluded): the stats' bytes_per_pixel.
constexpr int kBytesPerPixel = kChannels * static_cast<int>(sizeof(double));

/// All channels of one pixel (meanings and units as Image): what a ray gives, and what the
/// compositor sends. Plain and trivially copyable; member order is the wire order of the
/// compositor's messages and the channel order of Image.
struct Pixel {
    double rgba[4] = {0.0, 0.0, 0.0, 0.0};  ///< premultiplied colour and opacity
    double z = std::numeric_limits<double>::infinity();  ///< t of nearest hit, +inf: none
    double normal[3] = {0.0, 0.0, 0.0};                  ///< unit normal at that hit
    double isoResidual = std::numeric_limits<double>::quiet_NaN();  ///< NaN: no hit
    double isoId = -1.0;                                            ///< -1: no hit
    double volError = 0.0;  ///< absolute error estimate of RGB; adds over segments
};
static_assert(sizeof(Pixel) == kChannels * sizeof(double));

/// True iff `p` is the identity of Over: r = g = b = a = 0, no hit (z = +inf) and
/// volError = 0. Such pixels are never sent. The hit fields of a no-hit pixel are ignored
/// (by contract they are 0, NaN, -1).
inline bool IsEmpty(const Pixel& p) {
    return p.rgba[0] == 0.0 && p.rgba[1] == 0.0 && p.rgba[2] == 0.0 && p.rgba[3] == 0.0 &&
           p.z == std::numeric_limits<double>::infinity() && p.volError == 0.0;
}

/// `front` over `back` for two pieces of the same ray whose regions of space are disjoint
/// and `front`'s is nearer the camera: colour and alpha out = front + (1 - front.a) back;
/// z, normal, isoResidual and isoId from the nearer hit (smaller z; a tie keeps front);
/// volError = front.volError + back.volError. Associative (to rounding), not commutative;
/// the empty pixel is a two-sided identity.
inline Pixel Over(const Pixel& front, const Pixel& back) {
    Pixel out;
    const double t = 1.0 - front.rgba[3];
    for (int c = 0; c < 4; ++c) out.rgba[c] = front.rgba[c] + t * back.rgba[c];
    const Pixel& hit = back.z < front.z ? back : front;
    out.z = hit.z;
    for (int c = 0; c < 3; ++c) out.normal[c] = hit.normal[c];
    out.isoResidual = hit.isoResidual;
    out.isoId = hit.isoId;
    out.volError = front.volError + back.volError;
    return out;
}

/// Pixel `index` (j * width + i) of `image`; no bounds check.
inline Pixel LoadPixel(const Image& image, std::size_t index) {
    Pixel p;
    p.rgba[0] = image.r[index];
    p.rgba[1] = image.g[index];
    p.rgba[2] = image.b[index];
    p.rgba[3] = image.a[index];
    p.z = image.z[index];
    p.normal[0] = image.nx[index];
    p.normal[1] = image.ny[index];
    p.normal[2] = image.nz[index];
    p.isoResidual = image.isoResidual[index];
    p.isoId = image.isoId[index];
    p.volError = image.volError[index];
    return p;
}

/// Writes `p` to pixel `index` of `image`; no bounds check.
inline void StorePixel(Image& image, std::size_t index, const Pixel& p) {
    image.r[index] = p.rgba[0];
    image.g[index] = p.rgba[1];
    image.b[index] = p.rgba[2];
    image.a[index] = p.rgba[3];
    image.z[index] = p.z;
    image.nx[index] = p.normal[0];
    image.ny[index] = p.normal[1];
    image.nz[index] = p.normal[2];
    image.isoResidual[index] = p.isoResidual;
    image.isoId[index] = p.isoId;
    image.volError[index] = p.volError;
}

/// IsEmpty of pixel `index` of `image` without loading the hit fields.
inline bool IsEmptyAt(const Image& image, std::size_t index) {
    return image.a[index] == 0.0 && image.r[index] == 0.0 && image.g[index] == 0.0 &&
           image.b[index] == 0.0 && image.volError[index] == 0.0 &&
           image.z[index] == std::numeric_limits<double>::infinity();
}

/// accumulated := accumulated over behind, pixel by pixel (front-to-back accumulation of
/// a rank's own bricks in visibility order). Both images must have the same size
/// (InternalError otherwise).
void CompositeOver(Image& accumulated, const Image& behind);

/// back := front over back, pixel by pixel (back-to-front accumulation). Same sizes.
void CompositeUnder(const Image& front, Image& back);

}  // namespace hpray
