// Inverse of a small dense matrix in long double, for tables built once (collocation
// matrices of polynomial bases).
#pragma once

#include <cmath>
#include <cstddef>
#include <utility>
#include <vector>

#include "util/check.h"

namespace hpray {

/// Inverse of the n x n row-major matrix m by Gauss-Jordan elimination with partial
/// pivoting, in long double. The matrix must be invertible (checked).
inline std::vector<long double> InvertDense(int n, std::vector<long double> a) {
    std::vector<long double> inv(std::size_t(n) * n, 0.0L);
    for (int i = 0; i < n; ++i) inv[std::size_t(i) * n + i] = 1;
    for (int c = 0; c < n; ++c) {
        int piv = c;
        for (int r = c + 1; r < n; ++r)
            if (std::fabs(a[std::size_t(r) * n + c]) >
                std::fabs(a[std::size_t(piv) * n + c]))
                piv = r;
        HPRAY_CHECK(a[std::size_t(piv) * n + c] != 0);
        for (int k = 0; k < n; ++k) {
            std::swap(a[std::size_t(c) * n + k], a[std::size_t(piv) * n + k]);
            std::swap(inv[std::size_t(c) * n + k], inv[std::size_t(piv) * n + k]);
        }
        const long double d = a[std::size_t(c) * n + c];
        for (int k = 0; k < n; ++k) {
            a[std::size_t(c) * n + k] /= d;
            inv[std::size_t(c) * n + k] /= d;
        }
        for (int r = 0; r < n; ++r) {
            if (r == c) continue;
            const long double f = a[std::size_t(r) * n + c];
            if (f == 0) continue;
            for (int k = 0; k < n; ++k) {
                a[std::size_t(r) * n + k] -= f * a[std::size_t(c) * n + k];
                inv[std::size_t(r) * n + k] -= f * inv[std::size_t(c) * n + k];
            }
        }
    }
    return inv;
}

}  // namespace hpray
