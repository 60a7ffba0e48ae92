// Sum-factorised hexahedron field evaluation (see tensor_eval.h).
#include "elements/tensor_eval.h"

#include <algorithm>
#include <cmath>

#include "mesh/cell.h"

namespace hpray {

namespace {
// 1 / (m + 1): the Silvester factors divide by these; a table keeps divisions out of the
// innermost loops.
constexpr double kInverse[kMaxOrder + 1] = {1.0,       1.0 / 2, 1.0 / 3, 1.0 / 4,
                                            1.0 / 5,   1.0 / 6, 1.0 / 7, 1.0 / 8,
                                            1.0 / 9,   1.0 / 10, 1.0 / 11};
}  // namespace

void LagrangeEquispaced1D(int p, double x, double* l, double* dl) {
    // Silvester factors s_m(x) = prod_{q<m} (p x - q)/(q + 1) of x and of 1 - x:
    // l_i(x) = s_i(x) s_{p-i}(1 - x).
    double a[kMaxOrder + 1], b[kMaxOrder + 1];
    const double px = p * x, py = p * (1.0 - x);
    a[0] = b[0] = 1;
    if (!dl) {
        for (int m = 0; m < p; ++m) {
            a[m + 1] = a[m] * ((px - m) * kInverse[m]);
            b[m + 1] = b[m] * ((py - m) * kInverse[m]);
        }
        for (int i = 0; i <= p; ++i) l[i] = a[i] * b[p - i];
        return;
    }
    double da[kMaxOrder + 1], db[kMaxOrder + 1];
    da[0] = db[0] = 0;
    for (int m = 0; m < p; ++m) {
        const double fa = (px - m) * kInverse[m], fb = (py - m) * kInverse[m];
        da[m + 1] = da[m] * fa + a[m] * (p * kInverse[m]);
        db[m + 1] = db[m] * fb + b[m] * (p * kInverse[m]);
        a[m + 1] = a[m] * fa;
        b[m + 1] = b[m] * fb;
    }
    for (int i = 0; i <= p; ++i) {
        l[i] = a[i] * b[p - i];
        dl[i] = da[i] * b[p - i] - a[i] * db[p - i];
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
            for (int i = 0; i < n; ++i) fj = std::fma(row[i], l[0][i], fj);
            fk = std::fma(fj, l[1][j], fk);
        }
        f = std::fma(fk, l[2][k], f);
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

void HexMapValueJacobian(int p, const double* xyz, const double ref[3], double world[3],
                         double* jacobian) {
    double l[3][kMaxOrder + 1], dl[3][kMaxOrder + 1];
    for (int d = 0; d < 3; ++d) LagrangeEquispaced1D(p, ref[d], l[d], jacobian ? dl[d] : nullptr);
    const int n = p + 1, m = 3 * n;
    // The rows along r (3 n contiguous coordinates each) summed with their weights in s
    // and t first: one contiguous multiply-add per coordinate and row (what vectorises),
    // then the r direction once on the three sums.
    double r[3 * (kMaxOrder + 1)] = {}, rs[3 * (kMaxOrder + 1)] = {},
                              rt[3 * (kMaxOrder + 1)] = {};
    for (int k = 0; k < n; ++k)
        for (int j = 0; j < n; ++j) {
            const double* row = xyz + m * (j + n * k);
            const double w = l[1][j] * l[2][k];
            for (int q = 0; q < m; ++q) r[q] = std::fma(w, row[q], r[q]);
            if (jacobian) {
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
            if (jacobian) {
                dr[c] = std::fma(r[3 * i + c], dl[0][i], dr[c]);
                ds[c] = std::fma(rs[3 * i + c], l[0][i], ds[c]);
                dt[c] = std::fma(rt[3 * i + c], l[0][i], dt[c]);
            }
        }
    for (int c = 0; c < 3; ++c) world[c] = x[c];
    if (!jacobian) return;
    for (int c = 0; c < 3; ++c) {
        jacobian[3 * c] = dr[c];
        jacobian[3 * c + 1] = ds[c];
        jacobian[3 * c + 2] = dt[c];
    }
}

namespace {

// The contractions of HexFieldValuesAlongLine for N = p + 1 nodes per direction and S
// samples (a multiple of 4), with sizes known at compile time so that the per-row sums over
// samples stay in vector registers.
template <int N, int S>
void ContractLine(const double* u, const double* L0, const double* L1, const double* L2,
                  double* out) {
    double f[S] = {};
    for (int k = 0; k < N; ++k) {
        double fk[S] = {};
        for (int j = 0; j < N; ++j) {
            const double* row = u + N * (j + N * k);
            double fj[S] = {};
            for (int i = 0; i < N; ++i) {
                const double c = row[i];
                const double* l0 = L0 + i * S;
                for (int s = 0; s < S; ++s) fj[s] = std::fma(c, l0[s], fj[s]);
            }
            const double* l1 = L1 + j * S;
            for (int s = 0; s < S; ++s) fk[s] = std::fma(fj[s], l1[s], fk[s]);
        }
        const double* l2 = L2 + k * S;
        for (int s = 0; s < S; ++s) f[s] = std::fma(fk[s], l2[s], f[s]);
    }
    for (int s = 0; s < S; ++s) out[s] = f[s];
}

void ContractLineGeneric(int n, int S, const double* u, const double* L0, const double* L1,
                         const double* L2, double* out, double* fj, double* fk) {
    for (int s = 0; s < S; ++s) out[s] = 0;
    for (int k = 0; k < n; ++k) {
        for (int s = 0; s < S; ++s) fk[s] = 0;
        for (int j = 0; j < n; ++j) {
            const double* row = u + n * (j + n * k);
            for (int s = 0; s < S; ++s) fj[s] = 0;
            for (int i = 0; i < n; ++i) {
                const double c = row[i];
                const double* l0 = L0 + i * S;
                for (int s = 0; s < S; ++s) fj[s] = std::fma(c, l0[s], fj[s]);
            }
            const double* l1 = L1 + j * S;
            for (int s = 0; s < S; ++s) fk[s] = std::fma(fj[s], l1[s], fk[s]);
        }
        const double* l2 = L2 + k * S;
        for (int s = 0; s < S; ++s) out[s] = std::fma(fk[s], l2[s], out[s]);
    }
}

// Compile-time kernels for the exact projections (3p + 1 samples, padded to a multiple
// of 4) of every order.
using Kernel = void (*)(const double*, const double*, const double*, const double*, double*);
template <int P>
constexpr Kernel ExactKernel() {
    return &ContractLine<P + 1, ((3 * P + 1) + 3) / 4 * 4>;
}
constexpr Kernel kExactKernels[kMaxOrder + 1] = {
    nullptr,          ExactKernel<1>(), ExactKernel<2>(), ExactKernel<3>(),
    ExactKernel<4>(), ExactKernel<5>(), ExactKernel<6>(), ExactKernel<7>(),
    ExactKernel<8>(), ExactKernel<9>(), ExactKernel<10>()};

}  // namespace

namespace {

// Row i of L holds the 1-D Lagrange polynomial l_i at each sample's coordinate x[s]
// (sample-fastest, i * padded + s), built from the Silvester factors for all samples at
// once (vectorised over s): L(i, s) = A_i(s) B_{p-i}(s), B built in place, A in a rolling
// row `a`.
[[gnu::always_inline]] inline void LagrangeRows(int p, const double* x, int padded,
                                                double* L, double* a) {
    for (int s = 0; s < padded; ++s) L[s] = 1;
    for (int m = 0; m < p; ++m) {
        const double inv = kInverse[m];
        const double* prev = L + m * padded;
        double* next = L + (m + 1) * padded;
        for (int s = 0; s < padded; ++s) next[s] = prev[s] * ((p * (1 - x[s]) - m) * inv);
    }
    // Reverse the rows so row i holds B_{p-i}, then multiply by A_i row by row.
    for (int i = 0; i < (p + 1) / 2; ++i)
        for (int s = 0; s < padded; ++s) std::swap(L[i * padded + s], L[(p - i) * padded + s]);
    for (int s = 0; s < padded; ++s) a[s] = 1;
    for (int i = 0; i <= p; ++i) {
        double* row = L + i * padded;
        for (int s = 0; s < padded; ++s) row[s] *= a[s];
        if (i < p) {
            const double inv = kInverse[i];
            for (int s = 0; s < padded; ++s) a[s] *= (p * x[s] - i) * inv;
        }
    }
}

// LagrangeRows with the order and the padded count known at compile time (the same
// operations: bitwise the same rows), for the counts of the adaptive projections.
template <int P, int S>
void LagrangeRowsFixed(const double* __restrict x, double* __restrict L, double* /*a*/) {
    // The B factors kept in registers instead of built in L and reversed in place; every
    // product is the one LagrangeRows forms.
    double b[P + 1][S], a[S];
    for (int s = 0; s < S; ++s) b[0][s] = a[s] = 1;
    for (int m = 0; m < P; ++m)
        for (int s = 0; s < S; ++s)
            b[m + 1][s] = b[m][s] * ((P * (1 - x[s]) - m) * kInverse[m]);
    for (int i = 0; i <= P; ++i) {
        for (int s = 0; s < S; ++s) L[i * S + s] = b[P - i][s] * a[s];
        if (i < P)
            for (int s = 0; s < S; ++s) a[s] *= (P * x[s] - i) * kInverse[i];
    }
}
using RowsKernel = void (*)(const double*, double*, double*);
template <int S>
constexpr RowsKernel kRows[kMaxOrder + 1] = {nullptr,
                                             &LagrangeRowsFixed<1, S>,
                                             &LagrangeRowsFixed<2, S>,
                                             &LagrangeRowsFixed<3, S>,
                                             &LagrangeRowsFixed<4, S>,
                                             &LagrangeRowsFixed<5, S>,
                                             &LagrangeRowsFixed<6, S>,
                                             &LagrangeRowsFixed<7, S>,
                                             &LagrangeRowsFixed<8, S>,
                                             &LagrangeRowsFixed<9, S>,
                                             &LagrangeRowsFixed<10, S>};
constexpr RowsKernel SmallRows(int p, int padded) {
    return padded == 4    ? kRows<4>[p]
           : padded == 8  ? kRows<8>[p]
           : padded == 12 ? kRows<12>[p]
           : padded == 16 ? kRows<16>[p]
                          : nullptr;
}

// Compile-time kernels for small padded sample counts (the adaptive projections of curved
// cells sample 9 or 17 points, and their checks a few).
constexpr Kernel SmallKernel(int p, int padded) {
    constexpr Kernel k4[kMaxOrder + 1] = {nullptr,           &ContractLine<2, 4>,
                                          &ContractLine<3, 4>, &ContractLine<4, 4>,
                                          &ContractLine<5, 4>, &ContractLine<6, 4>,
                                          &ContractLine<7, 4>, &ContractLine<8, 4>,
                                          &ContractLine<9, 4>, &ContractLine<10, 4>,
                                          &ContractLine<11, 4>};
    constexpr Kernel k8[kMaxOrder + 1] = {nullptr,           &ContractLine<2, 8>,
                                          &ContractLine<3, 8>, &ContractLine<4, 8>,
                                          &ContractLine<5, 8>, &ContractLine<6, 8>,
                                          &ContractLine<7, 8>, &ContractLine<8, 8>,
                                          &ContractLine<9, 8>, &ContractLine<10, 8>,
                                          &ContractLine<11, 8>};
    constexpr Kernel k12[kMaxOrder + 1] = {nullptr,            &ContractLine<2, 12>,
                                           &ContractLine<3, 12>, &ContractLine<4, 12>,
                                           &ContractLine<5, 12>, &ContractLine<6, 12>,
                                           &ContractLine<7, 12>, &ContractLine<8, 12>,
                                           &ContractLine<9, 12>, &ContractLine<10, 12>,
                                           &ContractLine<11, 12>};
    return padded == 4 ? k4[p] : padded == 8 ? k8[p] : padded == 12 ? k12[p] : nullptr;
}

// f at the samples whose coordinates are in xs[d * padded + s] (padding repeats the last).
void ContractSamples(int p, const double* u, const double* xs, int count, int padded,
                     double* out, double* scratch) {
    const int n = p + 1;
    double* L[3] = {scratch, scratch + n * padded, scratch + 2 * n * padded};
    double* result = scratch + 3 * n * padded;
    if (const RowsKernel rows = SmallRows(p, padded)) {
        for (int d = 0; d < 3; ++d) rows(xs + d * padded, L[d], result);
    } else {
        for (int d = 0; d < 3; ++d)
            LagrangeRows(p, xs + d * padded, padded, L[d], result);
    }
    if (count == 3 * p + 1) {
        kExactKernels[p](u, L[0], L[1], L[2], result);
    } else if (const Kernel k = SmallKernel(p, padded)) {
        k(u, L[0], L[1], L[2], result);
    } else {
        ContractLineGeneric(n, padded, u, L[0], L[1], L[2], result, result + padded,
                            result + 2 * padded);
    }
    for (int s = 0; s < count; ++s) out[s] = result[s];
}

}  // namespace

void HexFieldValuesAlongLine(int p, const double* u, const double ref0[3],
                             const double dref[3], const double* t, int count, double* out,
                             double* scratch) {
    const int padded = (count + 3) / 4 * 4;
    double* xs = scratch + HexLineScratchSize(p, count) - 3 * padded;
    for (int d = 0; d < 3; ++d)
        for (int s = 0; s < padded; ++s)
            xs[d * padded + s] = ref0[d] + t[std::min(s, count - 1)] * dref[d];
    ContractSamples(p, u, xs, count, padded, out, scratch);
}

void HexFieldValuesAt(int p, const double* u, const double* refs, int count, double* out,
                      double* scratch) {
    const int padded = (count + 3) / 4 * 4;
    double* xs = scratch + HexLineScratchSize(p, count) - 3 * padded;
    for (int d = 0; d < 3; ++d)
        for (int s = 0; s < padded; ++s) xs[d * padded + s] = refs[3 * std::min(s, count - 1) + d];
    ContractSamples(p, u, xs, count, padded, out, scratch);
}

namespace {
// out[(a + m (b + m c)) comps + d] = sum_ijk in[(i + n (j + n k)) comps + d] A[a][i]
// A[b][j] A[c][k] for an m x n matrix A (row-major): the three one-dimensional passes of
// sum factorisation, m n^3 + m^2 n^2 + m^3 n products per component instead of m^3 n^3.
void TensorApply(int n, int m, int comps, const double* A, const double* in,
                 double* out) {
    std::vector<double> t1(std::size_t(m) * n * n * comps),
        t2(std::size_t(m) * m * n * comps);
    // Along the first axis: t1[(a + m (j + n k)) comps + d].
    for (int jk = 0; jk < n * n; ++jk)
        for (int a = 0; a < m; ++a)
            for (int d = 0; d < comps; ++d) {
                double s = 0;
                for (int i = 0; i < n; ++i)
                    s += A[a * n + i] *
                         in[(std::size_t(i) + std::size_t(n) * jk) * comps + d];
                t1[(std::size_t(a) + std::size_t(m) * jk) * comps + d] = s;
            }
    // Along the second: t2[(a + m (b + m k)) comps + d].
    for (int k = 0; k < n; ++k)
        for (int b = 0; b < m; ++b)
            for (int a = 0; a < m; ++a)
                for (int d = 0; d < comps; ++d) {
                    double s = 0;
                    for (int j = 0; j < n; ++j)
                        s += A[b * n + j] *
                             t1[(std::size_t(a) +
                                 std::size_t(m) * (j + std::size_t(n) * k)) *
                                    comps +
                                d];
                    t2[(std::size_t(a) + std::size_t(m) * (b + std::size_t(m) * k)) *
                           comps +
                       d] = s;
                }
    // Along the third.
    for (int c = 0; c < m; ++c)
        for (int ab = 0; ab < m * m; ++ab)
            for (int d = 0; d < comps; ++d) {
                double s = 0;
                for (int k = 0; k < n; ++k)
                    s += A[c * n + k] *
                         t2[(std::size_t(ab) + std::size_t(m) * m * k) * comps + d];
                out[(std::size_t(ab) + std::size_t(m) * m * c) * comps + d] = s;
            }
}

// The m x n matrix of the order-(n - 1) equispaced Lagrange basis at the order-(m - 1)
// lattice points: A[a][i] = l_i(a / (m - 1)).
std::vector<double> LatticeMatrix(int n, int m) {
    std::vector<double> A(std::size_t(m) * n);
    for (int a = 0; a < m; ++a)
        LagrangeEquispaced1D(n - 1, m == 1 ? 0.0 : double(a) / (m - 1),
                             &A[std::size_t(a) * n], nullptr);
    return A;
}
}  // namespace

void HexResample(int p, int components, const double* values, int q, std::vector<double>& out) {
    const int n = p + 1, m = q + 1;
    out.resize(std::size_t(m) * m * m * components);
    TensorApply(n, m, components, LatticeMatrix(n, m).data(), values, out.data());
}

void HexReductionDeviation(int p, int components, const double* values, int q,
                           const double* reduced, std::vector<double>& deviation) {
    const int n = p + 1, m = q + 1;
    deviation.resize(std::size_t(n) * n * n * components);
    TensorApply(m, n, components, LatticeMatrix(m, n).data(), reduced, deviation.data());
    for (std::size_t v = 0; v < deviation.size(); ++v) deviation[v] -= values[v];
}

}  // namespace hpray
