// Silvester factors: the one-dimensional building blocks of equispaced Lagrange bases on
// simplices and tensor cells (basis.cpp), shared with the per-order kernels
// (tet_kernels.cpp), which call them with a constant order.
#pragma once

namespace hpray {

/// Silvester factors of order p: s[m] = prod_{q<m} (p x - q) / (q + 1), m = 0..p, and
/// their derivatives in x. s[m] is 1 at x = m/p and 0 at x = 0, 1/p, ..., (m-1)/p.
template <typename Real>
inline void Silvester(int p, Real x, Real* s, Real* ds) {
    const Real px = p * x;
    s[0] = 1;
    ds[0] = 0;
    for (int m = 0; m < p; ++m) {
        const Real inv = Real(1) / Real(m + 1);
        const Real f = (px - m) * inv;
        ds[m + 1] = ds[m] * f + s[m] * (p * inv);
        s[m + 1] = s[m] * f;
    }
}

}  // namespace hpray
