// Rays, segments and boxes of the traversal API: plain, trivially copyable records.
#pragma once

#include <array>
#include <cstdint>
#include <type_traits>
#include <utility>

#include "geom/box.h"

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

/// Narrows `span` to the part of the ray inside `box` under the ownership rule of
/// geom/box.h (ClipRay); false when nothing is left.
inline bool ClipRayToBox(const Ray& ray, const Box& box, RaySpan& span) {
    return ClipRay(ray.origin, ray.dir, box, span);
}

}  // namespace hpray
