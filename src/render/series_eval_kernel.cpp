// Legendre series at many points in AVX2 registers (see series_eval_kernel.h).
#include "render/series_eval_kernel.h"

#include <algorithm>

#if defined(__AVX2__) && defined(__FMA__)
#include <immintrin.h>
#define HPRAY_SERIES_KERNEL 1
#else
#define HPRAY_SERIES_KERNEL 0
#endif

namespace hpray {

#if HPRAY_SERIES_KERNEL
namespace {

/// LegendreSeries' recurrence (the same table).
constexpr int kMaxDegree = LegendreRecurrence::kSize - 1;
constexpr const LegendreRecurrence& kRec = kLegendreRecurrence;

/// Two vectors of four points: x = t scale - shift and v = c0 + c1 x (each product and
/// sum rounded, as legendre.cpp's loops compile), then for k >= 2
/// P_k = fma(A_k x, P_{k-1}, -(B_k P_{k-2})) and v = fma(c_k, P_k, v); w likewise for q
/// when Pair.
///
/// Whole: t, outP and outQ hold all eight lanes (the caller's arrays are padded), read
/// and written in place; else the m < = 8 points are copied into a padded block and back.
///
/// NP, NQ >= 0: the degrees of p and q, known at compile time (the caller has checked
/// them), so that the recurrence's loop unrolls; the operations are the same.
template <bool Pair, bool Whole = false, int NP = -1, int NQ = -1>
void Block(const LegendreSeries& p, const LegendreSeries* q, const double* t, int m,
           double scale, double shift, double* outP, double* outQ) {
    alignas(32) double tt[8];
    if (!Whole)
        for (int s = 0; s < 8; ++s)
            tt[s] = s < m ? t[s] : t[0];  // padding repeats the first
    const double* ts = Whole ? t : tt;
    const int np = NP >= 0 ? NP : p.Degree();
    const int nq = !Pair ? 0 : NQ >= 0 ? NQ : q->Degree();
    const int n = std::max(np, nq);
    const __m256d vs = _mm256_set1_pd(scale), vh = _mm256_set1_pd(shift);
    __m256d x[2], p0[2], p1[2], v[2], w[2];
    for (int h = 0; h < 2; ++h) {
        x[h] = _mm256_sub_pd(_mm256_mul_pd(_mm256_loadu_pd(ts + 4 * h), vs), vh);
        p0[h] = _mm256_set1_pd(1.0);
        p1[h] = x[h];
        v[h] = _mm256_set1_pd(p.c[0]);
        if (np >= 1)
            v[h] = _mm256_add_pd(v[h], _mm256_mul_pd(_mm256_set1_pd(p.c[1]), x[h]));
        if (Pair) {
            w[h] = _mm256_set1_pd(q->c[0]);
            if (nq >= 1)
                w[h] = _mm256_add_pd(w[h], _mm256_mul_pd(_mm256_set1_pd(q->c[1]), x[h]));
        }
    }
    auto step = [&](int k, double c, double d) {
        const __m256d ak = _mm256_set1_pd(kRec.a[k]), bk = _mm256_set1_pd(kRec.b[k]);
        const __m256d ck = _mm256_set1_pd(c), dk = _mm256_set1_pd(d);
        for (int h = 0; h < 2; ++h) {
            const __m256d p2 =
                _mm256_fmsub_pd(_mm256_mul_pd(ak, x[h]), p1[h], _mm256_mul_pd(bk, p0[h]));
            v[h] = _mm256_fmadd_pd(ck, p2, v[h]);
            if (Pair) w[h] = _mm256_fmadd_pd(dk, p2, w[h]);
            p0[h] = p1[h];
            p1[h] = p2;
        }
    };
    // The degrees both series have, then those of the longer one (the shorter one's
    // coefficients there zero), without a choice per degree.
    const int both = Pair ? std::min(np, nq) : np;
    int k = 2;
    for (; k <= both; ++k) step(k, p.c[k], Pair ? q->c[k] : 0.0);
    for (; k <= n; ++k) step(k, k <= np ? p.c[k] : 0.0, Pair && k <= nq ? q->c[k] : 0.0);
    if (Whole) {
        for (int h = 0; h < 2; ++h) {
            _mm256_storeu_pd(outP + 4 * h, v[h]);
            if (Pair) _mm256_storeu_pd(outQ + 4 * h, w[h]);
        }
        return;
    }
    alignas(32) double rv[8], rw[8];
    for (int h = 0; h < 2; ++h) {
        _mm256_store_pd(rv + 4 * h, v[h]);
        if (Pair) _mm256_store_pd(rw + 4 * h, w[h]);
    }
    for (int s = 0; s < m; ++s) {
        outP[s] = rv[s];
        if (Pair) outQ[s] = rw[s];
    }
}

}  // namespace

bool EvalPairKernel(const LegendreSeries& p, const LegendreSeries& q, const double* t,
                    int count, double* outP, double* outQ) {
    if (p.a != q.a || p.b != q.b || p.c.empty() || q.c.empty() ||
        std::max(p.Degree(), q.Degree()) > kMaxDegree)
        return false;
    const double scale = 2 / (p.b - p.a), shift = (p.a + p.b) / (p.b - p.a);
    for (int s0 = 0; s0 < count; s0 += 8)
        Block<true>(p, &q, t + s0, std::min(8, count - s0), scale, shift, outP + s0,
                    outQ + s0);
    return true;
}

bool EvalPairKernelWhole(const LegendreSeries& p, const LegendreSeries& q,
                         const double* t, int count, double* outP, double* outQ) {
    if (p.a != q.a || p.b != q.b || p.c.empty() || q.c.empty() ||
        std::max(p.Degree(), q.Degree()) > kMaxDegree)
        return false;
    const double scale = 2 / (p.b - p.a), shift = (p.a + p.b) / (p.b - p.a);
    // The low degrees of the volume pieces' series (a field of degree d and its
    // antiderivative, of degree d + 1) with their loops unrolled.
    auto blocks = [&]<int NP, int NQ>() {
        for (int s0 = 0; s0 < count; s0 += 8)
            Block<true, true, NP, NQ>(p, &q, t + s0, 8, scale, shift, outP + s0,
                                      outQ + s0);
    };
    const int np = p.Degree(), nq = q.Degree();
    if (nq == np + 1 && np <= 4) {
        if (np == 0)
            blocks.operator()<0, 1>();
        else if (np == 1)
            blocks.operator()<1, 2>();
        else if (np == 2)
            blocks.operator()<2, 3>();
        else if (np == 3)
            blocks.operator()<3, 4>();
        else
            blocks.operator()<4, 5>();
    } else {
        blocks.operator()<-1, -1>();
    }
    return true;
}

bool EvalManyKernelWhole(const LegendreSeries& p, const double* t, int count,
                         double* out) {
    if (p.c.empty() || p.Degree() > kMaxDegree) return false;
    const double scale = 2 / (p.b - p.a), shift = (p.a + p.b) / (p.b - p.a);
    // Low degrees with their loops unrolled (see EvalPairKernelWhole).
    auto blocks = [&]<int NP>() {
        for (int s0 = 0; s0 < count; s0 += 8)
            Block<false, true, NP>(p, nullptr, t + s0, 8, scale, shift, out + s0,
                                   nullptr);
    };
    const int np = p.Degree();
    if (np == 0)
        blocks.operator()<0>();
    else if (np == 1)
        blocks.operator()<1>();
    else if (np == 2)
        blocks.operator()<2>();
    else if (np == 3)
        blocks.operator()<3>();
    else if (np == 4)
        blocks.operator()<4>();
    else
        blocks.operator()<-1>();
    return true;
}

bool EvalManyKernel(const LegendreSeries& p, const double* t, int count, double* out) {
    if (p.c.empty() || p.Degree() > kMaxDegree) return false;
    const double scale = 2 / (p.b - p.a), shift = (p.a + p.b) / (p.b - p.a);
    for (int s0 = 0; s0 < count; s0 += 8)
        Block<false>(p, nullptr, t + s0, std::min(8, count - s0), scale, shift, out + s0,
                     nullptr);
    return true;
}

#else

bool EvalPairKernel(const LegendreSeries&, const LegendreSeries&, const double*, int,
                    double*, double*) {
    return false;
}
bool EvalManyKernel(const LegendreSeries&, const double*, int, double*) { return false; }
bool EvalPairKernelWhole(const LegendreSeries&, const LegendreSeries&, const double*, int,
                         double*, double*) {
    return false;
}
bool EvalManyKernelWhole(const LegendreSeries&, const double*, int, double*) {
    return false;
}

#endif

}  // namespace hpray
