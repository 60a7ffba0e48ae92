// Nodal (Lagrange interpolating) bases of every cell of the mesh model: values and
// reference gradients, evaluated without allocation.
//
// Spaces (reference cells and node lattices of mesh/cell.h; p = order):
//   Tet      P_p, closed-form Silvester products prod_m (p*lambda - m)/(m + 1) of the
//            barycentric coordinates: exact nodal functions, no matrix inversion.
//   Hex      Q_p, tensor product of 1-D equispaced Lagrange polynomials (product form).
//   Wedge    P_p(r, s) x P_p(t): Silvester triangle times 1-D Lagrange.
//   Pyramid  The rational space of Bergot, Cohen & Durufle ("Higher-order finite elements
//            for hybrid meshes using new nodal pyramidal elements", J. Sci. Comput. 2010),
//            which is also the space of gmsh's high-order pyramids. With the collapsed
//            coordinates a = (r - t/2)/(1 - t), b = (s - t/2)/(1 - t), c = t, all in
//            [0, 1] over the pyramid, it is
//                B_p = span{ a^i b^j (1 - c)^max(i,j) c^k : 0 <= i, j <= p,
//                                                           0 <= k <= p - max(i, j) },
//            i.e. X^i Y^j t^k / (1 - t)^min(i,j) with X = r - t/2, Y = s - t/2. It contains
//            P_p, its trace on the quad face (t = 0) is Q_p and on each triangle face P_p,
//            so it is conforming with order-p hexes and tets. Its functions are rational,
//            not polynomial: along a straight line (1 - t)^p f is a polynomial of degree
//            <= 2p. Gradients are bounded but direction-dependent at the apex; at t = 1
//            exactly we return the limit along the axis a = b = 1/2.
//            The nodal basis is built from the level functions
//                psi_ijk = l^(q)_i(a) l^(q)_j(b) (1 - c)^q S_k(c),   q = p - k,
//            (l^(q): degree-q equispaced Lagrange on [0, 1], S_k: the Silvester factor that
//            is 1 at level k and 0 at levels below). psi_ijk is in B_p, is the Kronecker
//            delta on its own level and vanishes on every lower level, so the collocation
//            matrix is unit block-triangular: it is inverted exactly by block substitution
//            (which also proves unisolvence on the equispaced lattice).
//   Serendipity (order 2): hex20 spans the monomials of superlinear degree <= 2,
//            wedge15 spans P_2(r,s) x {1, t} + {1, r, s} t^2, pyramid13 spans B_2 minus
//            a^2 b^2 (1 - c)^2 (trace: 8-node serendipity quad on the base, P_2 on the
//            triangles). Each is evaluated as the order-2 Lagrange basis of the same shape
//            plus the exact correction N_m += N_m(x_r) N^full_r over the dropped nodes r.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "mesh/cell.h"

namespace hpray {

/// The closed set of basis implementations; EvalBasis switches on it.
enum class BasisKind : std::uint8_t {
    TetLagrange,
    HexLagrange,
    WedgeLagrange,
    PyramidLagrange,
    HexSerendipity,
    WedgeSerendipity,
    PyramidSerendipity
};

/// Largest node count of any supported cell (hex of order 10).
inline constexpr int kMaxBasisNodes = (kMaxOrder + 1) * (kMaxOrder + 1) * (kMaxOrder + 1);

/// Everything EvalBasis needs for one (shape, order, family), built once and shared.
/// Immutable after construction, so safe to use from any number of threads.
struct BasisTable {
    BasisKind kind = BasisKind::HexLagrange;
    CellShape shape = CellShape::Hex;
    CellFamily family = CellFamily::Lagrange;
    int order = 1;
    int nodeCount = 0;
    /// True for the polynomial spaces (all but pyramids).
    bool polynomial = true;
    /// Along any straight line of the reference cell, (1 - t)^lineDenominatorPower * f is a
    /// polynomial of degree <= lineDegree in the line parameter. Polynomial spaces have
    /// lineDenominatorPower == 0 and lineDegree = the maximal total degree of the space
    /// (tet p, hex 3p, wedge 2p, hex20 4, wedge15 3); pyramids: 2p over (1 - t)^p
    /// (pyramid13: 3 over (1 - t)^1).
    int lineDegree = 0;
    int lineDenominatorPower = 0;
    /// Lattice indices and reference coordinates of the nodes, internal order.
    std::vector<LatticeIndex> lattice;
    std::vector<std::array<double, 3>> refNodes;

    // Pyramid Lagrange: N_m = sum_l psiToNodal[l * n + m] psi_l; psi_l with l on level k is
    // only combined into nodes m < levelEnd[k] (block-triangular structure). Evaluation
    // instead solves V^T N = psi level by level from the apex down, using that the block
    // of V between node level kn and function level kl < kn is
    //   couplingScale[kn * (p+1) + kl] * (E (x) E),  E[in][il] = l^(ql)_il(in / qn),
    // with E stored row-major at coupling[couplingOffset[kn * (p+1) + kl]].
    std::vector<double> psiToNodal;
    std::vector<int> levelEnd;
    std::vector<double> coupling;
    std::vector<int> couplingOffset;
    std::vector<double> couplingScale;

    // Serendipity: the order-2 Lagrange table of the shape and, for every serendipity node
    // m, fullIndex[m] (its index in the full lattice); dropped[d] is a full-lattice index and
    // correction[d * nodeCount + m] = N_m(x_dropped[d]).
    const BasisTable* full = nullptr;
    std::vector<int> fullIndex;
    std::vector<int> dropped;
    std::vector<double> correction;
};

/// The cached table of a supported (shape, order, family); thread-safe, lives for the
/// program. Throws InternalError for an unsupported combination (see mesh/cell.h).
const BasisTable& GetBasis(CellShape shape, int order,
                           CellFamily family = CellFamily::Lagrange);

/// Evaluates all nodal basis functions at reference point `ref` (frame of mesh/cell.h; any
/// point, also outside the cell, is allowed — pyramids: t != 1 off the axis).
/// `values`: nodeCount entries, N_m(ref) in internal node order. `dRef`: null, or
/// 3 * nodeCount entries, dRef[3 m + d] = dN_m / dref_d. Buffers are owned by the caller;
/// nothing is allocated. Thread-safe.
void EvalBasis(const BasisTable& basis, const double ref[3], double* values, double* dRef);
/// EvalBasis of a Lagrange pyramid by the path for every order (EvalBasis takes a
/// specialised one for the linear pyramid, which must give bitwise the same values).
void EvalPyramidAnyOrder(const BasisTable& basis, const double ref[3], double* values,
                         double* dRef);

/// Reference cell membership: the largest signed Euclidean distance (reference units) of
/// `ref` beyond the planes of the cell's faces; <= 0 inside the closed cell, > 0 outside.
double RefOutsideDistance(CellShape shape, const double ref[3]);

/// Reference coordinates of the cell's centroid of vertices (a safe interior point).
std::array<double, 3> RefCenter(CellShape shape);

}  // namespace hpray
