// Rays, segments and boxes of the traversal API: plain, trivially copyable records.
#pragma once

#include <array>
#include <cstdint>
#include <type_traits>
#include <utility>

namespace hpray {

/// A ray in world coordinates. `dir` must be a unit vector, so the ray parameter t is the
/// world distance from `origin`.
struct Ray {
    double origin[3] = {0, 0, 0};
    double dir[3] = {0, 0, 1};
};

/// The part (tEnter, tExit) of a ray inside one cell. `cell` is the 0-based index in the
/// brick mesh's cell order; t in world units along the ray. Consecutive segments of one
/// ray are sorted and, while the ray stays inside the mesh, the next tEnter is exactly
/// (bitwise) the previous tExit.
struct Segment {
    std::int64_t cell = -1;
    double tEnter = 0;
    double tExit = 0;
};
static_assert(std::is_trivially_copyable_v<Segment>);
static_assert(std::is_trivially_copyable_v<Ray>);

/// An axis-aligned box {{xmin, ymin, zmin}, {xmax, ymax, zmax}} in world units.
using AxisBox = std::array<std::array<double, 3>, 2>;

/// Clips the ray to the closed box (slab method). Returns false when the ray misses it or
/// the clipped range is empty; otherwise narrows [tLow, tHigh] to the part inside. Each
/// box plane's t is computed as (plane - origin) / dir from that plane's value alone, so
/// two boxes sharing a plane (neighbouring bricks) cut a ray at bitwise the same t.
/// A ray parallel to a slab is inside it iff its origin is in the closed slab.
inline bool ClipRayToBox(const Ray& ray, const AxisBox& box, double& tLow, double& tHigh) {
    for (int a = 0; a < 3; ++a) {
        const double o = ray.origin[a], d = ray.dir[a];
        if (d == 0) {
            if (o < box[0][a] || o > box[1][a]) return false;
            continue;
        }
        double t0 = (box[0][a] - o) / d, t1 = (box[1][a] - o) / d;
        if (t0 > t1) std::swap(t0, t1);
        if (t0 > tLow) tLow = t0;
        if (t1 < tHigh) tHigh = t1;
    }
    return tLow <= tHigh;
}

}  // namespace hpray
