// Sum-factorised hexahedron field evaluation (see tensor_eval.h).
#include "elements/tensor_eval.h"

#include <Eigen/Core>

#include "mesh/cell.h"

namespace hpray {

void LagrangeEquispaced1D(int p, double x, double* l, double* dl) {
    // Silvester factors s_m(x) = prod_{q<m} (p x - q)/(q + 1) of x and of 1 - x.
    double a[kMaxOrder + 1], da[kMaxOrder + 1], b[kMaxOrder + 1], db[kMaxOrder + 1];
    const double xs[2] = {x, 1.0 - x};
    double* s[2] = {a, b};
    double* ds[2] = {da, db};
    for (int w = 0; w < 2; ++w) {
        const double px = p * xs[w];
        s[w][0] = 1;
        ds[w][0] = 0;
        for (int m = 0; m < p; ++m) {
            const double inv = 1.0 / (m + 1);
            const double f = (px - m) * inv;
            ds[w][m + 1] = ds[w][m] * f + s[w][m] * (p * inv);
            s[w][m + 1] = s[w][m] * f;
        }
    }
    for (int i = 0; i <= p; ++i) {
        l[i] = a[i] * b[p - i];
        if (dl) dl[i] = da[i] * b[p - i] - a[i] * db[p - i];
    }
}

double HexFieldValue(int p, const double* u, const double ref[3]) {
    double l[3][kMaxOrder + 1];
    for (int d = 0; d < 3; ++d) LagrangeEquispaced1D(p, ref[d], l[d], nullptr);
    const int n = p + 1;
    double f = 0;
    for (int k = 0; k < n; ++k) {
        double fk = 0;
        for (int j = 0; j < n; ++j) {
            const double* row = u + n * (j + n * k);
            double fj = 0;
            for (int i = 0; i < n; ++i) fj += row[i] * l[0][i];
            fk += fj * l[1][j];
        }
        f += fk * l[2][k];
    }
    return f;
}

double HexFieldValueGradient(int p, const double* u, const double ref[3], double dRef[3]) {
    double l[3][kMaxOrder + 1], dl[3][kMaxOrder + 1];
    for (int d = 0; d < 3; ++d) LagrangeEquispaced1D(p, ref[d], l[d], dl[d]);
    const int n = p + 1;
    double f = 0, fr = 0, fs = 0, ft = 0;
    for (int k = 0; k < n; ++k) {
        double fk = 0, frk = 0, fsk = 0;
        for (int j = 0; j < n; ++j) {
            const double* row = u + n * (j + n * k);
            double fj = 0, frj = 0;
            for (int i = 0; i < n; ++i) {
                fj += row[i] * l[0][i];
                frj += row[i] * dl[0][i];
            }
            fk += fj * l[1][j];
            frk += frj * l[1][j];
            fsk += fj * dl[1][j];
        }
        f += fk * l[2][k];
        fr += frk * l[2][k];
        fs += fsk * l[2][k];
        ft += fk * dl[2][k];
    }
    dRef[0] = fr;
    dRef[1] = fs;
    dRef[2] = ft;
    return f;
}

void HexFieldValuesAlongLine(int p, const double* u, const double ref0[3],
                             const double dref[3], const double* t, int count, double* out,
                             double* scratch) {
    const int n = p + 1;
    // L_d(i, s): 1-D polynomials of each direction at every sample.
    double* L[3] = {scratch, scratch + n * count, scratch + 2 * n * count};
    for (int s = 0; s < count; ++s)
        for (int d = 0; d < 3; ++d)
            LagrangeEquispaced1D(p, ref0[d] + t[s] * dref[d], L[d] + n * s, nullptr);
    // A(jk, s) = sum_i u(i, jk) L_0(i, s): one matrix product, U^T (n^2 x n) * L_0 (n x S).
    using Mat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic>;
    Eigen::Map<const Mat> U(u, n, n * n);
    Eigen::Map<const Mat> L0(L[0], n, count);
    Eigen::Map<Mat> A(scratch + 3 * n * count, n * n, count);
    A.noalias() = U.transpose() * L0;
    for (int s = 0; s < count; ++s) {
        const double* a = A.data() + static_cast<std::size_t>(n) * n * s;
        const double* l1 = L[1] + n * s;
        const double* l2 = L[2] + n * s;
        double f = 0;
        for (int k = 0; k < n; ++k) {
            double fk = 0;
            for (int j = 0; j < n; ++j) fk += a[j + n * k] * l1[j];
            f += fk * l2[k];
        }
        out[s] = f;
    }
}

}  // namespace hpray
