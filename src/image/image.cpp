// Image channels and whole-image compositing.
#include "image/image.h"

#include <limits>

#include "util/check.h"

namespace hpray {

void Image::Resize(int w, int h) {
    HPRAY_CHECK_GE(w, 0);
    HPRAY_CHECK_GE(h, 0);
    width = w;
    height = h;
    const std::size_t n = PixelCount();
    const double inf = std::numeric_limits<double>::infinity();
    const double nan = std::numeric_limits<double>::quiet_NaN();
    r.assign(n, 0.0);
    g.assign(n, 0.0);
    b.assign(n, 0.0);
    a.assign(n, 0.0);
    z.assign(n, inf);
    nx.assign(n, 0.0);
    ny.assign(n, 0.0);
    nz.assign(n, 0.0);
    isoResidual.assign(n, nan);
    isoId.assign(n, -1.0);
    volError.assign(n, 0.0);
}

std::vector<std::pair<std::string, std::vector<double>*>> Image::Channels() {
    return {{"R", &r},
            {"G", &g},
            {"B", &b},
            {"A", &a},
            {"Z", &z},
            {"N.X", &nx},
            {"N.Y", &ny},
            {"N.Z", &nz},
            {"iso.residual", &isoResidual},
            {"iso.id", &isoId},
            {"vol.error", &volError}};
}

std::vector<std::pair<std::string, const std::vector<double>*>> Image::Channels() const {
    // The same list, read-only: the mutable one does not modify the image.
    std::vector<std::pair<std::string, const std::vector<double>*>> out;
    for (const auto& [name, channel] : const_cast<Image*>(this)->Channels())
        out.emplace_back(name, channel);
    return out;
}

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

}  // namespace hpray
