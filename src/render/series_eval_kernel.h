// Legendre series at many points in AVX2 registers: the evaluations of the exact field
// series at a volume piece's quadrature nodes.
#pragma once

#if defined(__AVX2__) && defined(__FMA__)
#include <immintrin.h>
#endif

#include "render/legendre.h"
#include "util/check.h"

namespace hpray {

/// EvalPair (render/legendre.h) of p and q at t[s], s < count, into outP[s] and outQ[s],
/// with the points' recurrences in vector registers (eight at a time). Bitwise the same
/// values as EvalPair: the same operations in the same order, each rounded once. Returns
/// false, writing nothing, where this build has no kernel (AVX2 with FMA) or the degree
/// exceeds EvalPair's; the caller then uses EvalPair.
bool EvalPairKernel(const LegendreSeries& p, const LegendreSeries& q, const double* t,
                    int count, double* outP, double* outQ);

/// The same for one series (LegendreSeries::EvalMany).
bool EvalManyKernel(const LegendreSeries& p, const double* t, int count, double* out);

/// EvalPairKernel and EvalManyKernel on whole blocks of eight points: t, outP, outQ and
/// out hold count rounded up to a multiple of 8 entries, all read and written (each
/// point's values depend on it alone: those of the first count are the same).
bool EvalPairKernelWhole(const LegendreSeries& p, const LegendreSeries& q,
                         const double* t, int count, double* outP, double* outQ);
bool EvalManyKernelWhole(const LegendreSeries& p, const double* t, int count,
                         double* out);

/// p.At(t0) into v0 and p.At(t1) into v1, the two in the lanes of a vector where the
/// build has AVX2 with FMA: each lane the operations of LegendreSeries::At (bitwise its
/// values).
inline void AtTwo(const LegendreSeries& p, double t0, double t1, double& v0, double& v1) {
#if defined(__AVX2__) && defined(__FMA__)
    const int n = p.Degree();
    HPRAY_CHECK(n < LegendreRecurrence::kSize);
    const LegendreRecurrence& rec = kLegendreRecurrence;
    const __m128d a = _mm_set1_pd(p.a), b = _mm_set1_pd(p.b);
    const __m128d x = _mm_div_pd(
        _mm_sub_pd(_mm_sub_pd(_mm_mul_pd(_mm_set1_pd(2.0), _mm_set_pd(t1, t0)), a), b),
        _mm_sub_pd(b, a));
    const double* c = p.c.data();
    __m128d v = _mm_set1_pd(c[0]);
    if (n >= 1) v = _mm_add_pd(v, _mm_mul_pd(_mm_set1_pd(c[1]), x));
    __m128d q0 = _mm_set1_pd(1.0), q1 = x;
    for (int k = 2; k <= n; ++k) {
        const __m128d q2 = _mm_fmsub_pd(_mm_mul_pd(_mm_set1_pd(rec.a[k]), x), q1,
                                        _mm_mul_pd(_mm_set1_pd(rec.b[k]), q0));
        v = _mm_fmadd_pd(_mm_set1_pd(c[k]), q2, v);
        q0 = q1;
        q1 = q2;
    }
    v0 = _mm_cvtsd_f64(v);
    v1 = _mm_cvtsd_f64(_mm_unpackhi_pd(v, v));
#else
    v0 = p.At(t0);
    v1 = p.At(t1);
#endif
}

}  // namespace hpray
