// Whole-image 'over' compositing of two partial images of the same frame.
#include "over.h"

#include "util/check.h"

namespace hpray::compositor {

void CompositeOver(Image& accumulated, const Image& behind) {
    HPRAY_CHECK_EQ(accumulated.width, behind.width);
    HPRAY_CHECK_EQ(accumulated.height, behind.height);
    const std::size_t n = accumulated.PixelCount();
    for (std::size_t p = 0; p < n; ++p) {
        if (IsEmptyAt(behind, p)) continue;
        StorePixel(accumulated, p, Over(LoadPixel(accumulated, p), LoadPixel(behind, p)));
    }
}

void CompositeUnder(const Image& front, Image& back) {
    HPRAY_CHECK_EQ(front.width, back.width);
    HPRAY_CHECK_EQ(front.height, back.height);
    const std::size_t n = back.PixelCount();
    for (std::size_t p = 0; p < n; ++p) {
        if (IsEmptyAt(front, p)) continue;
        StorePixel(back, p, Over(LoadPixel(front, p), LoadPixel(back, p)));
    }
}

}  // namespace hpray::compositor
