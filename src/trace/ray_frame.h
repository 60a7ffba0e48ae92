// Exact, watertight ray-triangle crossing tests in a sheared ray frame (after Woop,
// Benthin & Wald, "Watertight ray/triangle intersection", JCGT 2013), with exact 2-D
// orientation signs and a symbolic perturbation that decides every tie.
//
// The rule that makes traversal watertight: every point is sheared into the ray frame
// (the ray becomes the origin of a 2-D plane) by the same arithmetic whichever face or
// cell asks, and whether the ray passes left or right of an edge (P, Q) is the EXACT sign
// of the 2-D cross product of the sheared P and Q, evaluated for the ray origin moved to
// (eps, eps^2) with eps -> 0+ (simulation of simplicity). That sign depends on the edge
// alone and flips exactly with its direction, and no edge or vertex is ever exactly hit,
// so a ray through a vertex, along an edge or inside a face is treated as the perturbed
// ray: it crosses the faces whose (sheared, rounded) projections contain the perturbed
// origin, each exactly once — it neither leaks between faces nor counts one twice. Faces
// seen edge-on by the ray (it lies in their plane) are not crossed: the perturbed ray
// runs beside them, inside one of the cells they separate.
#pragma once

#include <cmath>
#include <utility>

#include "trace/ray.h"

namespace hpray::trace {

/// A point in the sheared ray frame: (x, y) the projection along the ray, z = the ray
/// parameter t of the point's projection onto the ray line (world units).
struct ShearedPoint {
    double x = 0, y = 0, z = 0;
};

/// The shear that maps the ray onto the +z axis of a 2-D plane (Woop et al.). Built once
/// per ray; Transform is the only way points enter the frame, so a point transformed
/// twice gives bitwise the same result.
struct RayFrame {
    double org[3] = {0, 0, 0};
    double dir[3] = {0, 0, 1};
    int kx = 0, ky = 1, kz = 2;
    double sx = 0, sy = 0, sz = 1;
    double invDir[3] = {0, 0, 1};  ///< 1 / dir (infinite where dir is 0), for slab tests
    double ox = 0, oy = 0, oz = 0;  ///< org[kx], org[ky], org[kz]

    explicit RayFrame(const Ray& ray) {
        for (int a = 0; a < 3; ++a) {
            org[a] = ray.origin[a];
            dir[a] = ray.dir[a];
            invDir[a] = 1.0 / dir[a];
        }
        kz = 0;
        if (std::fabs(dir[1]) > std::fabs(dir[kz])) kz = 1;
        if (std::fabs(dir[2]) > std::fabs(dir[kz])) kz = 2;
        kx = (kz + 1) % 3;
        ky = (kx + 1) % 3;
        // Keep the winding: a triangle whose normal has a positive component along the
        // ray is counter-clockwise in the sheared (x, y) plane.
        if (dir[kz] < 0) std::swap(kx, ky);
        sx = dir[kx] / dir[kz];
        sy = dir[ky] / dir[kz];
        sz = 1.0 / dir[kz];
        ox = org[kx];
        oy = org[ky];
        oz = org[kz];
    }

