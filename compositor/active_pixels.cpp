// Active-pixel run-length encoding and decoding with the three compositing modes.
#include "active_pixels.h"

#include <algorithm>
#include <limits>

#include "image/image.h"
#include "util/check.h"

namespace hpray::compositor {

std::size_t EncodeActive(const Image& image, PixelRange range, WireBuffer& out) {
    HPRAY_CHECK_LE(range.end, image.PixelCount());
    // The worst case (runs of one pixel) needs 13 doubles per two pixels; reserving the
    // bound costs no memory traffic, as untouched pages of a large block stay unmapped.
    out.reserve(out.size() + range.Size() * kChannels + range.Size() + 2);
    std::size_t active = 0;
    std::size_t i = range.begin;
    while (i < range.end) {
        while (i < range.end && IsEmptyAt(image, i)) ++i;
        if (i == range.end) break;
        const std::size_t runStart = i;
        while (i < range.end && !IsEmptyAt(image, i)) ++i;
        const std::size_t runLength = i - runStart;
        // Offsets and counts are exact in a double below 2^53 pixels.
        out.push_back(static_cast<double>(runStart - range.begin));
        out.push_back(static_cast<double>(runLength));
        const std::size_t at = out.size();
        out.resize(at + runLength * kChannels);
        double* dst = out.data() + at;
        for (std::size_t p = runStart; p < i; ++p, dst += kChannels) {
            dst[0] = image.r[p];
            dst[1] = image.g[p];
            dst[2] = image.b[p];
            dst[3] = image.a[p];
            dst[4] = image.z[p];
            dst[5] = image.nx[p];
            dst[6] = image.ny[p];
            dst[7] = image.nz[p];
            dst[8] = image.isoResidual[p];
            dst[9] = image.isoId[p];
            dst[10] = image.volError[p];
        }
        active += runLength;
    }
    return active;
}

namespace {

inline Pixel ReadWire(const double* src) {
    Pixel p;
    p.rgba[0] = src[0];
    p.rgba[1] = src[1];
    p.rgba[2] = src[2];
    p.rgba[3] = src[3];
    p.z = src[4];
    p.normal[0] = src[5];
    p.normal[1] = src[6];
    p.normal[2] = src[7];
    p.isoResidual = src[8];
    p.isoId = src[9];
    p.volError = src[10];
    return p;
}

/// Applies every run of the message with the per-pixel operation `apply(index, src)`.
template <typename Apply>
void ForEachRun(const double* data, std::size_t count, PixelRange range, Apply apply) {
    std::size_t at = 0;
    const double rangeSize = static_cast<double>(range.Size());
    while (at < count) {
        HPRAY_CHECK_MSG(count - at >= 2, "truncated run header in a compositor message");
        const double offset = data[at], length = data[at + 1];
        HPRAY_CHECK_MSG(offset >= 0.0 && length >= 1.0 && offset + length <= rangeSize,
                        "compositor run [" << offset << ", +" << length
                                           << ") outside a range of " << rangeSize);
        at += 2;
        const std::size_t first = range.begin + static_cast<std::size_t>(offset);
        const std::size_t n = static_cast<std::size_t>(length);
        HPRAY_CHECK_MSG((count - at) / kChannels >= n,
                        "truncated pixel data in a compositor message");
        const double* src = data + at;
        for (std::size_t k = 0; k < n; ++k, src += kChannels) apply(first + k, src);
        at += n * kChannels;
    }
}

}  // namespace

void DecodeActive(const double* data, std::size_t count, PixelRange range,
                  DecodeMode mode, Image& image) {
    HPRAY_CHECK_LE(range.end, image.PixelCount());
    switch (mode) {
        case DecodeMode::Assign:
            ForEachRun(data, count, range, [&](std::size_t p, const double* src) {
                StorePixel(image, p, ReadWire(src));
            });
            break;
        case DecodeMode::Over:
            ForEachRun(data, count, range, [&](std::size_t p, const double* src) {
                StorePixel(image, p, Over(ReadWire(src), LoadPixel(image, p)));
            });
            break;
        case DecodeMode::Under:
            ForEachRun(data, count, range, [&](std::size_t p, const double* src) {
                StorePixel(image, p, Over(LoadPixel(image, p), ReadWire(src)));
            });
            break;
    }
}

void ClearRange(Image& image, PixelRange range) {
    HPRAY_CHECK_LE(range.end, image.PixelCount());
    if (range.Empty()) return;
    const auto b = static_cast<std::ptrdiff_t>(range.begin);
    const auto e = static_cast<std::ptrdiff_t>(range.end);
    const double inf = std::numeric_limits<double>::infinity();
    const double nan = std::numeric_limits<double>::quiet_NaN();
    for (auto* channel : {&image.r, &image.g, &image.b, &image.a, &image.nx, &image.ny,
                          &image.nz, &image.volError})
        std::fill(channel->begin() + b, channel->begin() + e, 0.0);
    std::fill(image.z.begin() + b, image.z.begin() + e, inf);
    std::fill(image.isoResidual.begin() + b, image.isoResidual.begin() + e, nan);
    std::fill(image.isoId.begin() + b, image.isoId.begin() + e, -1.0);
}

}  // namespace hpray::compositor
