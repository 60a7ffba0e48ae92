// The one axis-aligned box of hpray, and the rule that says which box a point on a shared
// face belongs to.
//
// Ownership rule. A k-d tree cuts its root box by planes x[axis] = split; the low child
// holds x[axis] < split, the high child x[axis] >= split. So a leaf is half-open: a face
// on a split plane (an inner face) belongs to the box only if it is a lower face; the
// faces on the root box's boundary belong to it. Every point of the root box belongs to
// exactly one leaf (Box::Contains).
//
// A ray is cut into per-leaf pieces by the same planes (ClipRay). A ray lying in a split
// plane belongs to the high side only, as its points do; a ray along an edge where
// several boxes meet to the one box that holds its points. A ray that crosses a split
// plane is cut there at bitwise the same t in both boxes, and the crossing point goes to
// the piece that starts there: every piece is [t_enter, t_exit), closed at t_exit only
// where the ray leaves the root box. That is the rule the traversal applies to the cells
// of one brick (a point event on a face shared by two segments belongs to the second),
// so a partitioned render draws an isosurface hit or a slice exactly on a split plane
// once, as the whole mesh does, and a ray that only grazes a box (touches it in a point,
// or along a face the box does not own) gets no piece of it. Partition directories, the
// in-memory split, the compositor's visibility order and the renderer all use this rule.
#pragma once

#include <algorithm>
#include <cmath>
#include <array>
#include <cstdint>
#include <limits>
#include <utility>

namespace hpray {

/// An axis-aligned box in world units: lo[d] <= x[d] <= hi[d], where a face that lies on
/// an inner split plane of a k-d tree is marked in `inner` (bit d: the lower face of axis
/// d, bit 3 + d: the upper face) and is treated by the ownership rule above. A plain box,
/// the default, has no inner face and is closed. An empty box has lo > hi on some axis.
struct Box {
    std::array<double, 3> lo{};
    std::array<double, 3> hi{};
    std::uint8_t inner = 0;

    /// The box holding nothing (lo = +inf, hi = -inf): Extend it to build bounds.
    static Box Empty() {
        constexpr double inf = std::numeric_limits<double>::infinity();
        return {{inf, inf, inf}, {-inf, -inf, -inf}};
    }
    bool IsEmpty() const {
        return !(lo[0] <= hi[0] && lo[1] <= hi[1] && lo[2] <= hi[2]);
    }
    bool InnerLo(int axis) const { return (inner >> axis) & 1; }
    bool InnerHi(int axis) const { return (inner >> (3 + axis)) & 1; }

    /// Grows the box to hold point `x` or box `b`.
    void Extend(const double x[3]) {
        for (int d = 0; d < 3; ++d) {
            lo[d] = std::min(lo[d], x[d]);
            hi[d] = std::max(hi[d], x[d]);
        }
    }
    void Extend(const Box& b) {
        for (int d = 0; d < 3; ++d) {
            lo[d] = std::min(lo[d], b.lo[d]);
            hi[d] = std::max(hi[d], b.hi[d]);
        }
    }

    /// Whether point `x` belongs to the box (inner upper faces excluded).
    bool Contains(const double x[3]) const {
        for (int d = 0; d < 3; ++d) {
            if (!(x[d] >= lo[d])) return false;
            if (InnerHi(d) ? !(x[d] < hi[d]) : !(x[d] <= hi[d])) return false;
        }
        return true;
    }

    /// Whether the closed boxes of `*this` and `b` share a point (a conservative test:
    /// boxes touching in a face count).
    bool Touches(const Box& b) const {
        for (int d = 0; d < 3; ++d)
            if (hi[d] < b.lo[d] || b.hi[d] < lo[d]) return false;
        return true;
    }

    /// The points in both boxes: the larger lower bound and the smaller upper bound; a
    /// face is inner where the box that sets it has it inner (either, on a tie).
    Box Intersect(const Box& b) const {
        Box r;
        for (int d = 0; d < 3; ++d) {
            bool innerLo, innerHi;
            if (lo[d] != b.lo[d]) {
                r.lo[d] = std::max(lo[d], b.lo[d]);
                innerLo = lo[d] > b.lo[d] ? InnerLo(d) : b.InnerLo(d);
            } else {
                r.lo[d] = lo[d];
                innerLo = InnerLo(d) || b.InnerLo(d);
            }
            if (hi[d] != b.hi[d]) {
                r.hi[d] = std::min(hi[d], b.hi[d]);
                innerHi = hi[d] < b.hi[d] ? InnerHi(d) : b.InnerHi(d);
            } else {
                r.hi[d] = hi[d];
                innerHi = InnerHi(d) || b.InnerHi(d);
            }
            if (innerLo) r.inner |= std::uint8_t(1u << d);
            if (innerHi) r.inner |= std::uint8_t(1u << (3 + d));
        }
        return r;
    }

    double Diagonal() const {
        double s = 0;
        for (int d = 0; d < 3; ++d) s += (hi[d] - lo[d]) * (hi[d] - lo[d]);
        return std::sqrt(s);
    }
    std::array<double, 3> Center() const {
        return {0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), 0.5 * (lo[2] + hi[2])};
    }
    /// Same bounds and same inner faces.
    bool operator==(const Box& b) const {
        return lo == b.lo && hi == b.hi && inner == b.inner;
    }
    bool operator!=(const Box& b) const { return !(*this == b); }
};

/// The part of a ray's parameter line inside a box: from t0 to t1, each end included or
/// not. Empty when t0 > t1, or t0 == t1 with an end left out.
struct RaySpan {
    double t0 = -std::numeric_limits<double>::infinity();
    double t1 = std::numeric_limits<double>::infinity();
    bool closed0 = true, closed1 = true;

    bool IsEmpty() const { return !(t0 < t1 || (t0 == t1 && closed0 && closed1)); }
    /// Whether parameter t lies in the span.
    bool Holds(double t) const {
        return (t > t0 || (t == t0 && closed0)) && (t < t1 || (t == t1 && closed1));
    }
};

/// Narrows `span` to the piece of the ray origin + t dir that belongs to `box` under the
/// ownership rule above: the entry end closed, the exit end open where the ray leaves
/// through an inner face. Returns false when nothing is left. A plane's t is
/// (plane - origin) / dir computed from that plane's value alone, so two boxes sharing a
/// plane cut a ray at bitwise the same t. A ray parallel to a slab lies in it iff its
/// origin does (lo <= o < hi at an inner upper face, lo <= o <= hi otherwise).
inline bool ClipRay(const double origin[3], const double dir[3], const Box& box,
                    RaySpan& span) {
    for (int a = 0; a < 3; ++a) {
        const double o = origin[a], d = dir[a];
        if (d == 0) {
            if (o < box.lo[a] || o > box.hi[a] || (o == box.hi[a] && box.InnerHi(a))) {
                span.t0 = 1;
                span.t1 = 0;
                return false;
            }
            continue;
        }
        const double tLo = (box.lo[a] - o) / d, tHi = (box.hi[a] - o) / d;
        // Enters through one face (closed), leaves through the other.
        const double tIn = d > 0 ? tLo : tHi, tOut = d > 0 ? tHi : tLo;
        const bool openOut = d > 0 ? box.InnerHi(a) : box.InnerLo(a);
        if (tIn > span.t0) {
            span.t0 = tIn;
            span.closed0 = true;
        }
        if (tOut < span.t1) {
            span.t1 = tOut;
            span.closed1 = !openOut;
        } else if (tOut == span.t1 && openOut) {
            span.closed1 = false;
        }
    }
    return !span.IsEmpty();
}

}  // namespace hpray
