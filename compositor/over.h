// The 'over' operator on image pixels: premultiplied colour, nearest hit, added error.
#pragma once

#include <cstddef>
#include <limits>

#include "io/image.h"

namespace hpray::compositor {

/// Doubles per pixel on the wire and in Pixel, in the channel order of hpray::Image.
constexpr int kChannels = 11;
/// Bytes per active pixel on the wire (run headers excluded): the stats' bytes_per_pixel.
constexpr int kBytesPerPixel = kChannels * static_cast<int>(sizeof(double));

/// All channels of one pixel (meanings and units as hpray::Image / design.md). Plain and
/// trivially copyable; member order is the wire order of the compositor's messages.
struct Pixel {
    double r = 0.0, g = 0.0, b = 0.0, a = 0.0;  ///< premultiplied colour and opacity
    double z = std::numeric_limits<double>::infinity();  ///< t of nearest hit, +inf: none
    double nx = 0.0, ny = 0.0, nz = 0.0;                 ///< normal at that hit
    double isoResidual = std::numeric_limits<double>::quiet_NaN();  ///< NaN: no hit
    double isoId = -1.0;                                            ///< -1: no hit
    double volError = 0.0;  ///< absolute error estimate of RGB; adds over segments
};

/// True iff `p` is the identity of Over: r = g = b = a = 0, no hit (z = +inf) and
/// volError = 0. Such pixels are never sent. The hit fields of a no-hit pixel are ignored
/// (by contract they are 0, NaN, -1).
inline bool IsEmpty(const Pixel& p) {
    return p.r == 0.0 && p.g == 0.0 && p.b == 0.0 && p.a == 0.0 &&
           p.z == std::numeric_limits<double>::infinity() && p.volError == 0.0;
}

/// `front` over `back` for two pieces of the same ray whose regions of space are disjoint
/// and `front`'s is nearer the camera: colour and alpha out = front + (1 - front.a) back;
/// z, normal, isoResidual and isoId from the nearer hit (smaller z; a tie keeps front);
/// volError = front.volError + back.volError. Associative (to rounding), not commutative;
/// the empty pixel is a two-sided identity.
inline Pixel Over(const Pixel& front, const Pixel& back) {
    Pixel out;
    const double t = 1.0 - front.a;
    out.r = front.r + t * back.r;
    out.g = front.g + t * back.g;
    out.b = front.b + t * back.b;
    out.a = front.a + t * back.a;
    const Pixel& hit = back.z < front.z ? back : front;
    out.z = hit.z;
    out.nx = hit.nx;
    out.ny = hit.ny;
    out.nz = hit.nz;
    out.isoResidual = hit.isoResidual;
    out.isoId = hit.isoId;
    out.volError = front.volError + back.volError;
    return out;
}

/// Pixel `index` (j * width + i) of `image`; no bounds check.
inline Pixel LoadPixel(const Image& image, std::size_t index) {
    Pixel p;
    p.r = image.r[index];
    p.g = image.g[index];
    p.b = image.b[index];
    p.a = image.a[index];
    p.z = image.z[index];
    p.nx = image.nx[index];
    p.ny = image.ny[index];
    p.nz = image.nz[index];
    p.isoResidual = image.isoResidual[index];
    p.isoId = image.isoId[index];
    p.volError = image.volError[index];
    return p;
}

/// Writes `p` to pixel `index` of `image`; no bounds check.
inline void StorePixel(Image& image, std::size_t index, const Pixel& p) {
    image.r[index] = p.r;
    image.g[index] = p.g;
    image.b[index] = p.b;
    image.a[index] = p.a;
    image.z[index] = p.z;
    image.nx[index] = p.nx;
    image.ny[index] = p.ny;
    image.nz[index] = p.nz;
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

}  // namespace hpray::compositor
