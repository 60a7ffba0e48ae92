// Polynomial maps of curved cell faces in a canonical face parametrisation, with
// derivatives: the 2-D traces of the cell spaces of elements/basis.h on their faces.
//
// Traversal must evaluate a face the same way whichever of its two cells asks, so faces
// are not evaluated through a cell's 3-D basis but through their own 2-D nodal basis on
// their own node lattice, in canonical order (see brick_traverser.cpp):
//   Triangle  P_p on {u, v >= 0, u + v <= 1}, node (i, j) at (i, j) / p — the trace of
//             tets, wedges and pyramids (Bergot's space restricted to a triangle face).
//   Quad      Q_p on [0, 1]^2, node (i, j) at (i, j) / p — hexes, wedges, pyramid bases.
//   QuadSerendipity  the 8-node serendipity quadrilateral (order 2 without the centre
//             node), the trace of hex20, wedge15 and pyramid13 on their quad faces.
// Nodes are numbered j-major, i fastest (serendipity: the 3 x 3 lattice without (1, 1)).
#pragma once

#include <array>
#include <cstdint>

namespace hpray::trace {

enum class FaceBasis : std::uint8_t { Triangle = 0, Quad = 1, QuadSerendipity = 2 };

/// Largest face node count (quad of order 10).
inline constexpr int kMaxFaceNodes = 121;

/// Number of nodes of the face basis of this order (serendipity: 8, order must be 2).
int FaceNodeCount(FaceBasis basis, int order);

/// Lattice index (i, j) of node m, in [0, p]^2 (triangle: i + j <= p).
std::array<int, 2> FaceNodeLattice(FaceBasis basis, int order, int m);

/// Evaluates all basis functions at (u, v) (any point; no range check). `values`,
/// `dU`, `dV`: FaceNodeCount entries each, caller-owned; dU / dV may be null.
void EvalFaceBasis(FaceBasis basis, int order, double u, double v, double* values,
                   double* dU, double* dV);

}  // namespace hpray::trace
