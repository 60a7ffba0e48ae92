// Evaluation kernels of Lagrange tetrahedra, one set per order with the sizes known at
// compile time, chosen from a table once per cell (as hex_kernels.h for hexahedra). Each
// fuses the basis (Silvester factors, as basis.cpp evaluates them) with the sums over the
// nodes, without the basis arrays in between, and performs the same operations in the
// same order as EvalBasis followed by those sums in elements/geometry.cpp and
// elements/field.cpp: its results are bitwise the same
// (tests/elements/test_hex_kernels.cpp). The one exception is the order-3 map, whose node
// sums go in another order (TetMapBlocked3 below), four nodes at a time.
#pragma once

namespace hpray {

struct TetKernels {
    int order = 0;
    /// f(ref) for nodal values u in the internal tet order (lattice (i, j, k), i fastest,
    /// then j, then k).
    double (*value)(const double* u, const double ref[3]) = nullptr;
    /// f(ref) and its reference gradient.
    double (*valueGradient)(const double* u, const double ref[3],
                            double dRef[3]) = nullptr;
    /// World point and, if jacobian is not null, d world_i / d ref_j (row-major), of the
    /// map with interleaved node coordinates xyz.
    void (*map)(const double* xyz, const double ref[3], double world[3],
                double* jacobian) = nullptr;
    /// value at n points (refs: x, y, z of each in turn) into out[0..n): bitwise `value`
    /// at each, four at a time in the lanes of vectors where the build has them.
    void (*values)(const double* u, const double* refs, int n, double* out) = nullptr;
};

/// The kernels of order p, 1 <= p <= kMaxOrder (mesh/cell.h).
const TetKernels& TetKernelsFor(int p);

/// The order-3 map as its kernel sums the nodes (four interleaved partial sums, node m in
/// sum m mod 4 by fused multiply-adds, added as (s0 + s1) + (s2 + s3); the other orders
/// sum in node order, unfused), in scalar arithmetic: the kernel's result bitwise, in
/// any build.
void TetMapBlocked3(const double* xyz, const double ref[3], double world[3],
                    double* jacobian);

}  // namespace hpray
