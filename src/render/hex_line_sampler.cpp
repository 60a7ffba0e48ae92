// Register-blocked sampling of a Lagrange hexahedron along a line (see hex_line_sampler.h).
#include "render/hex_line_sampler.h"

#include <algorithm>
#include <cmath>

#include "util/lanes.h"

#if defined(__AVX2__) && defined(__FMA__)
#include <immintrin.h>
#define HPRAY_HEX_LINE_KERNEL 1
// The block kernel also in an AVX-512 version, chosen at run time where the processor has
// it (the build itself leaves AVX-512 out; see CMakeLists.txt).
#if defined(__GNUC__) && defined(__x86_64__)
#define HPRAY_HEX_LINE_KERNEL_512 1
#else
#define HPRAY_HEX_LINE_KERNEL_512 0
#endif
#else
#define HPRAY_HEX_LINE_KERNEL 0
#endif

namespace hpray {

#if HPRAY_HEX_LINE_KERNEL
namespace {

/// Rows of the equispaced Lagrange polynomials of degree P on [0, 1] at x[s]:
/// L[i * S + s] = l_i(x[s]) = A_i(x) B_{P-i}(x) with the Silvester factors
/// A_i = prod_{m<i} (r - m) / (m + 1), r = P x, and B_j = prod_{m<j} (q - m) / (m + 1),
/// q = P (1 - x): four lanes at a time, the factors in registers (one fused multiply-add
/// each), every row stored once. S is a multiple of 4.
template <int P>
void LagrangeRows(const double* x, int S, double* L) {
    for (int s = 0; s < S; s += 4) {
        const __m256d xv = _mm256_loadu_pd(x + s);
        const __m256d q = _mm256_mul_pd(_mm256_set1_pd(P),
                                        _mm256_sub_pd(_mm256_set1_pd(1.0), xv));
        const __m256d r = _mm256_mul_pd(_mm256_set1_pd(P), xv);
        __m256d B[P + 1];
        B[0] = _mm256_set1_pd(1.0);
        for (int m = 0; m < P; ++m) {
            const double inv = 1.0 / (m + 1);
            B[m + 1] = _mm256_mul_pd(
                B[m], _mm256_fmadd_pd(q, _mm256_set1_pd(inv), _mm256_set1_pd(-m * inv)));
        }
        __m256d A = _mm256_set1_pd(1.0);
        for (int i = 0; i <= P; ++i) {
            _mm256_storeu_pd(L + i * S + s, _mm256_mul_pd(A, B[P - i]));
            if (i < P) {
                const double inv = 1.0 / (i + 1);
                A = _mm256_mul_pd(
                    A, _mm256_fmadd_pd(r, _mm256_set1_pd(inv), _mm256_set1_pd(-i * inv)));
            }
        }
    }
}

#if HPRAY_HEX_LINE_KERNEL_512
/// LagrangeRows on AVX-512, eight lanes at a time, the same operations per lane (bitwise
/// the same rows); S is a multiple of 8. Written out again rather than shared: a
/// function of the build's own instruction set cannot hold the wider intrinsics, and
/// only these functions carry the AVX-512 target.
template <int P>
__attribute__((target("avx512f"))) void LagrangeRows512(const double* x, int S,
                                                        double* L) {
    for (int s = 0; s < S; s += 8) {
        const __m512d xv = _mm512_loadu_pd(x + s);
        const __m512d q =
            _mm512_mul_pd(_mm512_set1_pd(P), _mm512_sub_pd(_mm512_set1_pd(1.0), xv));
        const __m512d r = _mm512_mul_pd(_mm512_set1_pd(P), xv);
        __m512d B[P + 1];
        B[0] = _mm512_set1_pd(1.0);
        for (int m = 0; m < P; ++m) {
            const double inv = 1.0 / (m + 1);
            B[m + 1] = _mm512_mul_pd(
                B[m], _mm512_fmadd_pd(q, _mm512_set1_pd(inv), _mm512_set1_pd(-m * inv)));
        }
        __m512d A = _mm512_set1_pd(1.0);
        for (int i = 0; i <= P; ++i) {
            _mm512_storeu_pd(L + i * S + s, _mm512_mul_pd(A, B[P - i]));
            if (i < P) {
                const double inv = 1.0 / (i + 1);
                A = _mm512_mul_pd(
                    A, _mm512_fmadd_pd(r, _mm512_set1_pd(inv), _mm512_set1_pd(-i * inv)));
            }
        }
    }
}
#endif

/// out[s] = sum_k L2[k][s] sum_j L1[j][s] sum_i u[i + N (j + N k)] L0[i][s] for s < count
/// (a multiple of 4; L rows have stride S). The first contraction, which holds almost all
/// the work, is a small matrix product: tiles of 4 rows of u times 3 vectors of samples
/// (12 accumulators, the 3 sample vectors and a broadcast fill the 16 registers), then
/// a tail block of one vector.
template <int N>
void Contract(const double* u, const double* L0, const double* L1, const double* L2,
              int count, int S, double* out) {
    int b = 0;
    for (; b + 12 <= count; b += 12) {
        __m256d o0 = _mm256_setzero_pd(), o1 = o0, o2 = o0;
        for (int k = 0; k < N; ++k) {
            __m256d g0 = _mm256_setzero_pd(), g1 = g0, g2 = g0;
            int j = 0;
            for (; j + 4 <= N; j += 4) {
                const double* r = u + N * (j + N * k);
                __m256d a00 = _mm256_setzero_pd(), a01 = a00, a02 = a00, a10 = a00,
                        a11 = a00, a12 = a00, a20 = a00, a21 = a00, a22 = a00, a30 = a00,
                        a31 = a00, a32 = a00;
                for (int i = 0; i < N; ++i) {
                    const double* l = L0 + i * S + b;
                    const __m256d l0 = _mm256_loadu_pd(l), l1 = _mm256_loadu_pd(l + 4),
                                  l2 = _mm256_loadu_pd(l + 8);
                    __m256d c = _mm256_broadcast_sd(r + i);
                    a00 = _mm256_fmadd_pd(c, l0, a00);
                    a01 = _mm256_fmadd_pd(c, l1, a01);
                    a02 = _mm256_fmadd_pd(c, l2, a02);
                    c = _mm256_broadcast_sd(r + N + i);
                    a10 = _mm256_fmadd_pd(c, l0, a10);
                    a11 = _mm256_fmadd_pd(c, l1, a11);
                    a12 = _mm256_fmadd_pd(c, l2, a12);
                    c = _mm256_broadcast_sd(r + 2 * N + i);
                    a20 = _mm256_fmadd_pd(c, l0, a20);
                    a21 = _mm256_fmadd_pd(c, l1, a21);
                    a22 = _mm256_fmadd_pd(c, l2, a22);
                    c = _mm256_broadcast_sd(r + 3 * N + i);
                    a30 = _mm256_fmadd_pd(c, l0, a30);
                    a31 = _mm256_fmadd_pd(c, l1, a31);
                    a32 = _mm256_fmadd_pd(c, l2, a32);
                }
                const double* m = L1 + j * S + b;
                g0 = _mm256_fmadd_pd(a00, _mm256_loadu_pd(m), g0);
                g1 = _mm256_fmadd_pd(a01, _mm256_loadu_pd(m + 4), g1);
                g2 = _mm256_fmadd_pd(a02, _mm256_loadu_pd(m + 8), g2);
                m += S;
                g0 = _mm256_fmadd_pd(a10, _mm256_loadu_pd(m), g0);
                g1 = _mm256_fmadd_pd(a11, _mm256_loadu_pd(m + 4), g1);
                g2 = _mm256_fmadd_pd(a12, _mm256_loadu_pd(m + 8), g2);
                m += S;
                g0 = _mm256_fmadd_pd(a20, _mm256_loadu_pd(m), g0);
                g1 = _mm256_fmadd_pd(a21, _mm256_loadu_pd(m + 4), g1);
                g2 = _mm256_fmadd_pd(a22, _mm256_loadu_pd(m + 8), g2);
                m += S;
                g0 = _mm256_fmadd_pd(a30, _mm256_loadu_pd(m), g0);
                g1 = _mm256_fmadd_pd(a31, _mm256_loadu_pd(m + 4), g1);
                g2 = _mm256_fmadd_pd(a32, _mm256_loadu_pd(m + 8), g2);
            }
            for (; j < N; ++j) {
                const double* r = u + N * (j + N * k);
                __m256d a0 = _mm256_setzero_pd(), a1 = a0, a2 = a0;
                for (int i = 0; i < N; ++i) {
                    const double* l = L0 + i * S + b;
                    const __m256d c = _mm256_broadcast_sd(r + i);
                    a0 = _mm256_fmadd_pd(c, _mm256_loadu_pd(l), a0);
                    a1 = _mm256_fmadd_pd(c, _mm256_loadu_pd(l + 4), a1);
                    a2 = _mm256_fmadd_pd(c, _mm256_loadu_pd(l + 8), a2);
                }
                const double* m = L1 + j * S + b;
                g0 = _mm256_fmadd_pd(a0, _mm256_loadu_pd(m), g0);
                g1 = _mm256_fmadd_pd(a1, _mm256_loadu_pd(m + 4), g1);
                g2 = _mm256_fmadd_pd(a2, _mm256_loadu_pd(m + 8), g2);
            }
            const double* n = L2 + k * S + b;
            o0 = _mm256_fmadd_pd(g0, _mm256_loadu_pd(n), o0);
            o1 = _mm256_fmadd_pd(g1, _mm256_loadu_pd(n + 4), o1);
            o2 = _mm256_fmadd_pd(g2, _mm256_loadu_pd(n + 8), o2);
        }
        _mm256_storeu_pd(out + b, o0);
        _mm256_storeu_pd(out + b + 4, o1);
        _mm256_storeu_pd(out + b + 8, o2);
    }
    for (; b < count; b += 4) {
        __m256d o = _mm256_setzero_pd();
        for (int k = 0; k < N; ++k) {
            __m256d g = _mm256_setzero_pd();
            int j = 0;
            for (; j + 4 <= N; j += 4) {
                const double* r = u + N * (j + N * k);
                __m256d a0 = _mm256_setzero_pd(), a1 = a0, a2 = a0, a3 = a0;
                for (int i = 0; i < N; ++i) {
                    const __m256d l = _mm256_loadu_pd(L0 + i * S + b);
                    a0 = _mm256_fmadd_pd(_mm256_broadcast_sd(r + i), l, a0);
                    a1 = _mm256_fmadd_pd(_mm256_broadcast_sd(r + N + i), l, a1);
                    a2 = _mm256_fmadd_pd(_mm256_broadcast_sd(r + 2 * N + i), l, a2);
                    a3 = _mm256_fmadd_pd(_mm256_broadcast_sd(r + 3 * N + i), l, a3);
                }
                const double* m = L1 + j * S + b;
                g = _mm256_fmadd_pd(a0, _mm256_loadu_pd(m), g);
                g = _mm256_fmadd_pd(a1, _mm256_loadu_pd(m + S), g);
                g = _mm256_fmadd_pd(a2, _mm256_loadu_pd(m + 2 * S), g);
                g = _mm256_fmadd_pd(a3, _mm256_loadu_pd(m + 3 * S), g);
            }
            for (; j < N; ++j) {
                const double* r = u + N * (j + N * k);
                __m256d a0 = _mm256_setzero_pd();
                for (int i = 0; i < N; ++i)
                    a0 = _mm256_fmadd_pd(_mm256_broadcast_sd(r + i),
                                         _mm256_loadu_pd(L0 + i * S + b), a0);
                g = _mm256_fmadd_pd(a0, _mm256_loadu_pd(L1 + j * S + b), g);
            }
            o = _mm256_fmadd_pd(g, _mm256_loadu_pd(L2 + k * S + b), o);
        }
        _mm256_storeu_pd(out + b, o);
    }
}

#if HPRAY_HEX_LINE_KERNEL_512
/// Contract on AVX-512 for one block of 8 V samples (V vectors of eight) with the same
/// register tile (4 rows of u times the V vectors), so that every sample sees the same
/// fused multiply-adds in the same order as in Contract (bitwise the same results), at
/// twice the width.
template <int N, int V>
__attribute__((target("avx512f"))) inline void ContractBlock512(const double* u,
                                                                const double* L0,
                                                                const double* L1,
                                                                const double* L2, int S,
                                                                double* out) {
    __m512d o[V], g[V], a[4][V], l[V];
#pragma GCC unroll 4
    for (int v = 0; v < V; ++v) o[v] = _mm512_setzero_pd();
    for (int k = 0; k < N; ++k) {
#pragma GCC unroll 4
        for (int v = 0; v < V; ++v) g[v] = _mm512_setzero_pd();
        int j = 0;
        for (; j + 4 <= N; j += 4) {
            const double* r = u + N * (j + N * k);
#pragma GCC unroll 4
            for (int q = 0; q < 4; ++q)
#pragma GCC unroll 4
                for (int v = 0; v < V; ++v) a[q][v] = _mm512_setzero_pd();
            for (int i = 0; i < N; ++i) {
#pragma GCC unroll 4
                for (int v = 0; v < V; ++v) l[v] = _mm512_loadu_pd(L0 + i * S + 8 * v);
#pragma GCC unroll 4
                for (int q = 0; q < 4; ++q) {
                    const __m512d c = _mm512_set1_pd(r[q * N + i]);
#pragma GCC unroll 4
                    for (int v = 0; v < V; ++v)
                        a[q][v] = _mm512_fmadd_pd(c, l[v], a[q][v]);
                }
            }
#pragma GCC unroll 4
            for (int q = 0; q < 4; ++q) {
                const double* m = L1 + (j + q) * S;
#pragma GCC unroll 4
                for (int v = 0; v < V; ++v)
                    g[v] = _mm512_fmadd_pd(a[q][v], _mm512_loadu_pd(m + 8 * v), g[v]);
            }
        }
        // The rest of j (none when N is a multiple of 4).
        for (; N % 4 != 0 && j < N; ++j) {
            const double* r = u + N * (j + N * k);
#pragma GCC unroll 4
            for (int v = 0; v < V; ++v) a[0][v] = _mm512_setzero_pd();
            for (int i = 0; i < N; ++i) {
                const __m512d c = _mm512_set1_pd(r[i]);
#pragma GCC unroll 4
                for (int v = 0; v < V; ++v)
                    a[0][v] =
                        _mm512_fmadd_pd(c, _mm512_loadu_pd(L0 + i * S + 8 * v), a[0][v]);
            }
            const double* m = L1 + j * S;
#pragma GCC unroll 4
            for (int v = 0; v < V; ++v)
                g[v] = _mm512_fmadd_pd(a[0][v], _mm512_loadu_pd(m + 8 * v), g[v]);
        }
        const double* n = L2 + k * S;
#pragma GCC unroll 4
        for (int v = 0; v < V; ++v)
            o[v] = _mm512_fmadd_pd(g[v], _mm512_loadu_pd(n + 8 * v), o[v]);
    }
#pragma GCC unroll 4
    for (int v = 0; v < V; ++v) _mm512_storeu_pd(out + 8 * v, o[v]);
}

/// ContractBlock512 for V = 3 written out as Contract's block of 12 is: the generic form's
/// loops leave the compiler holding rows of L1 across k, which spills (6% slower on
/// nk-sinc's volume).
template <int N>
__attribute__((target("avx512f"))) inline void ContractBlock24(const double* u,
                                                               const double* L0,
                                                               const double* L1,
                                                               const double* L2, int S,
                                                               double* out) {
    __m512d o0 = _mm512_setzero_pd(), o1 = o0, o2 = o0;
    for (int k = 0; k < N; ++k) {
        __m512d g0 = _mm512_setzero_pd(), g1 = g0, g2 = g0;
        int j = 0;
        for (; j + 4 <= N; j += 4) {
            const double* r = u + N * (j + N * k);
            __m512d a00 = _mm512_setzero_pd(), a01 = a00, a02 = a00, a10 = a00, a11 = a00,
                    a12 = a00, a20 = a00, a21 = a00, a22 = a00, a30 = a00, a31 = a00,
                    a32 = a00;
            for (int i = 0; i < N; ++i) {
                const double* l = L0 + i * S;
                const __m512d l0 = _mm512_loadu_pd(l), l1 = _mm512_loadu_pd(l + 8),
                              l2 = _mm512_loadu_pd(l + 16);
                __m512d c = _mm512_set1_pd(r[i]);
                a00 = _mm512_fmadd_pd(c, l0, a00);
                a01 = _mm512_fmadd_pd(c, l1, a01);
                a02 = _mm512_fmadd_pd(c, l2, a02);
                c = _mm512_set1_pd(r[N + i]);
                a10 = _mm512_fmadd_pd(c, l0, a10);
                a11 = _mm512_fmadd_pd(c, l1, a11);
                a12 = _mm512_fmadd_pd(c, l2, a12);
                c = _mm512_set1_pd(r[2 * N + i]);
                a20 = _mm512_fmadd_pd(c, l0, a20);
                a21 = _mm512_fmadd_pd(c, l1, a21);
                a22 = _mm512_fmadd_pd(c, l2, a22);
                c = _mm512_set1_pd(r[3 * N + i]);
                a30 = _mm512_fmadd_pd(c, l0, a30);
                a31 = _mm512_fmadd_pd(c, l1, a31);
                a32 = _mm512_fmadd_pd(c, l2, a32);
            }
            const double* m = L1 + j * S;
            g0 = _mm512_fmadd_pd(a00, _mm512_loadu_pd(m), g0);
            g1 = _mm512_fmadd_pd(a01, _mm512_loadu_pd(m + 8), g1);
            g2 = _mm512_fmadd_pd(a02, _mm512_loadu_pd(m + 16), g2);
            m += S;
            g0 = _mm512_fmadd_pd(a10, _mm512_loadu_pd(m), g0);
            g1 = _mm512_fmadd_pd(a11, _mm512_loadu_pd(m + 8), g1);
            g2 = _mm512_fmadd_pd(a12, _mm512_loadu_pd(m + 16), g2);
            m += S;
            g0 = _mm512_fmadd_pd(a20, _mm512_loadu_pd(m), g0);
            g1 = _mm512_fmadd_pd(a21, _mm512_loadu_pd(m + 8), g1);
            g2 = _mm512_fmadd_pd(a22, _mm512_loadu_pd(m + 16), g2);
            m += S;
            g0 = _mm512_fmadd_pd(a30, _mm512_loadu_pd(m), g0);
            g1 = _mm512_fmadd_pd(a31, _mm512_loadu_pd(m + 8), g1);
            g2 = _mm512_fmadd_pd(a32, _mm512_loadu_pd(m + 16), g2);
        }
        for (; j < N; ++j) {
            const double* r = u + N * (j + N * k);
            __m512d a0 = _mm512_setzero_pd(), a1 = a0, a2 = a0;
            for (int i = 0; i < N; ++i) {
                const double* l = L0 + i * S;
                const __m512d c = _mm512_set1_pd(r[i]);
                a0 = _mm512_fmadd_pd(c, _mm512_loadu_pd(l), a0);
                a1 = _mm512_fmadd_pd(c, _mm512_loadu_pd(l + 8), a1);
                a2 = _mm512_fmadd_pd(c, _mm512_loadu_pd(l + 16), a2);
            }
            const double* m = L1 + j * S;
            g0 = _mm512_fmadd_pd(a0, _mm512_loadu_pd(m), g0);
            g1 = _mm512_fmadd_pd(a1, _mm512_loadu_pd(m + 8), g1);
            g2 = _mm512_fmadd_pd(a2, _mm512_loadu_pd(m + 16), g2);
        }
        const double* n = L2 + k * S;
        o0 = _mm512_fmadd_pd(g0, _mm512_loadu_pd(n), o0);
        o1 = _mm512_fmadd_pd(g1, _mm512_loadu_pd(n + 8), o1);
        o2 = _mm512_fmadd_pd(g2, _mm512_loadu_pd(n + 16), o2);
    }
    _mm512_storeu_pd(out, o0);
    _mm512_storeu_pd(out + 8, o1);
    _mm512_storeu_pd(out + 16, o2);
}

/// Contract for count a multiple of 8: whole blocks of 24, then one of 16 or 8 samples.
template <int N>
__attribute__((target("avx512f"))) void Contract512(const double* u, const double* L0,
                                                    const double* L1, const double* L2,
                                                    int count, int S, double* out) {
    int b = 0;
    for (; b + 24 <= count; b += 24)
        ContractBlock24<N>(u, L0 + b, L1 + b, L2 + b, S, out + b);
    if (b + 16 <= count) {
        ContractBlock512<N, 2>(u, L0 + b, L1 + b, L2 + b, S, out + b);
        b += 16;
    } else if (b + 8 <= count) {
        ContractBlock512<N, 1>(u, L0 + b, L1 + b, L2 + b, S, out + b);
    }
}
#endif

/// The same for the one sample s (column s of the L rows): the first two contractions
/// swapped, G[i] = sum_jk u[i + N (j + N k)] L1[j] L2[k] vectorised over i, then
/// sum_i G[i] L0[i]. A few hundred cycles where a block of four lanes for one sample costs
/// as much as four.
template <int N>
double ContractOne(const double* u, const double* L0, const double* L1, const double* L2,
                   int S, int s) {
    constexpr int V = N / 4;  // whole vectors of i; the rest scalar
    __m256d g[V > 0 ? V : 1];
    for (int v = 0; v < V; ++v) g[v] = _mm256_setzero_pd();
    double rest[4] = {0, 0, 0, 0};
    for (int k = 0; k < N; ++k) {
        const double l2 = L2[k * S + s];
        for (int j = 0; j < N; ++j) {
            const double w = L1[j * S + s] * l2;
            const double* row = u + N * (j + N * k);
            const __m256d wv = _mm256_set1_pd(w);
            for (int v = 0; v < V; ++v)
                g[v] = _mm256_fmadd_pd(_mm256_loadu_pd(row + 4 * v), wv, g[v]);
            for (int i = 4 * V; i < N; ++i) rest[i - 4 * V] = std::fma(row[i], w, rest[i - 4 * V]);
        }
    }
    alignas(32) double gi[4 * (V > 0 ? V : 1)];
    for (int v = 0; v < V; ++v) _mm256_store_pd(gi + 4 * v, g[v]);
    double f = 0;
    for (int i = 0; i < 4 * V; ++i) f = std::fma(gi[i], L0[i * S + s], f);
    for (int i = 4 * V; i < N; ++i) f = std::fma(rest[i - 4 * V], L0[i * S + s], f);
    return f;
}

using Kernel = void (*)(const double*, const double*, const double*, const double*, int, int,
                        double*);
using OneKernel = double (*)(const double*, const double*, const double*, const double*, int,
                             int);
constexpr int kMaxKernelOrder = 10;
using RowsKernel = void (*)(const double*, int, double*);
constexpr RowsKernel kRows[kMaxKernelOrder + 1] = {
    nullptr,          &LagrangeRows<1>, &LagrangeRows<2>, &LagrangeRows<3>,
    &LagrangeRows<4>, &LagrangeRows<5>, &LagrangeRows<6>, &LagrangeRows<7>,
    &LagrangeRows<8>, &LagrangeRows<9>, &LagrangeRows<10>};
constexpr Kernel kKernels[kMaxKernelOrder + 1] = {
    nullptr,      &Contract<2>, &Contract<3>, &Contract<4>, &Contract<5>,  &Contract<6>,
    &Contract<7>, &Contract<8>, &Contract<9>, &Contract<10>, &Contract<11>};
constexpr OneKernel kOneKernels[kMaxKernelOrder + 1] = {
    nullptr,         &ContractOne<2>, &ContractOne<3>, &ContractOne<4>,
    &ContractOne<5>, &ContractOne<6>, &ContractOne<7>, &ContractOne<8>,
    &ContractOne<9>, &ContractOne<10>, &ContractOne<11>};

#if HPRAY_HEX_LINE_KERNEL_512
using Kernel512 = void (*)(const double*, const double*, const double*, const double*,
                           int, int, double*);
using RowsKernel512 = void (*)(const double*, int, double*);
constexpr RowsKernel512 kRows512[kMaxKernelOrder + 1] = {nullptr,
                                                         &LagrangeRows512<1>,
                                                         &LagrangeRows512<2>,
                                                         &LagrangeRows512<3>,
                                                         &LagrangeRows512<4>,
                                                         &LagrangeRows512<5>,
                                                         &LagrangeRows512<6>,
                                                         &LagrangeRows512<7>,
                                                         &LagrangeRows512<8>,
                                                         &LagrangeRows512<9>,
                                                         &LagrangeRows512<10>};
constexpr Kernel512 kKernels512[kMaxKernelOrder + 1] = {
    nullptr,         &Contract512<2>,  &Contract512<3>, &Contract512<4>,
    &Contract512<5>, &Contract512<6>,  &Contract512<7>, &Contract512<8>,
    &Contract512<9>, &Contract512<10>, &Contract512<11>};
#endif

}  // namespace

bool SampleAffineHexLine(int p, const double* u, const double ref0[3],
                         const double dref[3], const double* t, int count, double* out,
                         bool wideKernels) {
    if (p < 1 || p > kMaxKernelOrder || count < 1 || count > kMaxHexLineSamples)
        return false;
#if HPRAY_HEX_LINE_KERNEL_512
    const bool wide = wideKernels && CpuHasAvx512();
#else
    const bool wide = false;
    (void)wideKernels;
#endif
    // Rows padded to whole vectors of the kernels in use.
    const int S = wide ? (count + 7) / 8 * 8 : (count + 3) / 4 * 4;
    const int n = p + 1;
    alignas(64) double L[3 * (kMaxKernelOrder + 1) * kMaxHexLineSamples];
    alignas(64) double x[kMaxHexLineSamples];
    alignas(64) double result[kMaxHexLineSamples];
    for (int d = 0; d < 3; ++d) {
        // Padding repeats the last point.
        for (int s = 0; s < S; ++s) x[s] = ref0[d] + t[std::min(s, count - 1)] * dref[d];
#if HPRAY_HEX_LINE_KERNEL_512
        if (wide) {
            kRows512[p](x, S, L + d * n * S);
            continue;
        }
#endif
        kRows[p](x, S, L + d * n * S);
    }
    // Whole vectors of samples by the blocked kernels (with AVX-512 the last vector of
    // four is widened to eight on the padding), the last count % 4 one by one.
    const int blocked = count / 4 * 4;
#if HPRAY_HEX_LINE_KERNEL_512
    if (wide && blocked > 0)
        kKernels512[p](u, L, L + n * S, L + 2 * n * S, (blocked + 7) / 8 * 8, S, result);
#endif
    if (!wide && blocked > 0)
        kKernels[p](u, L, L + n * S, L + 2 * n * S, blocked, S, result);
    for (int s = blocked; s < count; ++s)
        result[s] = kOneKernels[p](u, L, L + n * S, L + 2 * n * S, S, s);
    for (int s = 0; s < count; ++s) out[s] = result[s];
    return true;
}

#else

bool SampleAffineHexLine(int, const double*, const double*, const double*, const double*,
                         int, double*, bool) {
    return false;
}

#endif

}  // namespace hpray
