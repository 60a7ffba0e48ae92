// Named colour maps for `color_tf: {map: NAME, range: ...}` (scripts/gen_colormaps.py
// names their published sources).
#pragma once

#include <string>
#include <vector>

#include "scene/scene.h"

namespace hpray {

/// The names of the colour maps, in the order the error messages list them.
std::vector<std::string> ColorMapNames();
/// Whether `name` is a colour map.
bool IsColorMap(const std::string& name);
/// The colour map `name` spread over [lo, hi] (lo < hi) as a colour transfer function:
/// 33 control points, the map's sRGB samples converted to linear RGB (the colours hpray
/// computes with; its PNG encodes them back to sRGB). Throws std::out_of_range for an
/// unknown name.
std::vector<ColorControlPoint> ExpandColorMap(const std::string& name, double lo, double hi);

}  // namespace hpray
