// Active-pixel run-length encoding: the wire format of the compositor's messages.
#pragma once

#include <cstddef>
#include <vector>

#include "io/image.h"

namespace hpray::compositor {

/// A half-open range [begin, end) of linear pixel indices (j * width + i).
struct PixelRange {
    std::size_t begin = 0;
    std::size_t end = 0;

    std::size_t Size() const { return end > begin ? end - begin : 0; }
    bool Empty() const { return end <= begin; }
};

/// The overlap of two ranges (empty if they do not meet).
inline PixelRange Intersect(const PixelRange& x, const PixelRange& y) {
    PixelRange out{x.begin > y.begin ? x.begin : y.begin, x.end < y.end ? x.end : y.end};
    if (out.end < out.begin) out.end = out.begin;
    return out;
}

/// Appends to `out` the non-empty pixels (IsEmpty false) of `image` in `range`, as runs:
/// for each maximal run of non-empty pixels, [offset of its first pixel from
/// range.begin, pixel count, then kChannels doubles per pixel in Pixel member order].
/// Empty pixels cost nothing; a run costs 2 doubles of header. Returns the number of
/// non-empty pixels. `range` must lie inside the image.
std::size_t EncodeActive(const Image& image, PixelRange range, std::vector<double>& out);

/// How DecodeActive combines an incoming pixel `in` with the image's pixel `cur`.
enum class DecodeMode {
    Assign,  ///< cur := in
    Over,    ///< cur := in over cur (the incoming data lies in front)
    Under,   ///< cur := cur over in (the incoming data lies behind)
};

/// Applies an EncodeActive message `data[0, count)` made for `range` to `image`; pixels
/// not in the message are left as they are (the empty pixel is the identity of Over).
/// A malformed message (runs outside the range, truncated data) is an InternalError:
/// messages only ever come from EncodeActive on another rank.
void DecodeActive(const double* data, std::size_t count, PixelRange range,
                  DecodeMode mode, Image& image);

/// Sets every pixel of `range` to the empty pixel (transparent, no hit, no error).
void ClearRange(Image& image, PixelRange range);

}  // namespace hpray::compositor
