// Compile-time-sized Lagrange tetrahedron kernels (see tet_kernels.h). The arithmetic
// mirrors EvalTet of basis.cpp and the node sums of geometry.cpp and field.cpp operation
// for operation; only the loop bounds are constants and the basis values are consumed
// where they are made.
#include "elements/tet_kernels.h"

#if defined(__AVX2__)
#include <immintrin.h>
#endif

#include "elements/silvester.h"
#include "mesh/cell.h"
#include "util/check.h"
#include "util/lanes.h"

namespace hpray {
namespace {

// Visits the nodes in the internal order with their basis value and, if Derivative, their
// reference gradient, computed as EvalTet computes them.
template <int P, bool Derivative, typename Visit>
inline void ForEachNode(const double ref[3], Visit&& visit) {
    double a[P + 1], da[P + 1], b[P + 1], db[P + 1];
    double c[P + 1], dc[P + 1], e[P + 1], de[P + 1];
    Silvester<double>(P, ref[0], a, da);
    Silvester<double>(P, ref[1], b, db);
    Silvester<double>(P, ref[2], c, dc);
    Silvester<double>(P, 1.0 - ref[0] - ref[1] - ref[2], e, de);
    int m = 0;
    for (int k = 0; k <= P; ++k)
        for (int j = 0; j + k <= P; ++j)
            for (int i = 0; i + j + k <= P; ++i, ++m) {
                const int l = P - i - j - k;
                const double bc = b[j] * c[k];
                const double value = a[i] * bc * e[l];
                if constexpr (!Derivative) {
                    visit(m, value, nullptr);
                } else {
                    const double ae = a[i] * e[l];
                    const double ade = a[i] * de[l];
                    const double d[3] = {(da[i] * e[l] - ade) * bc,
                                         (db[j] * c[k] * ae) - ade * bc,
                                         (b[j] * dc[k] * ae) - ade * bc};
                    visit(m, value, d);
                }
            }
}

template <int P>
double Value(const double* u, const double ref[3]) {
    double f = 0.0;
    ForEachNode<P, false>(ref, [&](int m, double v, const double*) { f += u[m] * v; });
    return f;
}

template <int P>
double ValueGradient(const double* u, const double ref[3], double dRef[3]) {
    double f = 0.0, g[3] = {0.0, 0.0, 0.0};
    ForEachNode<P, true>(ref, [&](int m, double v, const double* d) {
        const double c = u[m];
        f += c * v;
        g[0] += c * d[0];
        g[1] += c * d[1];
        g[2] += c * d[2];
    });
    dRef[0] = g[0];
    dRef[1] = g[1];
    dRef[2] = g[2];
    return f;
}

#if defined(__AVX2__)
// A node's coordinates (x, y, z) in the first three lanes of a vector, the fourth zero
// (a masked load: nothing past the node is read).
inline __m256d NodeXyz(const double* xyz, int m) {
    return _mm256_maskload_pd(xyz + 3 * m, _mm256_setr_epi64x(-1, -1, -1, 0));
}
#endif

template <int P>
void Map(const double* xyz, const double ref[3], double world[3], double* jacobian) {
#if defined(__AVX2__)
    // The sums of the scalar version below in the lanes of vectors, coordinate c in lane
    // c: each lane takes its products and sums in the same order (a product, then a sum;
    // nothing fused), so the results are bitwise the same.
    if (!jacobian) {
        __m256d x = _mm256_setzero_pd();
        ForEachNode<P, false>(ref, [&](int m, double v, const double*) {
            x = _mm256_add_pd(x, _mm256_mul_pd(_mm256_set1_pd(v), NodeXyz(xyz, m)));
        });
        alignas(32) double out[4];
        _mm256_store_pd(out, x);
        for (int c = 0; c < 3; ++c) world[c] = out[c];
        return;
    }
    // x and the Jacobian's columns d x / d ref_k.
    __m256d x = _mm256_setzero_pd(), j0 = x, j1 = x, j2 = x;
    ForEachNode<P, true>(ref, [&](int m, double v, const double* d) {
        const __m256d p = NodeXyz(xyz, m);
        x = _mm256_add_pd(x, _mm256_mul_pd(_mm256_set1_pd(v), p));
        j0 = _mm256_add_pd(j0, _mm256_mul_pd(p, _mm256_set1_pd(d[0])));
        j1 = _mm256_add_pd(j1, _mm256_mul_pd(p, _mm256_set1_pd(d[1])));
        j2 = _mm256_add_pd(j2, _mm256_mul_pd(p, _mm256_set1_pd(d[2])));
    });
    alignas(32) double out[4][4];
    _mm256_store_pd(out[0], x);
    _mm256_store_pd(out[1], j0);
    _mm256_store_pd(out[2], j1);
    _mm256_store_pd(out[3], j2);
    for (int c = 0; c < 3; ++c) {
        world[c] = out[0][c];
        for (int k = 0; k < 3; ++k) jacobian[3 * c + k] = out[1 + k][c];
    }
#else
    double x0 = 0, x1 = 0, x2 = 0;
    if (!jacobian) {
        ForEachNode<P, false>(ref, [&](int m, double v, const double*) {
            x0 += v * xyz[3 * m];
            x1 += v * xyz[3 * m + 1];
            x2 += v * xyz[3 * m + 2];
        });
    } else {
        double j[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0};
        ForEachNode<P, true>(ref, [&](int m, double v, const double* d) {
            x0 += v * xyz[3 * m];
            x1 += v * xyz[3 * m + 1];
            x2 += v * xyz[3 * m + 2];
            for (int i = 0; i < 3; ++i) {
                const double c = xyz[3 * m + i];
                j[3 * i] += c * d[0];
                j[3 * i + 1] += c * d[1];
                j[3 * i + 2] += c * d[2];
            }
        });
        for (int i = 0; i < 9; ++i) jacobian[i] = j[i];
    }
    world[0] = x0;
    world[1] = x1;
    world[2] = x2;
#endif
}

#if defined(HPRAY_LANES)
// Value<P> at four points, point q in lane q: Silvester's factors and the sums over the
// nodes with the same products and sums in the same order (the build does not fuse them),
// so each lane is bitwise Value<P> at its point.
template <int P>
lanes::D<4> Value4(const double* u, lanes::D<4> r0, lanes::D<4> r1, lanes::D<4> r2) {
    using V = lanes::D<4>;
    // Silvester<double>(P, x, s, ds)'s s.
    auto silvester = [](V x, V* s) {
        const V px = double(P) * x;
        s[0] = lanes::Splat<4>(1.0);
        for (int m = 0; m < P; ++m) {
            const double inv = 1.0 / double(m + 1);
            const V f = (px - double(m)) * inv;
            s[m + 1] = s[m] * f;
        }
    };
    V a[P + 1], b[P + 1], c[P + 1], e[P + 1];
    silvester(r0, a);
    silvester(r1, b);
    silvester(r2, c);
    silvester(1.0 - r0 - r1 - r2, e);
    V f = lanes::Splat<4>(0.0);
    int m = 0;
    for (int k = 0; k <= P; ++k)
        for (int j = 0; j + k <= P; ++j)
            for (int i = 0; i + j + k <= P; ++i, ++m) {
                const int l = P - i - j - k;
                const V bc = b[j] * c[k];
                const V value = a[i] * bc * e[l];
                f += u[m] * value;
            }
    return f;
}
#endif

template <int P>
void Values(const double* u, const double* refs, int n, double* out) {
    int first = 0;
#if defined(HPRAY_LANES)
    for (; first + 4 <= n; first += 4) {
        const double* q = refs + 3 * first;
        const lanes::D<4> r0 = {q[0], q[3], q[6], q[9]}, r1 = {q[1], q[4], q[7], q[10]},
                          r2 = {q[2], q[5], q[8], q[11]};
        const lanes::D<4> f = Value4<P>(u, r0, r1, r2);
        std::memcpy(out + first, &f, sizeof f);
    }
#endif
    for (int s = first; s < n; ++s) out[s] = Value<P>(u, refs + 3 * s);
}

template <int P>
constexpr TetKernels Make() {
    return {P, &Value<P>, &ValueGradient<P>, &Map<P>, &Values<P>};
}

constexpr TetKernels kTable[kMaxOrder + 1] = {
    TetKernels{}, Make<1>(), Make<2>(), Make<3>(), Make<4>(), Make<5>(),
    Make<6>(),    Make<7>(), Make<8>(), Make<9>(), Make<10>()};

}  // namespace

const TetKernels& TetKernelsFor(int p) {
    HPRAY_CHECK(p >= 1 && p <= kMaxOrder);
    return kTable[p];
}

}  // namespace hpray
