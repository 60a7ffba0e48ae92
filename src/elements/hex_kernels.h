// Evaluation kernels of Lagrange hexahedra, one set per order with the sizes known at compile
// time, chosen from a table once per cell or ray segment (the dispatch of MFEM's
// kernel_dispatch.hpp): the loops unroll and the partial sums stay in registers. Every
// kernel performs the same operations in the same order as the generic sum-factorised code
// of tensor_eval.h, so its results are bitwise the same (tests/elements/test_hex_kernels.cpp).
#pragma once

namespace hpray {

struct HexKernels {
    int order = 0;
    /// f(ref) for nodal values u in the internal hex order (i fastest).
    double (*value)(const double* u, const double ref[3]) = nullptr;
    /// f(ref) and its reference gradient.
    double (*valueGradient)(const double* u, const double ref[3], double dRef[3]) = nullptr;
    /// World point and, if jacobian is not null, d world_i / d ref_j (row-major), of the map
    /// with interleaved node coordinates xyz.
    void (*map)(const double* xyz, const double ref[3], double world[3],
                double* jacobian) = nullptr;
};

/// The kernels of order p, 1 <= p <= kMaxOrder (mesh/cell.h).
const HexKernels& HexKernelsFor(int p);

}  // namespace hpray
