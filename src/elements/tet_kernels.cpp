// Compile-time-sized Lagrange tetrahedron kernels (see tet_kernels.h). The arithmetic
// mirrors EvalTet of basis.cpp and the node sums of geometry.cpp and field.cpp operation
// for operation; only the loop bounds are constants and the basis values are consumed
// where they are made (except the order-3 map's node sums: see Map3).
#include "elements/tet_kernels.h"

#include <cmath>

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
// Silvester<double>(P, x, s, ds) lane by lane: the same operations, nothing fused (the
// build does not fuse them), so each lane is bitwise the scalar factors at its x.
template <int P>
inline void SilvesterLanes(lanes::D<4> x, lanes::D<4>* s, lanes::D<4>* ds) {
    const lanes::D<4> px = double(P) * x;
    s[0] = lanes::Splat<4>(1.0);
    ds[0] = lanes::Splat<4>(0.0);
    for (int m = 0; m < P; ++m) {
        const double inv = 1.0 / double(m + 1);
        const lanes::D<4> f = (px - double(m)) * inv;
        ds[m + 1] = ds[m] * f + s[m] * (P * inv);
        s[m + 1] = s[m] * f;
    }
}

// Value<P> at four points, point q in lane q: Silvester's factors and the sums over the
// nodes with the same products and sums in the same order, so each lane is bitwise
// Value<P> at its point.
template <int P>
lanes::D<4> Value4(const double* u, lanes::D<4> r0, lanes::D<4> r1, lanes::D<4> r2) {
    using V = lanes::D<4>;
    V a[P + 1], b[P + 1], c[P + 1], e[P + 1], unused[P + 1];
    SilvesterLanes<P>(r0, a, unused);
    SilvesterLanes<P>(r1, b, unused);
    SilvesterLanes<P>(r2, c, unused);
    SilvesterLanes<P>(1.0 - r0 - r1 - r2, e, unused);
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

// Order 3, the curved tetrahedra of most meshes: the map sums its 20 nodes in four
// interleaved partial sums, node m into sum m mod 4, each in order of m by fused
// multiply-adds, and adds them as (s0 + s1) + (s2 + s3). The basis values and derivatives
// of a node are those of ForEachNode (the same operations); only the order of the sums
// differs from the other orders', so that four nodes go through the lanes of a vector
// together. MapBlocked is the scalar form (builds without vectors, and the tests'
// reference).
constexpr int kTet3Nodes = 20;
struct TetLattice {
    int i[kTet3Nodes] = {}, j[kTet3Nodes] = {}, k[kTet3Nodes] = {}, l[kTet3Nodes] = {};
    constexpr TetLattice() {
        int m = 0;
        for (int kk = 0; kk <= 3; ++kk)
            for (int jj = 0; jj + kk <= 3; ++jj)
                for (int ii = 0; ii + jj + kk <= 3; ++ii, ++m) {
                    i[m] = ii;
                    j[m] = jj;
                    k[m] = kk;
                    l[m] = 3 - ii - jj - kk;
                }
    }
};
constexpr TetLattice kTet3{};

void MapBlocked3(const double* xyz, const double ref[3], double world[3],
                 double* jacobian) {
    double x[4][3] = {}, j0[4][3] = {}, j1[4][3] = {}, j2[4][3] = {};
    ForEachNode<3, true>(ref, [&](int m, double v, const double* d) {
        const int t = m % 4;
        for (int c = 0; c < 3; ++c) {
            const double p = xyz[3 * m + c];
            x[t][c] = std::fma(v, p, x[t][c]);
            if (jacobian) {
                j0[t][c] = std::fma(d[0], p, j0[t][c]);
                j1[t][c] = std::fma(d[1], p, j1[t][c]);
                j2[t][c] = std::fma(d[2], p, j2[t][c]);
            }
        }
    });
    auto total = [](const double(*s)[3], int c) {
        return (s[0][c] + s[1][c]) + (s[2][c] + s[3][c]);
    };
    for (int c = 0; c < 3; ++c) {
        world[c] = total(x, c);
        if (jacobian) {
            jacobian[3 * c] = total(j0, c);
            jacobian[3 * c + 1] = total(j1, c);
            jacobian[3 * c + 2] = total(j2, c);
        }
    }
}

#if defined(HPRAY_LANES)
using V4 = lanes::D<4>;

// Node m's lattice index i, j, k or l (Which = 0, 1, 2, 3).
constexpr int LatticeIndex(int which, int m) {
    return which == 0   ? kTet3.i[m]
           : which == 1 ? kTet3.j[m]
           : which == 2 ? kTet3.k[m]
                        : kTet3.l[m];
}

// Lane t for node 4Q + t (Q a constant): its lattice index Which looked up in a 4-vector
// of per-index factors.
template <int Q, int Which>
inline V4 Pick(V4 a) {
    return __builtin_shufflevector(
        a, a, LatticeIndex(Which, 4 * Q), LatticeIndex(Which, 4 * Q + 1),
        LatticeIndex(Which, 4 * Q + 2), LatticeIndex(Which, 4 * Q + 3));
}

struct Tet3Factors {
    V4 a, b, c, e, da, db, dc, de;  // Silvester's factors by index 0..3, and slopes
};

struct Tet3Sums {
    V4 x[3], j0[3], j1[3], j2[3];  // per coordinate; lane t: partial sum t
};

// Nodes 4Q .. 4Q + 3 added to the partial sums.
template <int Q, bool Jacobian>
inline void AddNodes3(const double* xyz, const Tet3Factors& f, Tet3Sums& s) {
    const V4 a = Pick<Q, 0>(f.a), da = Pick<Q, 0>(f.da);
    const V4 b = Pick<Q, 1>(f.b), db = Pick<Q, 1>(f.db);
    const V4 c = Pick<Q, 2>(f.c), dc = Pick<Q, 2>(f.dc);
    const V4 e = Pick<Q, 3>(f.e), de = Pick<Q, 3>(f.de);
    // ForEachNode's expressions, lane by lane.
    const V4 bc = b * c;
    const V4 value = a * bc * e;
    // The nodes' coordinates, x, y and z of the four in turn (12 doubles from 12 Q).
    const V4 l0 = lanes::Load<4>(xyz + 12 * Q), l1 = lanes::Load<4>(xyz + 12 * Q + 4),
             l2 = lanes::Load<4>(xyz + 12 * Q + 8);
    const V4 ux = __builtin_shufflevector(l0, l1, 0, 3, 6, 0);
    const V4 uy = __builtin_shufflevector(l0, l1, 1, 4, 7, 0);
    const V4 uz = __builtin_shufflevector(l0, l1, 2, 5, 0, 0);
    const V4 p[3] = {__builtin_shufflevector(ux, l2, 0, 1, 2, 5),
                     __builtin_shufflevector(uy, l2, 0, 1, 2, 6),
                     __builtin_shufflevector(uz, l2, 0, 1, 4, 7)};
    for (int k = 0; k < 3; ++k) s.x[k] = lanes::Fma(value, p[k], s.x[k]);
    if constexpr (Jacobian) {
        const V4 ae = a * e;
        const V4 ade = a * de;
        const V4 d0 = (da * e - ade) * bc;
        const V4 d1 = (db * c * ae) - ade * bc;
        const V4 d2 = (b * dc * ae) - ade * bc;
        for (int k = 0; k < 3; ++k) {
            s.j0[k] = lanes::Fma(d0, p[k], s.j0[k]);
            s.j1[k] = lanes::Fma(d1, p[k], s.j1[k]);
            s.j2[k] = lanes::Fma(d2, p[k], s.j2[k]);
        }
    }
}

inline double Total(V4 s) { return (s[0] + s[1]) + (s[2] + s[3]); }

template <bool Jacobian>
void MapLanes3(const double* xyz, const double ref[3], double world[3],
               double* jacobian) {
    // Silvester<double>(3, x, s, ds) for x = ref[0], ref[1], ref[2] and 1 - their sum, in
    // the four lanes; then transposed to factor vectors by index.
    const V4 X = {ref[0], ref[1], ref[2], 1.0 - ref[0] - ref[1] - ref[2]};
    V4 S[4], dS[4];
    SilvesterLanes<3>(X, S, dS);
    auto transpose = [](const V4* r, V4& a, V4& b, V4& c, V4& e) {
        const V4 t0 = __builtin_shufflevector(r[0], r[1], 0, 4, 2, 6);
        const V4 t1 = __builtin_shufflevector(r[0], r[1], 1, 5, 3, 7);
        const V4 t2 = __builtin_shufflevector(r[2], r[3], 0, 4, 2, 6);
        const V4 t3 = __builtin_shufflevector(r[2], r[3], 1, 5, 3, 7);
        a = __builtin_shufflevector(t0, t2, 0, 1, 4, 5);
        c = __builtin_shufflevector(t0, t2, 2, 3, 6, 7);
        b = __builtin_shufflevector(t1, t3, 0, 1, 4, 5);
        e = __builtin_shufflevector(t1, t3, 2, 3, 6, 7);
    };
    Tet3Factors f;
    transpose(S, f.a, f.b, f.c, f.e);
    transpose(dS, f.da, f.db, f.dc, f.de);
    Tet3Sums s;
    for (int k = 0; k < 3; ++k)
        s.x[k] = s.j0[k] = s.j1[k] = s.j2[k] = lanes::Splat<4>(0.0);
    AddNodes3<0, Jacobian>(xyz, f, s);
    AddNodes3<1, Jacobian>(xyz, f, s);
    AddNodes3<2, Jacobian>(xyz, f, s);
    AddNodes3<3, Jacobian>(xyz, f, s);
    AddNodes3<4, Jacobian>(xyz, f, s);
    for (int c = 0; c < 3; ++c) {
        world[c] = Total(s.x[c]);
        if constexpr (Jacobian) {
            jacobian[3 * c] = Total(s.j0[c]);
            jacobian[3 * c + 1] = Total(s.j1[c]);
            jacobian[3 * c + 2] = Total(s.j2[c]);
        }
    }
}
#endif

void Map3(const double* xyz, const double ref[3], double world[3], double* jacobian) {
#if defined(HPRAY_LANES)
    if (jacobian)
        MapLanes3<true>(xyz, ref, world, jacobian);
    else
        MapLanes3<false>(xyz, ref, world, nullptr);
#else
    MapBlocked3(xyz, ref, world, jacobian);
#endif
}

template <int P>
constexpr TetKernels Make() {
    if constexpr (P == 3)
        return {P, &Value<P>, &ValueGradient<P>, &Map3, &Values<P>};
    else
        return {P, &Value<P>, &ValueGradient<P>, &Map<P>, &Values<P>};
}

constexpr TetKernels kTable[kMaxOrder + 1] = {
    TetKernels{}, Make<1>(), Make<2>(), Make<3>(), Make<4>(), Make<5>(),
    Make<6>(),    Make<7>(), Make<8>(), Make<9>(), Make<10>()};

}  // namespace

void TetMapBlocked3(const double* xyz, const double ref[3], double world[3],
                    double* jacobian) {
    MapBlocked3(xyz, ref, world, jacobian);
}

const TetKernels& TetKernelsFor(int p) {
    HPRAY_CHECK(p >= 1 && p <= kMaxOrder);
    return kTable[p];
}

}  // namespace hpray
