// Guaranteed per-cell bounds: the range of a field and the box of the geometry, from
// Bernstein-Bezier coefficients (convex hull property).
//
// Method by shape (nodal values -> Bernstein coefficients -> min/max):
//   Hex      tensor product of the 1-D equispaced-Lagrange -> Bernstein transform.
//   Tet      simplex Bernstein polynomials of degree p (dense transform).
//   Wedge    triangle Bernstein (degree p) x 1-D Bernstein (degree p).
//   Pyramid  every function of the Bergot space is, in the collapsed coordinates
//            (a, b, c) in [0,1]^3 of basis.h, a polynomial of degree <= p in each of a, b,
//            c (a^i b^j (1-c)^max(i,j) c^k with i, j <= p and max(i,j) + k <= p). The
//            collapse map is onto the pyramid, so the range of f over the pyramid is the
//            range of a Q_p polynomial over the unit cube, bounded by its tensor Bernstein
//            coefficients. They are computed exactly from the level functions psi of
//            basis.h, each a product of 1-D polynomials of degree <= p in a, b and c.
//   Serendipity  the space is contained in the order-2 Lagrange space of the shape: the
//            dropped nodal values are interpolated exactly, then as above.
// Transforms are computed once in extended precision. Rounding is covered rigorously:
// each coefficient is widened by gamma * (|T| |f|)_k, with gamma bounding the relative
// error of the floating-point sums (n u per length-n sum) and of the stored transforms.
#pragma once

#include <array>

#include "elements/basis.h"
#include "geom/box.h"

namespace hpray {

struct Interval {
    double lo = 0.0;
    double hi = 0.0;
};

/// An interval containing f(x) for every x of the closed reference cell, where f is the
/// interpolant of the nodal coefficients coeffs[m * stride], m < basis.nodeCount (internal
/// order). Allocates a few small vectors per call (meant for once per cell at load).
Interval FieldBounds(const BasisTable& basis, const double* coeffs, int stride = 1);

/// An axis-aligned box containing the image of the whole reference cell; `nodeXyz` holds
/// x y z interleaved per node, internal order.
Box GeometryBox(const BasisTable& basis, const double* nodeXyz);

/// A box that holds GeometryBox(basis, nodeXyz), from the range of the node coordinates
/// alone (widened by the Bernstein transform's largest absolute row sum, with room for
/// every rounding of the exact box): where only a union of boxes is wanted, a cell whose
/// enclosure lies strictly inside the union so far needs no exact box. Lagrange
/// tetrahedra of up to 35 nodes; an infinite box for other bases.
Box GeometryBoxEnclosure(const BasisTable& basis, const double* nodeXyz);

/// The largest number of pieces per direction of HexSubBounds.
inline constexpr int kMaxSubdivision = 4;

/// Bounds of a Lagrange hexahedron's interpolant over the n^3 equal boxes of its
/// reference cube (1 <= n <= kMaxSubdivision): the Bernstein coefficients of the
/// interpolant restricted to each box (the 1-D subdivision matrices applied along each
/// axis, sum-factorised), their range widened by a bound of their rounding. `coeffs`: the
/// (p + 1)^3 nodal values in internal order, `comps` interleaved components (3 for node
/// coordinates). out[box * comps + c] for box = k0 + n (k1 + n k2), k0 along the first
/// reference axis. A component with a non-finite value gets infinite intervals.
void HexSubBounds(int p, int n, const double* coeffs, int comps, Interval* out);

/// The number of sub-tetrahedra of TetSubBounds at `levels` refinements: 8^levels.
int TetSubCount(int levels);

/// The refinements used for order-p tetrahedra: 2 (64 sub-tetrahedra) up to p = 4, 1 up
/// to p = 7, 0 above (each table holds 8^levels dense transforms of the cell's node
/// count, and each cell costs as many products).
inline int TetSubLevels(int p) { return p <= 4 ? 2 : p <= 7 ? 1 : 0; }

/// Bounds of a Lagrange tetrahedron's interpolant over the sub-tetrahedra of `levels`
/// (0 to 2) uniform refinements of its reference cell (each tetrahedron into its 4 corner
/// ones and the 4 of its inner octahedron): the Bernstein coefficients of the interpolant
/// restricted to each (one dense transform per sub-tetrahedron, built once per order),
/// their range widened by a bound of their rounding. `coeffs`: basis.nodeCount nodal
/// values in internal order, `comps` interleaved components; out[sub * comps + c]. A
/// component with a non-finite value gets infinite intervals.
void TetSubBounds(const BasisTable& basis, int levels, const double* coeffs, int comps,
                  Interval* out);

}  // namespace hpray
