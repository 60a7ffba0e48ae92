// Compile-time-sized Lagrange hexahedron kernels (see hex_kernels.h). The arithmetic mirrors
// tensor_eval.cpp operation for operation; only the loop bounds are constants here.
#include "elements/hex_kernels.h"

#include <cmath>

#include "elements/tensor_eval.h"
#include "mesh/cell.h"
#include "util/check.h"

namespace hpray {
namespace {

constexpr double kInverse[kMaxOrder + 1] = {1.0,       1.0 / 2, 1.0 / 3, 1.0 / 4,
                                            1.0 / 5,   1.0 / 6, 1.0 / 7, 1.0 / 8,
                                            1.0 / 9,   1.0 / 10, 1.0 / 11};

// LagrangeEquispaced1D for a fixed order P.
template <int P, bool Derivative>
inline void Lagrange1D(double x, double* l, double* dl) {
    double a[P + 1], b[P + 1];
    const double px = P * x, py = P * (1.0 - x);
    a[0] = b[0] = 1;
    if constexpr (!Derivative) {
        for (int m = 0; m < P; ++m) {
            a[m + 1] = a[m] * ((px - m) * kInverse[m]);
            b[m + 1] = b[m] * ((py - m) * kInverse[m]);
        }
        for (int i = 0; i <= P; ++i) l[i] = a[i] * b[P - i];
    } else {
        double da[P + 1], db[P + 1];
        da[0] = db[0] = 0;
        for (int m = 0; m < P; ++m) {
            const double fa = (px - m) * kInverse[m], fb = (py - m) * kInverse[m];
            da[m + 1] = da[m] * fa + a[m] * (P * kInverse[m]);
            db[m + 1] = db[m] * fb + b[m] * (P * kInverse[m]);
            a[m + 1] = a[m] * fa;
            b[m + 1] = b[m] * fb;
        }
        for (int i = 0; i <= P; ++i) {
            l[i] = a[i] * b[P - i];
            dl[i] = da[i] * b[P - i] - a[i] * db[P - i];
        }
    }
}

template <int P>
double Value(const double* u, const double ref[3]) {
    constexpr int n = P + 1;
    double l[3][n];
    for (int d = 0; d < 3; ++d) Lagrange1D<P, false>(ref[d], l[d], nullptr);
    double f = 0;
    for (int k = 0; k < n; ++k) {
        double fk = 0;
        for (int j = 0; j < n; ++j) {
            const double* row = u + n * (j + n * k);
            double fj = 0;
            for (int i = 0; i < n; ++i) fj = std::fma(row[i], l[0][i], fj);
            fk = std::fma(fj, l[1][j], fk);
        }
        f = std::fma(fk, l[2][k], f);
    }
    return f;
}

template <int P>
double ValueGradient(const double* u, const double ref[3], double dRef[3]) {
    constexpr int n = P + 1;
    double l[3][n], dl[3][n];
    for (int d = 0; d < 3; ++d) Lagrange1D<P, true>(ref[d], l[d], dl[d]);
    double f = 0, fr = 0, fs = 0, ft = 0;
    for (int k = 0; k < n; ++k) {
        double fk = 0, frk = 0, fsk = 0;
        for (int j = 0; j < n; ++j) {
            const double* row = u + n * (j + n * k);
            double fj = 0, frj = 0;
            for (int i = 0; i < n; ++i) {
                fj = std::fma(row[i], l[0][i], fj);
                frj = std::fma(row[i], dl[0][i], frj);
            }
            fk = std::fma(fj, l[1][j], fk);
            frk = std::fma(frj, l[1][j], frk);
            fsk = std::fma(fj, dl[1][j], fsk);
        }
        f = std::fma(fk, l[2][k], f);
        fr = std::fma(frk, l[2][k], fr);
        fs = std::fma(fsk, l[2][k], fs);
        ft = std::fma(fk, dl[2][k], ft);
    }
    dRef[0] = fr;
    dRef[1] = fs;
    dRef[2] = ft;
    return f;
}

template <int P, bool Jacobian>
void MapImpl(const double* xyz, const double ref[3], double world[3], double* jacobian) {
    constexpr int n = P + 1, m = 3 * n;
    double l[3][n], dl[3][n];
    for (int d = 0; d < 3; ++d) Lagrange1D<P, Jacobian>(ref[d], l[d], dl[d]);
    double r[m] = {}, rs[m] = {}, rt[m] = {};
    for (int k = 0; k < n; ++k)
        for (int j = 0; j < n; ++j) {
            const double* row = xyz + m * (j + n * k);
            const double w = l[1][j] * l[2][k];
            for (int q = 0; q < m; ++q) r[q] = std::fma(w, row[q], r[q]);
            if constexpr (Jacobian) {
                const double ws = dl[1][j] * l[2][k], wt = l[1][j] * dl[2][k];
                for (int q = 0; q < m; ++q) {
                    rs[q] = std::fma(ws, row[q], rs[q]);
                    rt[q] = std::fma(wt, row[q], rt[q]);
                }
            }
        }
    double x[3] = {0, 0, 0}, dr[3] = {0, 0, 0}, ds[3] = {0, 0, 0}, dt[3] = {0, 0, 0};
    for (int i = 0; i < n; ++i)
        for (int c = 0; c < 3; ++c) {
            x[c] = std::fma(r[3 * i + c], l[0][i], x[c]);
            if constexpr (Jacobian) {
                dr[c] = std::fma(r[3 * i + c], dl[0][i], dr[c]);
                ds[c] = std::fma(rs[3 * i + c], l[0][i], ds[c]);
                dt[c] = std::fma(rt[3 * i + c], l[0][i], dt[c]);
            }
        }
    for (int c = 0; c < 3; ++c) world[c] = x[c];
    if constexpr (Jacobian) {
        for (int c = 0; c < 3; ++c) {
            jacobian[3 * c] = dr[c];
            jacobian[3 * c + 1] = ds[c];
            jacobian[3 * c + 2] = dt[c];
        }
    }
}

// MapImpl<1, true> written out: the trilinear map of most reduced curved cells, where the
// loops above (two rows of six coordinates in s and t, then two nodes in r) do not unroll
// well. The same operations in the same order: l = (1 - x, x), dl = (-1, 1) exactly as
// Lagrange1D<1, true> gives them, each sum started from zero by an fma as in MapImpl.
template <>
void MapImpl<1, true>(const double* xyz, const double ref[3], double world[3],
                      double* jacobian) {
    const double l0[2] = {1.0 - ref[0], ref[0]}, l1[2] = {1.0 - ref[1], ref[1]},
                 l2[2] = {1.0 - ref[2], ref[2]};
    // d l / dx = (-1, 1): dl[0] = 0 * (1 - x) - 1 and dl[1] = 1 - x * 0 in Lagrange1D.
    double r[6], rs[6], rt[6];
    for (int q = 0; q < 6; ++q) {
        const double a = xyz[q], b = xyz[6 + q], c = xyz[12 + q], d = xyz[18 + q];
        // Rows (j, k) = (0, 0), (1, 0), (0, 1), (1, 1) with weights l1[j] l2[k],
        // ds: dl1[j] l2[k] = -l2[k], +l2[k], dt: l1[j] dl2[k] = -l1[j] for k = 0, +l1[j]
        // for k = 1 (products with -1 and 1 are exact).
        double v = std::fma(l1[0] * l2[0], a, 0.0);
        v = std::fma(l1[1] * l2[0], b, v);
        v = std::fma(l1[0] * l2[1], c, v);
        r[q] = std::fma(l1[1] * l2[1], d, v);
        double vs = std::fma(-l2[0], a, 0.0);
        vs = std::fma(l2[0], b, vs);
        vs = std::fma(-l2[1], c, vs);
        rs[q] = std::fma(l2[1], d, vs);
        double vt = std::fma(-l1[0], a, 0.0);
        vt = std::fma(-l1[1], b, vt);
        vt = std::fma(l1[0], c, vt);
        rt[q] = std::fma(l1[1], d, vt);
    }
    for (int c = 0; c < 3; ++c) {
        world[c] = std::fma(r[3 + c], l0[1], std::fma(r[c], l0[0], 0.0));
        jacobian[3 * c] = std::fma(r[3 + c], 1.0, std::fma(r[c], -1.0, 0.0));
        jacobian[3 * c + 1] = std::fma(rs[3 + c], l0[1], std::fma(rs[c], l0[0], 0.0));
        jacobian[3 * c + 2] = std::fma(rt[3 + c], l0[1], std::fma(rt[c], l0[0], 0.0));
    }
}

template <int P>
void Map(const double* xyz, const double ref[3], double world[3], double* jacobian) {
    if (jacobian)
        MapImpl<P, true>(xyz, ref, world, jacobian);
    else
        MapImpl<P, false>(xyz, ref, world, nullptr);
}

template <int P>
constexpr HexKernels Make() {
    return {P, &Value<P>, &ValueGradient<P>, &Map<P>};
}

constexpr HexKernels kTable[kMaxOrder + 1] = {
    HexKernels{}, Make<1>(), Make<2>(), Make<3>(), Make<4>(), Make<5>(),
    Make<6>(),    Make<7>(), Make<8>(), Make<9>(), Make<10>()};

}  // namespace

const HexKernels& HexKernelsFor(int p) {
    HPRAY_CHECK(p >= 1 && p <= kMaxOrder);
    return kTable[p];
}

}  // namespace hpray