    /// Bitwise the same in every translation unit whatever its -ffp-contract setting: on
    /// targets with FMA the shear is an explicit fused multiply-add (nothing left for the
    /// compiler to fuse differently), elsewhere nothing can be fused.
    ShearedPoint Transform(const double* p) const {
        const double ax = p[kx] - ox, ay = p[ky] - oy, az = p[kz] - oz;
#if defined(__FMA__) || defined(__ARM_FEATURE_FMA)
        return {std::fma(-sx, az, ax), std::fma(-sy, az, ay), sz * az};
#else
        return {ax - sx * az, ay - sy * az, sz * az};
#endif
    }
};

namespace detail {

inline void TwoSum(double a, double b, double& s, double& e) {
    s = a + b;
    const double bv = s - a, av = s - bv;
    e = (a - av) + (b - bv);
}

/// Exact sign of p0 + p1 + p2 + p3 (grow-expansion, Shewchuk 1997).
inline int ExactSumSign(const double p[4]) {
    double h[4];
    int n = 0;
    for (int k = 0; k < 4; ++k) {
        double q = p[k];
        for (int i = 0; i < n; ++i) {
            double s, e;
            TwoSum(q, h[i], s, e);
            h[i] = e;
            q = s;
        }
        h[n++] = q;
    }
    for (int i = n - 1; i >= 0; --i)
        if (h[i] != 0) return h[i] > 0 ? 1 : -1;
    return 0;
}

}  // namespace detail

/// Shewchuk's orient2d static filter, (3 eps + 16 eps^2) (|a| + |b|): px * qy - py * qx
/// computed in floating point as a - b is of its exact sign when beyond this bound.
constexpr double kCrossSignFilter = 3.3306690738754716e-16;

/// The sign of px * qy - py * qx where the static filter decides it (then it is the exact
/// sign), else 0 (ExactCrossSign decides it), without branches.
inline int FilteredCrossSign(double px, double py, double qx, double qy) {
    const double a = px * qy, b = py * qx;
    const double e = a - b;
    const double bound = kCrossSignFilter * (std::fabs(a) + std::fabs(b));
    return int(e > bound) - int(e < -bound);
}

/// Exact sign of the 2-D cross product px * qy - py * qx.
inline int ExactCrossSign(double px, double py, double qx, double qy) {
    const double a = px * qy, b = py * qx;
    const double e = a - b;
    const double bound = kCrossSignFilter * (std::fabs(a) + std::fabs(b));
    if (e > bound) return 1;
    if (e < -bound) return -1;
    const double terms[4] = {a, std::fma(px, qy, -a), -b, -std::fma(py, qx, -b)};
    return detail::ExactSumSign(terms);
}

/// Which side of the sheared edge (P, Q) the perturbed ray passes: the sign of
/// cross(P - X, Q - X) for X = (eps, eps^2), eps -> 0+. +1 / -1, or 0 only when P and Q
/// coincide in the projection (the edge is parallel to the ray through it).
/// Antisymmetric: EdgeSign(q, p) == -EdgeSign(p, q) exactly.
inline int EdgeSign(const ShearedPoint& p, const ShearedPoint& q) {
    const int s = ExactCrossSign(p.x, p.y, q.x, q.y);
    if (s != 0) return s;
    if (p.y != q.y) return p.y > q.y ? 1 : -1;
    if (q.x != p.x) return q.x > p.x ? 1 : -1;
    return 0;
}

/// A crossing of the ray with a planar triangle (A, B, C).
struct TriangleCrossing {
    double t = 0;                ///< ray parameter, world units
    double bary[3] = {0, 0, 0};  ///< barycentric weights of A, B, C (sum 1, each >= 0)
    /// +1: the ray runs along the normal (B - A) x (C - A); -1: against it.
    int side = 0;
};

/// The crossing of the ray with triangle (A, B, C) once the signs of its three edges
/// (EdgeSign of (B, C), (C, A), (A, B)) are known to be all `side`: t and the
/// barycentrics in floating point from the sheared corners, in the order given.
inline void FinishCrossing(const ShearedPoint& a, const ShearedPoint& b,
                           const ShearedPoint& c, int side, TriangleCrossing& out) {
    double w[3] = {b.x * c.y - b.y * c.x, c.x * a.y - c.y * a.x, a.x * b.y - a.y * b.x};
    // Weights whose rounded value disagrees with the exact decision are ties: zero them.
    double sum = 0;
    for (double& x : w) {
        if (x * side < 0) x = 0;
        sum += x;
    }
    if (sum == 0) {
        out.bary[0] = out.bary[1] = out.bary[2] = 1.0 / 3.0;
    } else {
        const double inv = 1.0 / sum;
        for (int k = 0; k < 3; ++k) out.bary[k] = w[k] * inv;
    }
    out.t = out.bary[0] * a.z + out.bary[1] * b.z + out.bary[2] * c.z;
    out.side = side;
}

/// Watertight crossing test of the (perturbed) ray with triangle (A, B, C) given in the
/// ray frame. The decision uses only EdgeSign of the three edges; t and the barycentrics
/// are computed in floating point from the same sheared points, so a triangle evaluated
/// with its vertices in the same order always gives bitwise the same result.
inline bool CrossTriangle(const ShearedPoint& a, const ShearedPoint& b,
                          const ShearedPoint& c, TriangleCrossing& out) {
    const int sa = EdgeSign(b, c);
    if (sa == 0) return false;
    const int sb = EdgeSign(c, a);
    if (sb != sa) return false;
    const int sc = EdgeSign(a, b);
    if (sc != sa) return false;
    FinishCrossing(a, b, c, sa, out);
    return true;
}

}  // namespace hpray::trace
