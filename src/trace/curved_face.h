// Exact ray crossings of curved (polynomial) cell faces: Bernstein control nets built
// from the faces' nodes, crossings counted by a winding rule on the faces' boundary
// curves that neighbouring faces evaluate identically, and located by subdivision and
// Newton.
//
// The rule (see trace/ray_frame.h for the straight-face rule it extends). In the sheared
// ray frame the ray is the origin of a plane and a face is a polynomial map G(u, v) of
// its parameter domain D into that plane; the ray crosses the face where G = 0. The
// signed number of crossings (+1 where G is orientation-preserving) is the winding number
// of the boundary curve G(dD) around the origin, and that winding number is a sum over
// the boundary's edges of one integer per edge: the signed number of times the edge
// crosses the half-line from the perturbed origin X = (eps, eps^2), eps -> 0+, towards
// +x. The count of an edge is computed from the edge's own Bernstein control points only,
// by deciding hull tests that are exact under the perturbation (all control points with
// y > 0, or y <= 0, or x <= 0: no crossing; all with x > 0: the change of [y > 0] between
// the end points) and bisection at parameter 1/2 otherwise; straight edges use the exact
// segment predicate EdgeSign of ray_frame.h on their end points, which is what planar and
// bilinear faces are decided by. Neighbouring faces hold bitwise identical control points
// for a shared edge (built from the edge's nodes in a canonical order), the count is
// exactly antisymmetric in the edge's direction, so the counts of the faces around a
// closed cell sum to zero exactly: no ray leaks through an edge or crosses it twice,
// whatever rounding does near it. Midpoint bisection is also exactly additive, which lets
// the same counts, restricted to sub-patches, tell how many crossings each sub-patch of a
// subdivided face holds; a sub-patch whose derivative cones prove it injective holds
// |count| <= 1 crossing, found by Newton from its centre.
//
// Limits: a sub-patch that stays non-injective down to the depth limit (the ray is
// tangent to the face within about 1e-6 of the face's parameter range) is given |count|
// crossings at the Newton root from its centre, so two crossings that close together (a
// tangent ray's double root) are dropped as a pair; bisection of an edge count stops at
// depth 60, where the last sub-curve is taken as its chord — the same for both faces. A
// straight edge's sub-patch sides are its (rounded) control points on the segment; where
// their count differs from the exact segment count (the ray passes within rounding of
// the edge), the crossing at the edge is added, or the one found next to it dropped.
#pragma once

#include <cstdint>
#include <vector>

#include "trace/face_map.h"
#include "trace/ray_frame.h"

namespace hpray::trace {

/// Number of Bernstein control points of a triangle (P_p) or quadrilateral (Q_p) face,
/// stored in the node lattice order of face_map.h (j-major, i fastest): point (i, j) of a
/// triangle has the weight p! / (i! j! k!) u^i v^j w^k with w = 1 - u - v, k = p - i - j;
/// of a quadrilateral B_i(u) B_j(v) with B_i(s) = C(p, i) s^i (1 - s)^(p - i).
int NetSize(bool triangle, int order);

/// Lattice index of the k-th point (k = 0..order) along boundary edge e of a face, in the
/// counter-clockwise order of the parameter domain: triangle e0 (0,0)->(1,0), e1 (1,0)->
/// (0,1), e2 (0,1)->(0,0); quadrilateral e0 (0,0)->(1,0), e1 (1,0)->(1,1), e2
/// (1,1)->(0,1), e3 (0,1)->(0,0). The same index addresses a face's nodes and its control
/// net.
int EdgeLatticeIndex(bool triangle, int order, int e, int k);

/// Bernstein control points (order + 1 points, 3 doubles each, caller-owned) of the curve
/// interpolating `nodal` at s = k / order. End points are copied bitwise.
void EdgeBernstein(int order, const double* nodal, double* net);

/// Bernstein control net (NetSize points, 3 doubles each, caller-owned) of the triangle
/// (P_p) or quadrilateral (Q_p) face interpolating `nodal` (the same number of points, on
/// the equispaced lattice of face_map.h). Corners are copied bitwise. Orders 1..10.
void FaceBernstein(bool triangle, int order, const double* nodal, double* net);

/// Value and first derivatives at (u, v) (any point) of a net given in the ray frame.
void EvalNet(bool triangle, int order, const ShearedPoint* net, double u, double v,
             double value[3], double dU[3], double dV[3]);

/// A curved face as the traversal holds it.
struct CurvedFace {
    const double* net = nullptr;  ///< world control points, NetSize(triangle, order) x 3
    bool triangle = true;
    int order = 2;
    /// Bit e set: boundary edge e is straight; it is counted by the exact segment
    /// predicate on its two corners (its interior control points must lie on the
    /// segment).
    std::uint8_t straightEdges = 0;
    double size = 0;  ///< diagonal of the control points' box, world units
};

/// One crossing of the ray with a face. side +1: the ray runs along the face normal
/// dG/du x dG/dv (for the canonical corner order, (B - A) x (C - A)); -1: against it.
struct FaceCrossing {
    double t = 0;         ///< ray parameter, world units
    double u = 0, v = 0;  ///< face parameters of the crossing
    int side = 0;
};

/// Tolerances of CrossCurvedFace.
struct CurvedFaceOptions {
    /// Newton stops (after one more polishing step) once |G(u, v)| <= tolerance (world
    /// units, the face's size times the mapping tolerance).
    double tolerance = 1e-12;
    int maxNewtonIterations = 30;
};

/// Appends to `out` every crossing of the ray line (any t) with the face, as decided by
/// the rule above; bitwise the same for the same face and frame. Thread-safe. Returns the
/// number of crossings whose Newton iteration failed (their t is the face point at the
/// centre of a sub-patch smaller than 1e-6 of the face).
int CrossCurvedFace(const CurvedFace& face, const RayFrame& frame,
                    const CurvedFaceOptions& options, std::vector<FaceCrossing>& out);

}  // namespace hpray::trace
