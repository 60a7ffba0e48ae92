// Closed-form intersection of a ray with a bilinear patch (Reshetov, "Cool patches: a
// geometric approach to ray/bilinear patch intersections", Ray Tracing Gems, 2019).
#pragma once

namespace hpray::trace {

/// One intersection of the ray line with the patch's surface.
struct PatchRoot {
    double u = 0, v = 0;  ///< patch parameters (not limited to [0, 1])
    double t = 0;         ///< ray parameter, world units
};

/// All intersections (0, 1 or 2) of the full line origin + t dir with the bilinear
/// surface P(u, v) = (1-u)(1-v) q00 + u(1-v) q10 + u v q11 + (1-u) v q01, with no limit on
/// t, u or v (the caller selects). Returns the count; roots[] is caller-owned.
int IntersectBilinearPatch(const double origin[3], const double dir[3], const double q00[3],
                           const double q10[3], const double q11[3], const double q01[3],
                           PatchRoot roots[2]);

}  // namespace hpray::trace
