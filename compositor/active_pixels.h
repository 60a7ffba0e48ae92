// Active-pixel run-length encoding: the wire format of the compositor's messages.
#pragma once

#include <cstddef>
#include <memory>
#include <vector>

#include "image/image.h"

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

/// An allocator that default-initialises, so that growing a message buffer does not
/// write zeros that are overwritten at once (a full pass over up to S bytes per message).
template <typename T>
struct DefaultInitAllocator : std::allocator<T> {
    template <typename U>
    struct rebind {
        using other = DefaultInitAllocator<U>;
    };
    DefaultInitAllocator() = default;
    template <typename U>
    DefaultInitAllocator(const DefaultInitAllocator<U>&) noexcept {}
    template <typename U>
    void construct(U* p) noexcept {
        ::new (static_cast<void*>(p)) U;
    }
    template <typename U, typename... Args>
    void construct(U* p, Args&&... args) {
        ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
    }
};

/// A compositor message: doubles in the wire format of EncodeActive.
using WireBuffer = std::vector<double, DefaultInitAllocator<double>>;

/// Appends to `out` the non-empty pixels (IsEmpty false) of `image` in `range`, as runs:
/// for each maximal run of non-empty pixels, [offset of its first pixel from
/// range.begin, pixel count, then kChannels doubles per pixel in Pixel member order].
/// Empty pixels cost nothing; a run costs 2 doubles of header. Returns the number of
/// non-empty pixels. `range` must lie inside the image.
std::size_t EncodeActive(const Image& image, PixelRange range, WireBuffer& out);

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
