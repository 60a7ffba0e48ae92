// Named colour maps: sRGB samples of their published tables, expanded to linear RGB.
#include "scene/colormaps.h"

#include <array>
#include <cmath>
#include <stdexcept>

namespace hpray {
namespace {

struct ColorMap {
    const char* name;
    std::array<std::array<double, 3>, 33> srgb;
};

const ColorMap kMaps[] = {
#include "scene/colormaps_data.inc"
};

/// The sRGB transfer function inverted (IEC 61966-2-1).
double SrgbToLinear(double c) {
    return c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4);
}

}  // namespace

std::vector<std::string> ColorMapNames() {
    std::vector<std::string> names;
    for (const ColorMap& m : kMaps) names.push_back(m.name);
    return names;
}

bool IsColorMap(const std::string& name) {
    for (const ColorMap& m : kMaps)
        if (name == m.name) return true;
    return false;
}

std::vector<ColorControlPoint> ExpandColorMap(const std::string& name, double lo,
                                              double hi) {
    for (const ColorMap& m : kMaps) {
        if (name != m.name) continue;
        std::vector<ColorControlPoint> points;
        const int n = static_cast<int>(m.srgb.size());
        for (int k = 0; k < n; ++k) {
            ColorControlPoint p;
            p.scalar = k + 1 == n ? hi : lo + (hi - lo) * k / (n - 1);
            for (int c = 0; c < 3; ++c) p.rgb[c] = SrgbToLinear(m.srgb[k][c]);
            points.push_back(p);
        }
        return points;
    }
    throw std::out_of_range("no colour map named '" + name + "'");
}

}  // namespace hpray
