// Volume integration along one ray (see volume_ray.h).
#include "render/volume_ray.h"

#include <tbb/parallel_for.h>

#if defined(__AVX2__) && defined(__FMA__)
#include <immintrin.h>
#endif

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>

#include "render/hex_line_sampler.h"
#include "render/series_eval_kernel.h"
#include "trace/ray_frame.h"
#include "util/check.h"
#include "util/dense_inverse.h"
#include "util/error.h"

namespace hpray {
namespace {

constexpr double kEps = std::numeric_limits<double>::epsilon();
/// Bisections of a Kronrod piece stop here (2^-40 of the piece); the estimate stays.
constexpr int kMaxKronrodDepth = 40;
/// Kronrod intervals evaluated in one piece before the rest are accepted as they are
/// (their error estimates still go into vol.error): a cap on the work of integrands whose
/// estimated error does not shrink with the interval (noise at the tolerance's level).
constexpr int kMaxKronrodEvaluations = 4096;
/// Series mode: the highest rung of the nested ladder (GetNestedQuadratureRules: rung L
/// integrates by rule L, estimated by rule L + 1) climbed to before an interval is
/// bisected, and the rung every piece starts on. Climbing evaluates only the nodes the
/// higher rule adds, so a piece costs the nodes of the rung that suffices, wherever it
/// starts at or below it. Rung 1 for all: rung 0's estimate (the midpoint against Gauss
/// 3) can vanish by accident where the integrand is far from a polynomial (the claimed
/// error then fails to bound the true one on test scenes).
constexpr int kTopLevel = 3;
constexpr int kStartLevel = 1;
/// An interval's result is its lower rule (Gauss; in series mode rule L of the nested
/// ladder), whose error is estimated by the difference s from the higher rule that
/// extends it (Kronrod; rule L + 1, of about twice the degree): truth - lower = s + the
/// higher rule's own error. That error is taken as at most this fraction of |s|, and goes
/// into the error as an absolute term.
constexpr double kKronrodMargin = 0.25;
/// A bound of the rounding error of a Legendre series evaluated by its recurrence (and
/// of the sampled field it interpolates), in units of eps times the sum of |c_k|.
constexpr double kSeriesRounding = 8;
/// A bound of the rounding error of the field's samples in a cell, in units of eps times
/// the largest |value| in the cell (measured on nk-sinc's order-8 cells: at most 12).
constexpr double kSampleRounding = 32;
/// 1 + the Lebesgue constant of interpolation at the Legendre-Gauss-Lobatto nodes of any
/// degree used here (at most 2.7 up to degree 30): how much a part of the field that the
/// samples do not resolve changes the interpolant, at most.
constexpr double kLebesgueBound = 4;
/// Trailing Legendre coefficients of an exact series whose sum is below this many eps
/// times the largest |value| in the cell (half the samples' rounding bound) are dropped,
/// and their sum counted as field error.
constexpr double kTruncation = 16;

/// Share of a segment's part of volume_tolerance (its length over the ray's, times the
/// tolerance) that the field error of sampling an affine Lagrange hexahedron at a lower
/// degree may take, through the transfer functions' steepest slopes. The bound is a sup
/// of the field's error while the pixel feels its integral, in which the interpolation
/// error (a polynomial with m + 1 roots on the segment) largely cancels: a larger share
/// makes vol.error overstate the true error on pixels whose error is far below the
/// tolerance. With 1e-5 vol.error stays within 100x of the true error on more than 99%
/// of the pixels of test VolumeErrorBars at tolerances 1e-4, 1e-6 and 1e-8 (1e-4 of the
/// tolerance: 98% at 1e-4).
constexpr double kDegreeShare = 1e-5;
/// Degrees an affine Lagrange hexahedron's series may be sampled at below its exact 3p:
/// whole vectors of 4 samples for the line sampler.
constexpr int kSampledDegrees[] = {3, 7, 11, 15, 19, 23, 27};
/// Highest degree of the series of a linear pyramid's (rational) field along a ray; a
/// segment that needs more (one passing near the apex plane) takes the general path.
constexpr int kMaxRationalDegree = 32;
/// A linear pyramid's field is taken in closed form (BeginPyramidLine) where its pole
/// lies between kPyramidNearPole and 1 / kPyramidFarPole - 1 half-lengths beyond the
/// segment, and the rounding bounds of the closed forms stay within kPyramidRounding eps
/// of the cell's values (their sum), about what the series' own come to.
constexpr double kPyramidFarPole = 1.0 / 64, kPyramidNearPole = 1.0 / 1024;
constexpr double kPyramidRounding = 256;
/// The nested rules, looked up once (GetNestedQuadratureRules builds them on first use).
const NestedQuadratureRules& kQuadratureRules = GetNestedQuadratureRules();

/// Legendre coefficients from values at the equispaced nodes y_i = 2 i / p - 1 of
/// [-1, 1]: the inverse of V_ij = P_j(y_i) (row-major, (p + 1)^2), by Gauss-Jordan with
/// partial pivoting in long double.
std::vector<long double> LegendreFromEquispaced(int p) {
    using LD = long double;
    const int n = p + 1;
    std::vector<LD> v(std::size_t(n) * n);
    for (int i = 0; i < n; ++i) {
        // P_j(y_i) by the three-term recurrence.
        const LD y = LD(2 * i) / p - 1;
        LD prev = 1, cur = y;
        for (int j = 0; j < n; ++j) {
            LD value = j == 0 ? LD(1) : y;
            if (j >= 2) {
                const LD next = (LD(2 * j - 1) * y * cur - LD(j - 1) * prev) / j;
                prev = cur;
                cur = next;
                value = next;
            }
            v[std::size_t(i) * n + j] = value;
        }
    }
    return InvertDense(n, std::move(v));
}

/// degreeTail of one Lagrange hexahedron of order p (see VolumeSetup::degreeTail) from
/// its nodal values u (lattice order, i fastest) into tail[0..3p].
void HexDegreeTail(int p, const double* u, const std::vector<long double>& legendre,
                   double* tail) {
    using LD = long double;
    const int n = p + 1;
    LD a[(kMaxOrder + 1) * (kMaxOrder + 1) * (kMaxOrder + 1)];
    LD b[(kMaxOrder + 1) * (kMaxOrder + 1) * (kMaxOrder + 1)];
    for (int q = 0; q < n * n * n; ++q) a[q] = u[q];
    // One direction at a time: b[.., j, ..] = sum_i M_ji a[.., i, ..].
    LD norm = 0, scale = 0;
    for (int j = 0; j < n; ++j) {
        LD row = 0;
        for (int i = 0; i < n; ++i) row += std::abs(legendre[std::size_t(j) * n + i]);
        norm = std::max(norm, row);
    }
    for (int q = 0; q < n * n * n; ++q) scale = std::max(scale, std::abs(a[q]));
    int stride = 1;
    for (int d = 0; d < 3; ++d, stride *= n) {
        for (int q = 0; q < n * n * n; ++q) {
            const int i0 = (q / stride) % n;
            const int base = q - i0 * stride;
            LD sum = 0;
            for (int i = 0; i < n; ++i)
                sum += legendre[std::size_t(i0) * n + i] * a[base + i * stride];
            b[q] = sum;
        }
        std::copy(b, b + n * n * n, a);
    }
    LD byDegree[3 * kMaxOrder + 1] = {};
    for (int k = 0; k < n; ++k)
        for (int j = 0; j < n; ++j)
            for (int i = 0; i < n; ++i)
                byDegree[i + j + k] += std::abs(a[i + n * (j + n * k)]);
    // Rounding of the three passes, each a sum of n products: far above long double's.
    const LD slack =
        8 * 3 * n * std::numeric_limits<LD>::epsilon() * norm * norm * norm * scale;
    LD rest = 0;
    tail[3 * p] = 0;
    for (int m = 3 * p - 1; m >= 0; --m) {
        rest += byDegree[m + 1];
        tail[m] = double((rest + slack) * (1 + 1e-15L));
    }
}

const std::vector<long double>& LegendreFromEquispacedCached(int p) {
    static const auto tables = [] {
        std::vector<std::vector<long double>> t(kMaxOrder + 1);
        for (int q = 1; q <= kMaxOrder; ++q) t[q] = LegendreFromEquispaced(q);
        return t;
    }();
    return tables[p];
}

PiecewiseLinearTf ExtinctionTf(const std::vector<ExtinctionControlPoint>& points) {
    std::vector<double> s, v;
    for (const ExtinctionControlPoint& p : points) {
        s.push_back(p.scalar);
        v.push_back(p.extinction);
    }
    return PiecewiseLinearTf(std::move(s), std::move(v), 1);
}

/// The root of p - level in [lo, hi], where p - level has the signs of fLo and fHi (opposite,
/// nonzero) at the ends and p is monotone: Newton's method kept inside the shrinking
/// bracket (bisection when a step leaves it), to `tol` in t.
double MonotoneRoot(const LegendreSeries& p, double level, double lo, double hi, double fLo,
                    double fHi, double guess, double tol, double noise) {
    double t = guess > lo && guess < hi ? guess : lo + (hi - lo) * (fLo / (fLo - fHi));
    bool probed = false;
    for (int it = 0; it < 100; ++it) {
        double v, dv;
        p.Eval(t, v, dv);
        const double f = v - level;
        // Within the rounding of p: no closer root can be told apart.
        if (std::abs(f) <= noise) return t;
        if ((f < 0) == (fLo < 0)) {
            lo = t;
            fLo = f;
        } else {
            hi = t;
        }
        double next = dv != 0 ? t - f / dv : 0.5 * (lo + hi);
        bool probe = false;
        if (!(next > lo && next < hi)) {
            // Newton points past an end of the bracket: mostly a root within rounding of
            // that end (a crossing at a critical point or at the segment's end), which
            // bisection would take some 40 halvings to reach. Probe once just inside that
            // end (a bracket of width tol then ends the search), else bisect.
            const double inside = std::min(tol, 0.25 * (hi - lo));
            if (!probed && dv != 0 && inside > 0) {
                next = next <= lo ? lo + inside : hi - inside;
                probed = probe = true;
            } else {
                next = 0.5 * (lo + hi);
            }
        }
        // A probe's step says nothing of convergence; only the bracket's width does.
        if (hi - lo <= tol || (!probe && std::abs(next - t) <= tol)) return next;
        t = next;
    }
    return t;
}

#if defined(__AVX2__) && defined(__FMA__)
/// ExpNegative's four lanes: exp(-x) of each lane of xv (see ExpNegative).
inline __m256d ExpNegativeLanes(__m256d xv) {
    constexpr double kLog2e = 1.4426950408889634074, kLn2Hi = 6.93147180369123816490e-01,
                     kLn2Lo = 1.90821492927058770002e-10, kShifter = 6755399441055744.0;
    // 1 / k!, k = 0..13.
    const double* kCoef = kInverseFactorial;
    const __m256d big = _mm256_cmp_pd(xv, _mm256_set1_pd(708.0), _CMP_GT_OQ);
    const __m256d y =
        _mm256_sub_pd(_mm256_setzero_pd(), _mm256_min_pd(xv, _mm256_set1_pd(708.0)));
    // k = round(y / ln 2) in the low bits of kd.
    const __m256d kd =
        _mm256_fmadd_pd(y, _mm256_set1_pd(kLog2e), _mm256_set1_pd(kShifter));
    const __m256d k = _mm256_sub_pd(kd, _mm256_set1_pd(kShifter));
    __m256d r = _mm256_fnmadd_pd(k, _mm256_set1_pd(kLn2Hi), y);
    r = _mm256_fnmadd_pd(k, _mm256_set1_pd(kLn2Lo), r);
    // The polynomial by Estrin's scheme (pairs, then pairs of pairs in r^2, r^4, r^8):
    // four levels of multiply-adds instead of Horner's chain of thirteen, whose latency
    // each series piece waited for.
    auto pair = [&](int c) {
        return _mm256_fmadd_pd(_mm256_set1_pd(kCoef[c + 1]), r, _mm256_set1_pd(kCoef[c]));
    };
    const __m256d r2 = _mm256_mul_pd(r, r), r4 = _mm256_mul_pd(r2, r2),
                  r8 = _mm256_mul_pd(r4, r4);
    const __m256d s0 = _mm256_fmadd_pd(pair(2), r2, pair(0));
    const __m256d s1 = _mm256_fmadd_pd(pair(6), r2, pair(4));
    const __m256d s2 = _mm256_fmadd_pd(pair(10), r2, pair(8));
    const __m256d s3 = pair(12);
    const __m256d u0 = _mm256_fmadd_pd(s1, r4, s0), u1 = _mm256_fmadd_pd(s3, r4, s2);
    const __m256d poly = _mm256_fmadd_pd(u1, r8, u0);
    // 2^k: (k + 1023) << 52, with k the integer in kd's low bits.
    const __m256i ki = _mm256_sub_epi64(_mm256_castpd_si256(kd),
                                        _mm256_castpd_si256(_mm256_set1_pd(kShifter)));
    const __m256i bits =
        _mm256_slli_epi64(_mm256_add_epi64(ki, _mm256_set1_epi64x(1023)), 52);
    const __m256d result = _mm256_mul_pd(poly, _mm256_castsi256_pd(bits));
    return _mm256_andnot_pd(big, result);
}

inline void ExpNegative4(const double* in, double* result4) {
    _mm256_storeu_pd(result4, ExpNegativeLanes(_mm256_loadu_pd(in)));
}

/// NaturalLog's four lanes: ln of each lane of wv (positive and normal; see NaturalLog).
inline __m256d LogLanes(__m256d wv) {
    constexpr double kLn2Hi = 6.93147180369123816490e-01,
                     kLn2Lo = 1.90821492927058770002e-10, kTwo52 = 4503599627370496.0;
    const __m256i bits = _mm256_castpd_si256(wv);
    // w = 2^(E - 1023) m, m in [1, 2) (E the biased exponent), then m in [sqrt(1/2),
    // sqrt(2)) with E one larger where it was halved.
    const __m256i biased = _mm256_srli_epi64(bits, 52);
    __m256d m = _mm256_castsi256_pd(
        _mm256_or_si256(_mm256_and_si256(bits, _mm256_set1_epi64x(0x000FFFFFFFFFFFFFLL)),
                        _mm256_set1_epi64x(0x3FF0000000000000LL)));
    const __m256d halve =
        _mm256_cmp_pd(m, _mm256_set1_pd(1.4142135623730951), _CMP_GT_OQ);
    m = _mm256_blendv_pd(m, _mm256_mul_pd(m, _mm256_set1_pd(0.5)), halve);
    // E as a double: its bits in the mantissa of 2^52 (exact), less 2^52 + 1023.
    __m256d e = _mm256_sub_pd(_mm256_castsi256_pd(_mm256_or_si256(
                                  biased, _mm256_castpd_si256(_mm256_set1_pd(kTwo52)))),
                              _mm256_set1_pd(kTwo52 + 1023.0));
    e = _mm256_add_pd(e, _mm256_and_pd(halve, _mm256_set1_pd(1.0)));
    // ln m = 2 atanh(s) = 2 s sum z^j / (2 j + 1), s = (m - 1) / (m + 1), z = s^2 <=
    // 0.0295: terms to j = 10 (the rest below 1e-18 relative), by Estrin's scheme.
    const __m256d one = _mm256_set1_pd(1.0);
    const __m256d sv = _mm256_div_pd(_mm256_sub_pd(m, one), _mm256_add_pd(m, one));
    const __m256d z = _mm256_mul_pd(sv, sv), z2 = _mm256_mul_pd(z, z),
                  z4 = _mm256_mul_pd(z2, z2), z8 = _mm256_mul_pd(z4, z4);
    auto pair = [&](int j) {
        return _mm256_fmadd_pd(_mm256_set1_pd(1.0 / (2 * j + 3)), z,
                               _mm256_set1_pd(1.0 / (2 * j + 1)));
    };
    const __m256d a0 = _mm256_fmadd_pd(pair(2), z2, pair(0));
    const __m256d a1 = _mm256_fmadd_pd(pair(6), z2, pair(4));
    const __m256d a2 = _mm256_fmadd_pd(_mm256_set1_pd(1.0 / 21), z2, pair(8));
    const __m256d poly = _mm256_fmadd_pd(a2, z8, _mm256_fmadd_pd(a1, z4, a0));
    const __m256d lnm = _mm256_mul_pd(_mm256_add_pd(sv, sv), poly);
    return _mm256_fmadd_pd(e, _mm256_set1_pd(kLn2Hi),
                           _mm256_fmadd_pd(e, _mm256_set1_pd(kLn2Lo), lnm));
}
#endif

}  // namespace

// x = k ln 2 - r with |r| <= ln 2 / 2, e^-r by its Taylor polynomial of degree 13 (error
// below 1e-17), times 2^-k built in the exponent bits; four lanes at a time where AVX2 is
// available (all of them, the last partly filled: out[i] depends on x[i] alone, not on n
// or i).
void ExpNegative(const double* x, int n, double* out) {
#if defined(__AVX2__) && defined(__FMA__)
    int i = 0;
    for (; i + 4 <= n; i += 4) ExpNegative4(x + i, out + i);
    if (i < n) {
        // The last n % 4 through the same lanes: each value independent of its position.
        alignas(32) double in4[4] = {0, 0, 0, 0}, out4[4];
        for (int k = i; k < n; ++k) in4[k - i] = x[k];
        ExpNegative4(in4, out4);
        for (int k = i; k < n; ++k) out[k] = out4[k - i];
    }
#else
    for (int i = 0; i < n; ++i) out[i] = x[i] > 708.0 ? 0.0 : std::exp(-x[i]);
#endif
}

// See volume_ray.h: Estrin's scheme below d = 0.5, exp above.
void PieceOpacity(double d, double& opacity, double& attenuation) {
    if (d < 0.5) {
        const double x = -d;
        // c_k = 1 / (k + 1)! for the term x^k.
        const double* c = kInverseFactorial + 1;
        auto pair = [&](int k) { return std::fma(c[k + 1], x, c[k]); };
        const double x2 = x * x, x4 = x2 * x2, x8 = x4 * x4, x16 = x8 * x8;
        const double a0 = std::fma(pair(2), x2, pair(0)),
                     a1 = std::fma(pair(6), x2, pair(4));
        const double a2 = std::fma(pair(10), x2, pair(8)),
                     a3 = std::fma(pair(14), x2, pair(12));
        const double b0 = std::fma(a1, x4, a0), b1 = std::fma(a3, x4, a2);
        const double sum = std::fma(c[16], x16, std::fma(b1, x8, b0));
        opacity = d * sum;
        attenuation = 1 - opacity;
    } else {
        attenuation = std::exp(-d);
        opacity = 1 - attenuation;
    }
}

// ln w = E ln 2 + ln m, E the binary exponent and m in [sqrt(1/2), sqrt(2)): ln m by the
// series of 2 atanh((m - 1) / (m + 1)); the rounding is that of the few last operations.
void NaturalLog(const double* x, int n, double* out) {
#if defined(__AVX2__) && defined(__FMA__)
    int i = 0;
    for (; i + 4 <= n; i += 4)
        _mm256_storeu_pd(out + i, LogLanes(_mm256_loadu_pd(x + i)));
    if (i < n) {
        alignas(32) double in4[4] = {1, 1, 1, 1}, out4[4];
        for (int k = i; k < n; ++k) in4[k - i] = x[k];
        _mm256_store_pd(out4, LogLanes(_mm256_load_pd(in4)));
        for (int k = i; k < n; ++k) out[k] = out4[k - i];
    }
#else
    for (int i = 0; i < n; ++i) out[i] = std::log(x[i]);
#endif
}

bool MakePyramidDepthLine(const PyramidLine& p, double cellScale, double sumV,
                          PyramidDepthLine& out) {
    if (p.k == 0 || !(p.u0 > 0) || !(p.half > 0)) return false;
    // The pole, where U = 0, at x = -1 / rho. Far from the segment the field is nearly a
    // quadratic whose series is short (and the partial fractions below lose what it
    // gains); within 1/1024 of the segment's half-length the depth's logarithm runs away.
    const double rho = p.u1 / p.u0, arho = std::abs(rho);
    if (!(arho >= kPyramidFarPole && arho <= 1 - kPyramidNearPole)) return false;
    // R S / U = alpha x + beta + gamma / U, so the field is mean + (l1 + k alpha) x + k
    // gamma / U with mean = l0 + k beta, and its antiderivative less the mean, in t, is V
    // = half (a2 x^2 + g ln(U / u0)) with a2 = (l1 + k alpha) / 2, g = k gamma / u1.
    const double alpha = p.r1 * p.s1 / p.u1;
    const double beta = (p.r0 * p.s1 + p.r1 * p.s0 - alpha * p.u0) / p.u1;
    const double gamma = p.r0 * p.s0 - beta * p.u0;
    out.a2 = 0.5 * (p.l1 + p.k * alpha);
    out.g = p.k * gamma / p.u1;
    out.rho = rho;
    out.mean = p.l0 + p.k * beta;
    // The rounding of V, from the magnitudes of the terms each quantity sums (ma, mb, mc
    // for alpha, beta, gamma; each computed within a few eps of its magnitude): of a2, of
    // g, of the logarithm (NaturalLog's, and 1 + rho x within eps / (1 - |rho|) of its
    // relative size), of the sum, and of the mean (which moves V by half its error at
    // most). Twice that.
    const double au1 = std::abs(p.u1), ak = std::abs(p.k);
    const double ma = std::abs(alpha);
    const double mb = (std::abs(p.r0 * p.s1) + std::abs(p.r1 * p.s0) + ma * p.u0) / au1;
    const double mc = std::abs(p.r0 * p.s0) + mb * p.u0;
    // The largest |ln(1 + rho x)| on [-1, 1], -ln(1 - |rho|), is at most |rho| / (1 -
    // |rho|).
    const double lnMax = arho / (1 - arho);
    const double g = std::abs(out.g);
    const double dA2 = 4 * kEps * (std::abs(p.l1) + ak * ma);
    const double dG = 24 * kEps * ak * mc / au1;
    const double dLn = 4 * kEps + 2 * kEps / (1 - arho);
    const double dMean = 12 * kEps * (std::abs(p.l0) + ak * mb);
    out.depthError =
        2 * p.half *
        (dA2 + dG * lnMax + g * dLn + 4 * kEps * (std::abs(out.a2) + g * lnMax) + dMean);
    // The field at a point of the segment: R / U, S / U and R S / U are at most 1 there,
    // so each product and quotient adds a few eps of the terms l0, l1 x and k; the
    // coefficients are rounded as a sampled point's reference coordinates are
    // (kSampleRounding of the cell's values, as for the series).
    const double terms = std::abs(p.l0) + std::abs(p.l1) +
                         ak * (3 + std::abs(p.r0) + std::abs(p.r1) + std::abs(p.s0) +
                               std::abs(p.s1) + p.u0 + au1);
    out.fieldError = kSampleRounding * kEps * cellScale + 8 * kEps * terms;
    // No worse than the series: its depth line is rounded to kSeriesRounding eps of its
    // coefficients, about half the cell's values.
    return out.depthError <= kPyramidRounding * kEps * p.half * sumV &&
           out.fieldError <=
               kSampleRounding * kEps * cellScale + kPyramidRounding * kEps * sumV;
}

namespace {
#if defined(__AVX2__) && defined(__FMA__)
/// PyramidLineAt for four points t[0..3].
inline void PyramidLineAt4(const PyramidLine& p, const PyramidDepthLine& d,
                           const double* t, double* out, double* depth) {
    const __m256d x =
        _mm256_mul_pd(_mm256_sub_pd(_mm256_loadu_pd(t), _mm256_set1_pd(p.mid)),
                      _mm256_set1_pd(p.inverseHalf));
    // PyramidLine::AtX's operations lane by lane (no fused multiply-adds).
    const __m256d rs = _mm256_mul_pd(
        _mm256_add_pd(_mm256_set1_pd(p.r0), _mm256_mul_pd(_mm256_set1_pd(p.r1), x)),
        _mm256_add_pd(_mm256_set1_pd(p.s0), _mm256_mul_pd(_mm256_set1_pd(p.s1), x)));
    const __m256d q = _mm256_div_pd(
        rs, _mm256_add_pd(_mm256_set1_pd(p.u0), _mm256_mul_pd(_mm256_set1_pd(p.u1), x)));
    _mm256_storeu_pd(out,
                     _mm256_add_pd(_mm256_add_pd(_mm256_set1_pd(p.l0),
                                                 _mm256_mul_pd(_mm256_set1_pd(p.l1), x)),
                                   _mm256_mul_pd(_mm256_set1_pd(p.k), q)));
    if (depth) {
        const __m256d ln = LogLanes(
            _mm256_add_pd(_mm256_set1_pd(1.0), _mm256_mul_pd(_mm256_set1_pd(d.rho), x)));
        const __m256d sum =
            _mm256_add_pd(_mm256_mul_pd(_mm256_set1_pd(d.a2), _mm256_mul_pd(x, x)),
                          _mm256_mul_pd(_mm256_set1_pd(d.g), ln));
        _mm256_storeu_pd(depth, _mm256_mul_pd(_mm256_set1_pd(p.half), sum));
    }
}
#endif
}  // namespace

namespace {
#if defined(__AVX2__) && defined(__FMA__)
/// at4(t, out, depth) for the n points t (four at a time; the rest through the same
/// lanes, padded with `filler`: each value independent of its position).
template <typename At4>
inline void InLanesOfFour(const double* t, int n, double* out, double* depth,
                          double filler, At4&& at4) {
    int i = 0;
    for (; i + 4 <= n; i += 4) at4(t + i, out + i, depth ? depth + i : nullptr);
    if (i < n) {
        const int rest = std::min(n - i, 3);
        alignas(32) double t4[4] = {filler, filler, filler, filler}, out4[4], depth4[4];
        for (int k = 0; k < rest; ++k) t4[k] = t[i + k];
        at4(t4, out4, depth ? depth4 : nullptr);
        for (int k = 0; k < rest; ++k) {
            out[i + k] = out4[k];
            if (depth) depth[i + k] = depth4[k];
        }
    }
}
#endif
}  // namespace

void PyramidLineAt(const PyramidLine& p, const PyramidDepthLine& d, const double* t,
                   int n, double* out, double* depth) {
#if defined(__AVX2__) && defined(__FMA__)
    InLanesOfFour(t, n, out, depth, p.mid, [&](const double* t4, double* o4, double* d4) {
        PyramidLineAt4(p, d, t4, o4, d4);
    });
#else
    for (int i = 0; i < n; ++i) {
        const double x = (t[i] - p.mid) * p.inverseHalf;
        out[i] = p.AtX(x);
        double ln;
        const double w = 1.0 + d.rho * x;
        NaturalLog(&w, 1, &ln);
        if (depth) depth[i] = p.half * (d.a2 * (x * x) + d.g * ln);
    }
#endif
}

void PyramidLevelCrossings(const PyramidLine& p, double level, double tEnter,
                           double tExit, std::vector<double>& out) {
    // f = level where h(x) = (l0 - level + l1 x) U + k R S = 0 (U > 0 on the segment): a
    // quadratic a2 x^2 + a1 x + a0, its roots by the stable formula, each polished by
    // Newton's method on h in product form.
    const double c = p.l0 - level;
    const double a2 = p.l1 * p.u1 + p.k * (p.r1 * p.s1);
    const double a1 = c * p.u1 + p.l1 * p.u0 + p.k * (p.r0 * p.s1 + p.r1 * p.s0);
    const double a0 = c * p.u0 + p.k * (p.r0 * p.s0);
    double roots[2];
    const int count = QuadraticRoots(a2, a1, a0, roots);
    for (int r = 0; r < count; ++r) {
        double x = roots[r];
        if (!(std::abs(x) < 1.001)) continue;
        for (int step = 0; step < 2; ++step) {
            const double R = p.r0 + p.r1 * x, S = p.s0 + p.s1 * x, U = p.u0 + p.u1 * x;
            const double line = c + p.l1 * x;
            const double h = line * U + p.k * (R * S);
            const double dh = p.l1 * U + line * p.u1 + p.k * (p.r1 * S + R * p.s1);
            if (h == 0 || dh == 0) break;
            const double next = x - h / dh;
            if (!(std::abs(next - x) < 1e-3)) break;
            x = next;
        }
        const double t = p.mid + p.half * x;
        if (t > tEnter && t < tExit) out.push_back(t);
    }
}

namespace {
#if defined(__AVX2__) && defined(__FMA__)
/// PolyLineAt for four points t[0..3].
inline void PolyLineAt4(const PolyLine& p, const double* t, double* out, double* depth) {
    const __m256d x =
        _mm256_mul_pd(_mm256_sub_pd(_mm256_loadu_pd(t), _mm256_set1_pd(p.mid)),
                      _mm256_set1_pd(p.inverseHalf));
    // PolyLine::AtX's operations lane by lane (no fused multiply-adds).
    __m256d f =
        _mm256_add_pd(_mm256_mul_pd(_mm256_set1_pd(p.m[3]), x), _mm256_set1_pd(p.m[2]));
    f = _mm256_add_pd(_mm256_mul_pd(f, x), _mm256_set1_pd(p.m[1]));
    f = _mm256_add_pd(_mm256_mul_pd(f, x), _mm256_set1_pd(p.m[0]));
    _mm256_storeu_pd(out, f);
    if (depth) {
        __m256d v = _mm256_add_pd(_mm256_mul_pd(_mm256_set1_pd(0.25 * p.m[3]), x),
                                  _mm256_set1_pd(p.m[2] / 3));
        v = _mm256_add_pd(_mm256_mul_pd(v, x), _mm256_set1_pd(0.5 * p.m[1]));
        v = _mm256_mul_pd(v, _mm256_mul_pd(x, x));
        _mm256_storeu_pd(depth, _mm256_mul_pd(_mm256_set1_pd(p.half), v));
    }
}
#endif
}  // namespace

void PolyLineAt(const PolyLine& p, const double* t, int n, double* out, double* depth) {
#if defined(__AVX2__) && defined(__FMA__)
    InLanesOfFour(t, n, out, depth, p.mid, [&](const double* t4, double* o4, double* d4) {
        PolyLineAt4(p, t4, o4, d4);
    });
#else
    for (int i = 0; i < n; ++i) {
        const double x = (t[i] - p.mid) * p.inverseHalf;
        out[i] = p.AtX(x);
        if (depth)
            depth[i] = p.half * ((((0.25 * p.m[3]) * x + p.m[2] / 3) * x + 0.5 * p.m[1]) *
                                 (x * x));
    }
#endif
}

int QuadraticRoots(double a, double b, double c, double out[2]) {
    // The stable formula (no cancellation between -b and the root of the discriminant).
    int n = 0;
    if (a == 0) {
        if (b != 0) out[n++] = -c / b;
    } else {
        const double disc = b * b - 4 * a * c;
        if (disc >= 0) {
            const double q = -0.5 * (b + std::copysign(std::sqrt(disc), b));
            out[n++] = q / a;
            if (q != 0) out[n++] = c / q;
        }
    }
    return n;
}

int QuadraticRootsInside(double a, double b, double c, double out[2]) {
    double x[2];
    const int n = QuadraticRoots(a, b, c, x);
    if (n == 2 && x[1] < x[0]) std::swap(x[0], x[1]);
    int count = 0;
    for (int k = 0; k < n; ++k)
        if (x[k] > -1 && x[k] < 1 && (count == 0 || x[k] > out[count - 1]))
            out[count++] = x[k];
    return count;
}

int PolyCriticalPoints(const PolyLine& p, double out[2]) {
    return QuadraticRootsInside(3 * p.m[3], 2 * p.m[2], p.m[1], out);
}

PolyLine MakePolyLine(double t0, double t1, const double* mono, int degree) {
    PolyLine p;
    p.mid = 0.5 * (t0 + t1);
    p.half = 0.5 * (t1 - t0);
    p.inverseHalf = 1 / p.half;
    for (int k = 0; k < 4; ++k) p.m[k] = k <= degree ? mono[k] : 0.0;
    return p;
}

void PolyLevelCrossings(const PolyLine& p, double level, double tEnter, double tExit,
                        std::vector<double>& out) {
    const double* m = p.m;
    // Split at the critical points in (-1, 1).
    double points[4];
    int count = 0;
    points[count++] = -1;
    count += PolyCriticalPoints(p, points + 1);
    points[count++] = 1;
    // Between them the polynomial is monotone: a level strictly between the end values is
    // crossed once, found by Newton's method kept inside the bracket (bisection where it
    // leaves it), to a step of a few ulps of [-1, 1].
    auto g = [&](double x) { return p.AtX(x) - level; };
    double ga = g(points[0]);
    for (int k = 0; k + 1 < count; ++k) {
        const double xa = points[k], xb = points[k + 1], gb = g(xb);
        if ((ga < 0 && gb > 0) || (ga > 0 && gb < 0)) {
            double lo = xa, hi = xb, glo = ga;
            double x = xa - ga * (xb - xa) / (gb - ga);
            if (!(x > lo && x < hi)) x = 0.5 * (lo + hi);
            for (int it = 0; it < 100; ++it) {
                const double gx = g(x);
                if (gx == 0) break;
                if ((gx < 0) == (glo < 0)) {
                    lo = x;
                    glo = gx;
                } else {
                    hi = x;
                }
                const double d = (3 * m[3] * x + 2 * m[2]) * x + m[1];
                double next = d != 0 ? x - gx / d : 0.5 * (lo + hi);
                if (!(next > lo && next < hi)) next = 0.5 * (lo + hi);
                const bool done = std::abs(next - x) <= 4 * kEps || hi - lo <= 4 * kEps;
                x = next;
                if (done) break;
            }
            const double t = p.mid + p.half * x;
            if (t > tEnter && t < tExit) out.push_back(t);
        }
        ga = gb;
    }
}

void SeriesCrossings(const LegendreSeries& p, const double* levels, int count, double tol,
                     const double* sampleT, const double* sampleV, int samples,
                     std::vector<double>& scratch, std::vector<double>& points,
                     LegendreSeries& derivative, std::vector<double>& out) {
    if (count == 0 || !(p.b > p.a)) return;
    // |p - c_0| <= sum_{k>=1} |c_k| on [a, b]: levels outside that range are not crossed.
    const double tail = p.Tail();
    if (std::none_of(levels, levels + count, [&](double level) {
            return std::abs(level - p.c[0]) <= tail;
        }))
        return;
    // Split [a, b] at the critical points of p: the roots of p', isolated on its series
    // (a window is passed over only where |p'| provably exceeds its rounding).
    points.clear();
    points.push_back(p.a);
    if (p.Degree() >= 2) {
        LegendreSeries& d = derivative;
        p.Derivative(d);
        double sum = 0;
        for (double c : d.c) sum += std::abs(c);
        const double slopeEps = kSeriesRounding * kEps * sum;
        if (detail::TailExcluded(d, 0.0) <= slopeEps) {
            detail::IsolateRoots(d, 0.0, slopeEps, tol, scratch,
                                 [&](double lo, double hi, int kind, double tStar) {
                                     double t = tStar;
                                     if (kind == 1) {
                                         const double dlo = d(lo), dhi = d(hi);
                                         t = (dlo < 0) != (dhi < 0) && dlo != 0 && dhi != 0
                                                 ? detail::PolishSeriesRoot(d, lo, hi, dlo,
                                                                            dhi, tol)
                                                 : 0.5 * (lo + hi);
                                     }
                                     if (t > points.back() && t < p.b) points.push_back(t);
                                     return false;
                                 });
        }
    }
    points.push_back(p.b);
    // On each interval between them p is monotone: a level strictly between the end
    // values is crossed once.
    const double noise = 2 * kEps * (std::abs(p.c[0]) + tail);
    double vlo = p.At(points[0]);
    for (std::size_t k = 0; k + 1 < points.size(); ++k) {
        const double lo = points[k], hi = points[k + 1], vhi = p.At(hi);
        const double vmin = std::min(vlo, vhi), vmax = std::max(vlo, vhi);
        for (int m = 0; m < count; ++m) {
            const double level = levels[m];
            if (!(level > vmin && level < vmax)) continue;
            // Newton's start: where the samples inside [lo, hi] change sides, linearly.
            double guess = std::numeric_limits<double>::quiet_NaN();
            for (int i = 0; i + 1 < samples; ++i) {
                if (sampleT[i + 1] < lo || sampleT[i] > hi) continue;
                const double fa = sampleV[i] - level, fb = sampleV[i + 1] - level;
                if ((fa < 0) != (fb < 0)) {
                    guess = sampleT[i] + (sampleT[i + 1] - sampleT[i]) * (fa / (fa - fb));
                    break;
                }
            }
            const double t = MonotoneRoot(p, level, lo, hi, vlo - level, vhi - level, guess,
                                          tol, noise);
            if (t > p.a && t < p.b) out.push_back(t);
        }
        vlo = vhi;
    }
}

PiecewiseLinearTf MakeColorTf(const std::vector<ColorControlPoint>& points) {
    std::vector<double> s, v;
    for (const ColorControlPoint& p : points) {
        s.push_back(p.scalar);
        v.insert(v.end(), p.rgb.begin(), p.rgb.end());
    }
    return PiecewiseLinearTf(std::move(s), std::move(v), 3);
}

void LagrangeHexDegreeTail(int p, const double* u, double* tail) {
    HPRAY_CHECK(p >= 1 && p <= kMaxOrder);
    HexDegreeTail(p, u, LegendreFromEquispacedCached(p), tail);
}

float LinearTetGradientBound(const double* points, const double* u,
                             const std::int64_t* ids) {
    const double* p0 = points + 3 * ids[0];
    double e[3][3], du[3];
    double scale = 1;
    for (int k = 0; k < 3; ++k) {
        const double* pk = points + 3 * ids[k + 1];
        for (int d = 0; d < 3; ++d) e[k][d] = pk[d] - p0[d];
        du[k] = u[ids[k + 1]] - u[ids[0]];
        scale *= std::abs(e[k][0]) + std::abs(e[k][1]) + std::abs(e[k][2]);
    }
    double cof[3][3];
    const double det = EdgeCofactors(e, cof);
    if (!(std::abs(det) > 1e-6 * scale)) return std::numeric_limits<float>::quiet_NaN();
    // grad = E^-1 du (Cramer). With |det| above 1e-6 of the rows' product, the rounding
    // of the edges, the cofactors and the quotient stays far below 1e-6 relative.
    double g2 = 0;
    for (int d = 0; d < 3; ++d) {
        const double g =
            (cof[0][d] * du[0] + cof[1][d] * du[1] + cof[2][d] * du[2]) / det;
        g2 += g * g;
    }
    const double bound = std::sqrt(g2) * (1 + 1e-6);
    if (!std::isfinite(bound)) return std::numeric_limits<float>::quiet_NaN();
    float f = static_cast<float>(bound);
    if (static_cast<double>(f) < bound)
        f = std::nextafter(f, std::numeric_limits<float>::infinity());
    return f;
}

VolumeSetup MakeVolumeSetup(const Mesh& mesh, const Scene& scene, FieldCache& cache) {
    HPRAY_CHECK(scene.volume.has_value());
    const SceneVolume& vol = *scene.volume;
    const std::string source = scene.sourcePath.empty() ? "scene" : scene.sourcePath;
    VolumeSetup s;
    s.glow = vol.glow;
    s.colorTf = MakeColorTf(vol.colorTf);
    s.extinctionTf = ExtinctionTf(vol.extinctionTf);
    auto resolve = [&](const std::string& name, const std::string& key) {
        const auto sel = SelectScalar(mesh, name);
        if (!sel) throw InputError(source, key, "the mesh has no field '" + name + "'");
        return *sel;
    };
    s.fields[0] = resolve(vol.colorField, "volume.color_field");
    if (vol.extinctionField.empty()) {
        s.fields[1] = s.fields[0];
    } else {
        s.fields[1] = resolve(vol.extinctionField, "volume.extinction_field");
    }
    s.sameField = s.fields[0].field == s.fields[1].field &&
                  s.fields[0].component == s.fields[1].component;
    const int count = s.sameField ? 1 : 2;
    const std::int64_t cells = mesh.CellCount();
    for (int f = 0; f < count; ++f) {
        const ScalarSelector sel = s.fields[f];
        s.ranges.push_back(cache.Ranges(sel));
        s.data.push_back(sel.field->association == Association::Point ? cache.Data(sel)
                                                                       : nullptr);
        const auto r = sel.field->Range(sel.component);
        s.fieldScale.push_back(std::max(std::abs(r[0]), std::abs(r[1])));
        if (s.data[f]) s.pointValues[f] = s.data[f]->PointValues();
    }
    // The top coefficient of each Lagrange hexahedron (see VolumeSetup::topCoefficient):
    // the tensor divided difference of the nodal values at the equispaced y nodes.
    s.topCoefficient.resize(count);
    int maxHexOrder = 0;  // of the Lagrange hexahedra; none: both tables left empty
    for (std::int64_t c = 0; c < cells; ++c)
        if (mesh.cellShape[c] == CellShape::Hex &&
            mesh.cellFamily[c] == CellFamily::Lagrange)
            maxHexOrder = std::max<int>(maxHexOrder, mesh.cellOrder[c]);
    const bool anyLagrangeHex = maxHexOrder > 0;
    for (int f = 0; f < count; ++f) {
        if (!s.data[f] || !anyLagrangeHex) continue;
        const FieldCellData& data = *s.data[f];
        s.topCoefficient[f].assign(cells, 0.0);
        tbb::parallel_for(
            tbb::blocked_range<std::int64_t>(0, cells, 256),
            [&](const tbb::blocked_range<std::int64_t>& range) {
                using LD = long double;
                for (std::int64_t c = range.begin(); c < range.end(); ++c) {
                    if (mesh.cellShape[c] != CellShape::Hex ||
                        mesh.cellFamily[c] != CellFamily::Lagrange)
                        continue;
                    const int p = mesh.cellOrder[c], n = p + 1;
                    // Divided-difference weights 1 / prod_{m != i} (y_i - y_m), y_i = 2i/p - 1.
                    LD w[kMaxOrder + 1];
                    for (int i = 0; i < n; ++i) {
                        LD prod = 1;
                        for (int m = 0; m < n; ++m)
                            if (m != i) prod *= LD(2 * (i - m)) / p;
                        w[i] = 1 / prod;
                    }
                    const double* u = data.values.data() + mesh.cellOffsets[c];
                    LD sum = 0;
                    for (int k = 0; k < n; ++k)
                        for (int j = 0; j < n; ++j)
                            for (int i = 0; i < n; ++i)
                                sum += w[i] * w[j] * w[k] * LD(u[i + n * (j + n * k)]);
                    // Leading coefficient of P_3p: prod_{k=1}^{3p} (2k - 1) / k.
                    LD lead = 1;
                    for (int k = 1; k <= 3 * p; ++k) lead *= LD(2 * k - 1) / k;
                    s.topCoefficient[f][c] = double(std::abs(sum) / lead);
                }
            });
    }
    // Degree tails of the Lagrange hexahedra (see VolumeSetup::degreeTail).
    s.degreeTail.resize(count);
    s.tailStride = 3 * maxHexOrder + 1;
    for (int f = 0; f < count; ++f) {
        if (!s.data[f] || !anyLagrangeHex) continue;
        const FieldCellData& data = *s.data[f];
        s.degreeTail[f].assign(std::size_t(cells) * s.tailStride, 0.0);
        tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, cells, 256),
                          [&](const tbb::blocked_range<std::int64_t>& range) {
                              for (std::int64_t c = range.begin(); c < range.end(); ++c) {
                                  if (mesh.cellShape[c] != CellShape::Hex ||
                                      mesh.cellFamily[c] != CellFamily::Lagrange)
                                      continue;
                                  const int p = mesh.cellOrder[c];
                                  LagrangeHexDegreeTail(
                                      p, data.values.data() + mesh.cellOffsets[c],
                                      s.degreeTail[f].data() + s.tailStride * c);
                              }
                          });
    }
    // Gradient bounds of the linear tetrahedra (see VolumeSetup::gradientBound), kept
    // by the cache.
    for (int f = 0; f < count; ++f)
        if (s.pointValues[f]) s.gradientBound[f] = cache.GradientBounds(s.fields[f]);
    s.cellKind.assign(cells, VolumeSetup::kVarying);
    tbb::parallel_for(
        tbb::blocked_range<std::int64_t>(0, cells, 4096),
        [&](const tbb::blocked_range<std::int64_t>& range) {
            for (std::int64_t c = range.begin(); c < range.end(); ++c) {
                const Interval& rc = (*s.ranges[0])[c];
                const Interval& re = (*s.ranges[count - 1])[c];
                double eMin, eMax, cMin[3], cMax[3];
                s.extinctionTf.RangeOver(re.lo, re.hi, &eMin, &eMax);
                s.colorTf.RangeOver(rc.lo, rc.hi, cMin, cMax);
                const bool glowZero = std::max({cMax[0], cMax[1], cMax[2]}) <= 0;
                if (eMax <= 0 && (s.glow == GlowModel::WilliamsMax || glowZero)) {
                    s.cellKind[c] = VolumeSetup::kEmpty;
                } else if (eMin == eMax && cMin[0] == cMax[0] && cMin[1] == cMax[1] &&
                           cMin[2] == cMax[2]) {
                    s.cellKind[c] = VolumeSetup::kConstant;
                }
            }
        });
    s.breakpoints = s.colorTf.Scalars();
    s.breakpoints.insert(s.breakpoints.end(), s.extinctionTf.Scalars().begin(),
                         s.extinctionTf.Scalars().end());
    std::sort(s.breakpoints.begin(), s.breakpoints.end());
    s.breakpoints.erase(std::unique(s.breakpoints.begin(), s.breakpoints.end()),
                        s.breakpoints.end());
    s.shortBreakpoints.Set(s.breakpoints);
    s.colorMax = std::max(0.0, s.colorTf.MaxValue());
    s.extinctionSlope = s.extinctionTf.MaxSlope();
    s.colorSlope = s.colorTf.MaxSlope();
    s.mappingTolerance = scene.accuracy.mappingTolerance;
    const SceneAccuracy& acc = scene.accuracy;
    s.tolerance = acc.volumeTolerance;
    s.projection.tolerance = acc.projectionTolerance;
    if (acc.projectionOrder > 0) {
        s.projection.startDegree = acc.projectionOrder;
        s.projection.maxDegree = acc.projectionOrder;
    }
    s.roots.rootTolerance = acc.rootTolerance;
    s.inversion.tolerance = acc.mappingTolerance;
    return s;
}

void VolumeRayMarcher::BeginRay(const VolumeSetup& setup, const Ray& ray, double tStart,
                                double tEnd) {
    setup_ = &setup;
    ray_ = ray;
    tStart_ = tStart;
    tEnd_ = tEnd;
    pathLength_ = std::max(tEnd - tStart, std::numeric_limits<double>::min());
    kronrodIntervals_ = 0;
    // Each ray starts from the same state: its pixel must not depend on the rays the
    // thread integrated before (tiles and threads may take any rays).
    for (FacePointSums& sums : faceSums_)
        sums.t = std::numeric_limits<double>::quiet_NaN();
    startTau_ = 0;
    for (int c = 0; c < 3; ++c) startEmission_[c] = endEmission_[c] = 0;
    lastColor_ = lastExtinction_ = TfValue{};
    queued_ = 0;
    linearTetField_ = setup.sameField && setup.pointValues[0] &&
                      setup.fields[0].field->association != Association::Cell &&
                      setup.gradientBound[0] && !setup.gradientBound[0]->empty();
    groupable_ = linearTetField_ && setup.colorTf.ShortScalars().valid &&
                 setup.extinctionTf.ShortScalars().valid &&
                 setup.colorTf.Channels() == 3 && setup.extinctionTf.Channels() == 1;
    if ((setup.gradientBound[0] && !setup.gradientBound[0]->empty()) ||
        (setup.gradientBound[1] && !setup.gradientBound[1]->empty())) {
        // In the frame (x, y, z) = (a_kx - sx a_kz, a_ky - sy a_kz, sz a_kz) of world
        // offsets a: d/dx = d/da_kx, d/dy = d/da_ky, d/dz = (sx d/da_kx + sy d/da_ky +
        // d/da_kz) / sz; each world component is at most the gradient's norm. Rounded up
        // by a relative 1e-15.
        const trace::RayFrame frame(ray);
        frameGradient_[0] = frameGradient_[1] = 1;
        frameGradient_[2] = (1 + std::abs(frame.sx) + std::abs(frame.sy)) /
                            std::abs(frame.sz) * (1 + 1e-15);
    }
}

void VolumeRayMarcher::RecordEnds(double p0, double p1, double tau0, const double e0[3],
                                  double tau1, const double e1[3],
                                  double transmittanceAtP1) {
    if (p0 == tStart_) {
        startTau_ = tau0;
        for (int c = 0; c < 3; ++c) startEmission_[c] = e0[c];
    }
    if (p1 == tEnd_) {
        (void)tau1;
        for (int c = 0; c < 3; ++c) endEmission_[c] = transmittanceAtP1 * e1[c];
    }
}

void VolumeRayMarcher::FinishRay(RayComposite& composite) const {
    // d pixel / d tStart = -E(tStart) + tau(tStart) * pixel (everything behind is
    // attenuated); d pixel / d tEnd = T(tEnd) E(tEnd). The ends carry a few ulps of t.
    const double dStart = 4 * kEps * std::abs(tStart_), dEnd = 4 * kEps * std::abs(tEnd_);
    for (int c = 0; c < 3; ++c) {
        composite.error[c] +=
            dStart * std::abs(startTau_ * composite.rgba[c] - startEmission_[c]) +
            dEnd * endEmission_[c] + std::abs(composite.signedError[c]);
        composite.signedError[c] = 0;
    }
}

void VolumeRayMarcher::AddFieldError(double length, double depth, double tauMin, double T,
                                     double colorError, double tauError,
                                     RayComposite& composite) const {
    const double own = FieldErrorOwn(length, depth, tauMin, colorError, tauError);
    for (double& e : composite.error) e += T * own;
    // Everything behind is attenuated by the depth error (see RayComposite::AddColor).
    composite.depthError += length * tauError;
}

double VolumeRayMarcher::FieldErrorOwn(double length, double depth, double tauMin,
                                       double colorError, double tauError) const {
    const VolumeSetup& s = *setup_;
    // Emission happens within lambda of the piece's start: integral_0^l exp(-phi) <=
    // lambda. First-order effects of a colour error dc and an extinction error dtau:
    // Williams-Max dc (1 - e^-D) + 2 kappa_max dtau lambda; Wilhelms-Van Gelder
    // dc lambda + g_max dtau lambda^2.
    const double lambda = tauMin * length > 1 ? 1 / tauMin : length;
    return s.glow == GlowModel::WilliamsMax
               ? colorError * std::min(1.0, depth) + 2 * s.colorMax * tauError * lambda
               : (colorError + s.colorMax * tauError * lambda) * lambda;
}

bool VolumeRayMarcher::LinearFromFacePoints(int f, const SegmentEnds& ends) {
    const VolumeSetup& s = *setup_;
    const double* u = s.pointValues[f];
    const FacePoint& in = ends.enter;
    const FacePoint& out = ends.exit;
    // The field's gradient in the ray frame, bounded from the cell's: it only bounds how
    // far the face points may lie off the ray. NaN: a sliver, the cell's own path.
    if (!s.gradientBound[f] || s.gradientBound[f]->empty()) return false;
    const double g = (*s.gradientBound[f])[seg_.cell];
    if (!(g >= 0)) return false;
    const double grad[3] = {g * frameGradient_[0], g * frameGradient_[1],
                            g * frameGradient_[2]};
    // Each face point: the face's linear interpolant at sum w P, whose distance from the
    // ray point at t the face point bounds (FacePoint::off).
    double value[2], error = 0;
    const FacePoint* p[2] = {&in, &out};
    for (int k = 0; k < 2; ++k) {
        const FacePoint& q = *p[k];
        // The entry is the previous segment's exit, mostly: its sums are kept.
        FacePointSums& sums = faceSums_[f];
        if (!(k == 0 && sums.t == q.t && sums.v[0] == q.v[0] && sums.v[1] == q.v[1] &&
              sums.v[2] == q.v[2])) {
            const double uk[3] = {u[q.v[0]], u[q.v[1]], u[q.v[2]]};
            const double au =
                std::max({std::abs(uk[0]), std::abs(uk[1]), std::abs(uk[2])});
            sums.value = q.w[0] * uk[0] + q.w[1] * uk[1] + q.w[2] * uk[2];
            sums.rounding = 4 * kEps * au;
            sums.t = q.t;
            for (int m = 0; m < 3; ++m) sums.v[m] = q.v[m];
        }
        value[k] = sums.value;
        const double off = grad[0] * q.off[0] + grad[1] * q.off[1] + grad[2] * q.off[2];
        // Twice: a margin over the rounding of these sums.
        error = std::max(error, 2 * off + sums.rounding);
    }
    const double t0 = in.t, t1 = out.t;
    const double slope = (value[1] - value[0]) / (t1 - t0);
    FieldState& st = state_[f];
    st.linear = true;
    st.valueEnter = seg_.tEnter == t0 ? value[0] : value[0] + slope * (seg_.tEnter - t0);
    st.valueExit = seg_.tExit == t1 ? value[1] : value[0] + slope * (seg_.tExit - t0);
    st.error = 8 * kEps * s.fieldScale[f] + error;
    return true;
}

bool VolumeRayMarcher::BeginSegment(const Mesh& mesh, const MeshGeometry& geometry,
                                    const Segment& seg, RenderCounters& counters,
                                    const SegmentEnds* ends) {
    const VolumeSetup& s = *setup_;
    seg_ = seg;
    kind_ = s.cellKind[seg.cell];
    crossings_.clear();
    mode_ = Mode::kClosed;
    pyramidLine_ = polyLine_ = false;
    if (kind_ == VolumeSetup::kEmpty) return false;
    if (kind_ == VolumeSetup::kConstant) {
        BeginConstantCell(seg.cell);
        return true;
    }
    fieldCount_ = s.sameField ? 1 : 2;
    bool allLinear = true, allSeries = true;
    for (int f = 0; f < fieldCount_; ++f) {
        FieldState& st = state_[f];
        st = FieldState{};
        const ScalarSelector& sel = s.fields[f];
        if (sel.field->association == Association::Cell) {
            st.constant = st.linear = true;
            st.valueEnter = st.valueExit = ScalarValue(sel, seg.cell);
            continue;
        }
        SegmentField& sf = field_[f];
        truncated_[f] = unresolved_[f] = 0;
        sampleCount_[f] = 0;
        // The exact series' coefficients keep their storage for the next segment's.
        if (!pieces_[f].empty() &&
            pieces_[f][0].p.c.capacity() > spareCoefficients_[f].capacity())
            std::swap(pieces_[f][0].p.c, spareCoefficients_[f]);
        pieces_[f].clear();
        if (ends && ends->enter.Valid() && ends->exit.Valid() && s.pointValues[f] &&
            geometry.IsDerived(seg.cell) && LinearFromFacePoints(f, *ends)) {
            // A linear tetrahedron: the field is linear along the ray, its values at the
            // ends are those of the faces the walk crossed.
            FindCrossings(f, seg, counters);
            continue;
        }
        if (s.data[f]) {
            sf.Begin(*s.data[f], geometry, sel, seg.cell, ray_, s.inversion);
        } else {
            sf.Begin(mesh, geometry, sel, seg.cell, ray_, s.inversion);
        }
        // Rounding of a nodal sum; in curved cells also the inversion tolerance
        // (reference units) times the field's variation over the cell (affine cells map
        // back in closed form, also those whose field is not a polynomial, as pyramids').
        const Interval& range = (*s.ranges[f])[seg.cell];
        st.error = 8 * kEps * s.fieldScale[f];
        if (!sf.Affine()) st.error += 4 * s.mappingTolerance * (range.hi - range.lo);
        if (sf.ExactAlongLine() && BeginPolyLine(f, seg)) {
            // An affine linear hexahedron or wedge: its polynomial, or linear (st set).
        } else if (sf.ExactAlongLine() && sf.LineDegree() <= 1) {
            st.linear = true;
            st.valueEnter = sf(seg.tEnter);
            st.valueExit = sf(seg.tExit);
        } else if (sf.ExactAlongLine()) {
            // A polynomial of known degree along the ray: its interpolant is the field.
            ProjectExact(f, geometry, seg);
            st.bySeries = pieces_[f].size() == 1;
            if (st.bySeries) st.error = std::max(st.error, pieces_[f][0].eps);
            if (st.bySeries) {
                // Linear data on a higher-order cell (e.g. u = x + 2y + 3z on hexes): the
                // closed form applies.
                const ProjectedPiece& p = pieces_[f][0];
                double tail = 0;
                for (std::size_t k = 2; k < p.p.c.size(); ++k) tail += std::abs(p.p.c[k]);
                if (tail <= p.eps) {
                    st.linear = true;
                    st.valueEnter = p.p(seg.tEnter);
                    st.valueExit = p.p(seg.tExit);
                }
            }
        } else if (BeginPyramidLine(f, seg)) {
            // A linear pyramid in closed form.
            st.pyramid = true;
            st.error = std::max(st.error, lineError_[f]);
        } else if (double pole, gap, residue;
                   sf.RationalPole(seg.tEnter, seg.tExit, pole, gap, residue) &&
                   ProjectRational(f, seg, gap, residue)) {
            // A linear pyramid: its rational field's series to below the rounding noise.
            st.bySeries = true;
            st.error = std::max(st.error, pieces_[f][0].eps);
        }
        allLinear = allLinear && st.linear;
        allSeries = allSeries && (st.linear || st.bySeries || st.pyramid || st.poly);
        FindCrossings(f, seg, counters);
        sf.AddCountersTo(counters);
    }
    if (fieldCount_ == 2 && !(state_[0].poly && state_[1].poly) &&
        !(state_[0].pyramid && state_[1].pyramid) &&
        (state_[0].poly || state_[1].poly || state_[0].pyramid || state_[1].pyramid)) {
        // Two fields held differently (a closed form beside a series, a linear or a
        // constant field): the closed forms as series, as without them (the crossings
        // found stand).
        allSeries = true;
        for (int f = 0; f < 2; ++f) {
            FieldState& st = state_[f];
            if (st.poly) {
                st.poly = false;
                SeriesFromPolynomial(f, seg, field_[f].LineDegree(), poly_[f].m,
                                     polyMagnitude_[f]);
                st.bySeries = true;
                st.error = std::max(st.error, pieces_[f][0].eps);
            } else if (st.pyramid) {
                st.pyramid = false;
                if (double pole, gap, residue;
                    field_[f].RationalPole(seg.tEnter, seg.tExit, pole, gap, residue) &&
                    ProjectRational(f, seg, gap, residue)) {
                    st.bySeries = true;
                    st.error = std::max(st.error, pieces_[f][0].eps);
                }
            }
            allSeries = allSeries && (st.linear || st.bySeries);
        }
    }
    mode_ = allLinear ? Mode::kClosed : allSeries ? Mode::kSeries : Mode::kGeneric;
    if (mode_ == Mode::kSeries) {
        for (int f = 0; f < fieldCount_; ++f) {
            const FieldState& st = state_[f];
            if (st.pyramid || st.poly) {
                // lineError_[f] and the depth line set by BeginPyramidLine or
                // BeginPolyLine.
                pyramidLine_ = st.pyramid;
                polyLine_ = st.poly;
                continue;
            }
            // The projected series itself where there is one (not a copy), else line_[f].
            LegendreSeries& line = st.bySeries ? pieces_[f][0].p : line_[f];
            linePtr_[f] = &line;
            if (!st.bySeries) {
                // Constant or linear on the segment.
                line.a = seg.tEnter;
                line.b = seg.tExit;
                line.c.assign(st.constant ? 1 : 2, 0.0);
                line.c[0] = 0.5 * (st.valueEnter + st.valueExit);
                if (!st.constant) line.c[1] = 0.5 * (st.valueExit - st.valueEnter);
            }
            double sum = 0;
            for (double c : line.c) sum += std::abs(c);
            // Rounding of the field's samples (a few eps of the cell's values, from the
            // sum-factorised contraction) and of the series' evaluation, and what the
            // truncation dropped.
            const Interval& range = (*s.ranges[f])[seg.cell];
            const double cellScale = std::max(std::abs(range.lo), std::abs(range.hi));
            lineError_[f] = st.constant ? 0.0
                                        : kSampleRounding * kEps * cellScale +
                                              kSeriesRounding * kEps * sum + truncated_[f] +
                                              unresolved_[f];
        }
        haveDepthLine_ = false;
    }
    std::sort(crossings_.begin(), crossings_.end());
    crossings_.erase(std::unique(crossings_.begin(), crossings_.end()), crossings_.end());
    counters.fieldEvaluations += fieldSamples_;
    fieldSamples_ = 0;
    return true;
}

void VolumeRayMarcher::ProjectExact(int f, const MeshGeometry& geometry,
                                    const Segment& seg) {
    const VolumeSetup& s = *setup_;
    SegmentField& sf = field_[f];
    int n = std::min(sf.LineDegree(), kMaxLegendreDegree);
    if (s.projection.startDegree == s.projection.maxDegree || n < 1) {
        // A pinned projection order (order studies): as the isosurfaces do.
        ProjectionOptions projection = s.projection;
        projection.scaleFloor = s.fieldScale[f];
        projection.exactDegree = sf.LineDegree();
        projectionStats_ = ProjectionStats{};
        ProjectSegment(sf, seg.tEnter, seg.tExit, projection, pieces_[f],
                       projectionStats_, scratch_);
        return;
    }
    // Affine linear hexahedra and wedges: the polynomial along the ray in closed form.
    if (double mono[4], magnitude; n <= 3) {
        int degree = 0;
        if (sf.LinearCellLine(seg.tEnter, seg.tExit, mono, degree, magnitude) &&
            degree == n) {
            SeriesFromPolynomial(f, seg, n, mono, magnitude);
            return;
        }
    }
    // Affine Lagrange hexahedra: the register-blocked kernel on the gathered values.
    const CellGeometry& cell = geometry.Cell(seg.cell, cellScratch_);
    const bool hexKernel = s.data[f] && cell.affine && cell.linearInvertible &&
                           cell.basis->kind == BasisKind::HexLagrange &&
                           cell.basis->polynomial;
    double ref0[3] = {0, 0, 0}, dref[3] = {0, 0, 0};
    unresolved_[f] = 0;
    if (hexKernel) {
        // ref(t) = L^-1 (o + t d - origin).
        const auto& inv = cell.inverseLinear;
        double rel[3];
        for (int i = 0; i < 3; ++i) rel[i] = ray_.origin[i] - cell.origin[i];
        for (int i = 0; i < 3; ++i) {
            ref0[i] = inv[3 * i] * rel[0] + inv[3 * i + 1] * rel[1] + inv[3 * i + 2] * rel[2];
            dref[i] = inv[3 * i] * ray_.dir[0] + inv[3 * i + 1] * ray_.dir[1] +
                      inv[3 * i + 2] * ray_.dir[2];
        }
        // The degree-3p coefficient is known in closed form: where it is below the
        // samples' rounding (about 1e-17 on nk-sinc, whose data is smooth), interpolate at
        // one degree less (3p samples: whole vectors for p = 8) and count what that
        // coefficient adds, at most.
        const int p = cell.basis->order;
        const double length = seg.tExit - seg.tEnter;
        if (n == 3 * p && !s.degreeTail[f].empty()) {
            // The lowest degree whose miss (see VolumeSetup::degreeTail) stays within
            // kDegreeShare of the segment's part of the tolerance, through the steepest
            // slopes of the transfer functions (see AddFieldError: a field error e costs
            // at most e (colour slope + (2 colorMax + 1) extinction slope length)).
            // The slopes are those of the pieces over the cell's range of the field,
            // widened by the miss (which the series may stray by).
            const double* tail = s.degreeTail[f].data() + s.tailStride * seg.cell;
            const Interval& range = (*s.ranges[f])[seg.cell];
            const bool drivesColor = f == 0, drivesExtinction = f == 1 || s.sameField;
            const double allowed = kDegreeShare * s.tolerance * (length / pathLength_);
            auto costOver = [&](double lo, double hi) {
                return (drivesColor ? s.colorTf.SteepestOver(lo, hi) : 0.0) +
                       (drivesExtinction
                            ? (2 * s.colorMax + 1) * s.extinctionTf.SteepestOver(lo, hi) *
                                  length
                            : 0.0);
            };
            // Over the range itself the cost is no larger than over any widening: a
            // degree that fails with it fails (most segments at tight tolerances, one
            // lookup).
            const double least = costOver(range.lo, range.hi);
            // tail[m] falls with m: where the highest candidate's fails, all do (one
            // load of the cell's tail, not one per candidate).
            int highest = -1;
            for (int m : kSampledDegrees)
                if (m < n - 1) highest = m;
            const bool any =
                highest >= 0 && !(kLebesgueBound * tail[highest] * least > allowed);
            for (int m : kSampledDegrees) {
                if (!any || m >= n - 1) break;
                const double miss = kLebesgueBound * tail[m];
                if (miss * least > allowed) continue;
                if (miss * costOver(range.lo - miss, range.hi + miss) <= allowed) {
                    n = m;
                    unresolved_[f] = kLebesgueBound * tail[m];
                    break;
                }
            }
        }
        if (n == 3 * p && p >= 2 && !s.topCoefficient[f].empty()) {
            double base = std::abs(dref[0] * length * dref[1] * length * dref[2] * length);
            double top = s.topCoefficient[f][seg.cell];
            for (int k = p; k > 0; k >>= 1, base *= base)  // top * base^p by squaring
                if (k & 1) top *= base;
            const Interval& range = (*s.ranges[f])[seg.cell];
            const double hidden =
                kEps * std::max(std::abs(range.lo), std::abs(range.hi));
            if (kLebesgueBound * top <= hidden) {
                n -= 1;
                unresolved_[f] = kLebesgueBound * top;
            }
        }
    }
    // The interpolant at the n + 1 Legendre-Gauss-Lobatto nodes, sampled together.
    const LglRule& rule = LglNodes(n);
    const double mid = 0.5 * (seg.tEnter + seg.tExit), half = 0.5 * (seg.tExit - seg.tEnter);
    double* values = samples_[f];
    double* ts = values + n + 1;
    for (int i = 0; i <= n; ++i) ts[i] = mid + half * rule.nodes[i];
    bool sampled = false;
    if (hexKernel) {
        const FieldCellData& data = *s.data[f];
        sampled = SampleAffineHexLine(
            cell.basis->order, data.values.data() + data.mesh->cellOffsets[seg.cell],
            ref0, dref, ts, n + 1, values);
        if (sampled) fieldSamples_ += n + 1;
    }
    if (!sampled) sf.SampleBatch(ts, n + 1, values);
    SeriesFromSamples(f, seg, n);
}

void VolumeRayMarcher::SeriesFromSamples(int f, const Segment& seg, int n) {
    const double* values = samples_[f];
    double scale = 0;
    for (int i = 0; i <= n; ++i) scale = std::max(scale, std::abs(values[i]));
    sampleCount_[f] = n + 1;
    ProjectedPiece& piece = OnlyPiece(f);
    std::swap(piece.p.c, spareCoefficients_[f]);
    InterpolateLgl(values, n, seg.tEnter, seg.tExit, piece.p);
    // As ProjectSegment's exact projection: rounding in the samples and the transform.
    piece.eps = 64 * (n + 1) * kEps * scale;
    piece.converged = true;
    // The trailing coefficients at the level of that rounding (the field is smooth on
    // the segment: its coefficients fall to the noise of the samples well before the
    // degree bound) are dropped, their sum kept as an error: every later evaluation of
    // the series is that much cheaper.
    DropNoiseTail(f, seg, piece.p.c);
}

int VolumeRayMarcher::KeptCoefficients(int f, const Segment& seg, const double* c,
                                       int size) {
    const Interval& range = (*setup_->ranges[f])[seg.cell];
    const double noise =
        kTruncation * kEps * std::max(std::abs(range.lo), std::abs(range.hi));
    double dropped = 0;
    while (size > 2 && dropped + std::abs(c[size - 1]) <= noise) {
        dropped += std::abs(c[size - 1]);
        --size;
    }
    truncated_[f] = dropped;
    return size;
}

void VolumeRayMarcher::DropNoiseTail(int f, const Segment& seg, std::vector<double>& c) {
    c.resize(std::size_t(KeptCoefficients(f, seg, c.data(), int(c.size()))));
}

void VolumeRayMarcher::SeriesFromPolynomial(int f, const Segment& seg, int n,
                                            const double* mono, double magnitude) {
    // x^2 = (2 P2 + P0) / 3 and x^3 = (2 P3 + 3 P1) / 5: the Legendre coefficients.
    const double m2 = n >= 2 ? mono[2] : 0.0, m3 = n >= 3 ? mono[3] : 0.0;
    ProjectedPiece& piece = OnlyPiece(f);
    std::swap(piece.p.c, spareCoefficients_[f]);
    piece.p.a = seg.tEnter;
    piece.p.b = seg.tExit;
    const double coefficients[4] = {mono[0] + m2 / 3, mono[1] + 0.6 * m3,
                                    n >= 2 ? (2.0 / 3.0) * m2 : 0.0,
                                    n >= 3 ? 0.4 * m3 : 0.0};
    // The values at the Legendre-Gauss-Lobatto nodes of degree n, where the sampled
    // series has its samples (SeriesCrossings brackets crossings between them).
    const LglRule& rule = LglNodes(n);
    const double mid = 0.5 * (seg.tEnter + seg.tExit),
                 half = 0.5 * (seg.tExit - seg.tEnter);
    double* values = samples_[f];
    double* ts = values + n + 1;
    sampleCount_[f] = n + 1;
    double scale = magnitude;
    for (int i = 0; i <= n; ++i) {
        const double x = rule.nodes[i];
        double v = mono[n];
        for (int k = n - 1; k >= 0; --k) v = v * x + mono[k];
        ts[i] = mid + half * x;
        values[i] = v;
        scale = std::max(scale, std::abs(v));
    }
    // Every term of the sum factorisation and of the conversion is at most the largest
    // nodal value: the same bound as the sampled series' rounding.
    piece.eps = 64 * (n + 1) * kEps * scale;
    piece.converged = true;
    // As DropNoiseTail, on the local coefficients: only those kept are stored.
    piece.p.c.assign(coefficients,
                     coefficients + KeptCoefficients(f, seg, coefficients, n + 1));
}

bool VolumeRayMarcher::ProjectRational(int f, const Segment& seg, double gap,
                                       double residue) {
    const VolumeSetup& s = *setup_;
    // On the segment mapped to x in [-1, 1] the field is q(x) + C / (x - p) with q linear
    // (SegmentField::RationalPole). The Chebyshev coefficients of 1 / (x - p), |p| > 1,
    // are 2 rho^-k / sqrt(p^2 - 1) in magnitude (k >= 1), rho = |p| + sqrt(p^2 - 1): the
    // truncation after degree n misses by at most K rho^-(n+1), K = 2 |C| / (sqrt(p^2 -
    // 1) (1 - 1 / rho)), and the interpolant at the Legendre-Gauss-Lobatto nodes of
    // degree n by at most kLebesgueBound times that (twice, for the rounding of this
    // bound). The lowest degree whose miss is below the level of the trailing
    // coefficients ProjectExact drops as noise.
    const double root = std::sqrt(gap * (gap + 2));
    const double rho = 1 + gap + root;
    // No residue (a polynomial of degree <= 2, the pole at infinity): nothing missed.
    const double K = residue == 0 ? 0.0 : 2 * std::abs(residue) / (root * (1 - 1 / rho));
    const Interval& range = (*s.ranges[f])[seg.cell];
    const double target =
        kTruncation * kEps * std::max(std::abs(range.lo), std::abs(range.hi));
    const double lead = 2 * kLebesgueBound * K;
    int n = 2;
    if (lead > target) {
        if (!(rho > 1)) return false;
        const double need = std::ceil(std::log(lead / target) / std::log(rho)) - 1;
        if (!(need <= kMaxRationalDegree)) return false;
        n = std::max(2, static_cast<int>(need));
    }
    double miss = lead == 0 ? 0.0 : lead * std::pow(rho, -(n + 1));
    if (!(miss <= target)) {
        // The logarithms' rounding left the degree one short.
        ++n;
        miss = lead * std::pow(rho, -(n + 1));
        if (n > kMaxRationalDegree || !(miss <= target)) return false;
    }
    const LglRule& rule = LglNodes(n);
    const double mid = 0.5 * (seg.tEnter + seg.tExit),
                 half = 0.5 * (seg.tExit - seg.tEnter);
    double* ts = samples_[f] + n + 1;
    for (int i = 0; i <= n; ++i) ts[i] = mid + half * rule.nodes[i];
    field_[f].SampleBatch(ts, n + 1, samples_[f]);
    SeriesFromSamples(f, seg, n);
    pieces_[f][0].eps += miss;
    unresolved_[f] = miss;
    return true;
}

bool VolumeRayMarcher::BeginPyramidLine(int f, const Segment& seg) {
    if (!field_[f].PyramidLineOn(seg.tEnter, seg.tExit, pyramid_[f])) return false;
    const Interval& range = (*setup_->ranges[f])[seg.cell];
    const double cellScale = std::max(std::abs(range.lo), std::abs(range.hi));
    const double* v = field_[f].NodalValues();
    double sumV = 0;
    for (int i = 0; i < 5; ++i) sumV += std::abs(v[i]);
    if (!MakePyramidDepthLine(pyramid_[f], cellScale, sumV, pyramidDepth_[f]))
        return false;
    // The depth line is the extinction field's (the last).
    if (f == fieldCount_ - 1) depthLineError_ = pyramidDepth_[f].depthError;
    lineError_[f] = pyramidDepth_[f].fieldError;
    depthLineT_ = std::numeric_limits<double>::quiet_NaN();
    return true;
}

bool VolumeRayMarcher::BeginPolyLine(int f, const Segment& seg) {
    const VolumeSetup& s = *setup_;
    SegmentField& sf = field_[f];
    const int n = sf.LineDegree();
    if (s.projection.startDegree == s.projection.maxDegree || n < 2 || n > 3 ||
        !(seg.tExit > seg.tEnter))
        return false;
    double mono[4], magnitude;
    int degree = 0;
    if (!sf.LinearCellLine(seg.tEnter, seg.tExit, mono, degree, magnitude) || degree != n)
        return false;
    PolyLine& p = poly_[f];
    p = MakePolyLine(seg.tEnter, seg.tExit, mono, n);
    double sum = 0;
    for (const double c : p.m) sum += std::abs(c);
    FieldState& st = state_[f];
    // As SeriesFromPolynomial: every term of the sum factorisation is at most the largest
    // nodal value, and the values are at most the sum of the coefficients.
    const double eps = 64 * (n + 1) * kEps * std::max(magnitude, sum);
    st.error = std::max(st.error, eps);
    polyMagnitude_[f] = magnitude;
    if (fieldCount_ == 1 && std::abs(p.m[2]) + std::abs(p.m[3]) <= eps) {
        // Linear data on the cell (u = x + 2y + 3z on hexes, say): the closed form.
        st.linear = true;
        st.valueEnter = p.AtX(-1.0);
        st.valueExit = p.AtX(1.0);
        return true;
    }
    st.poly = true;
    // The series' bounds: the samples' rounding, and the evaluation's (Horner's on [-1,
    // 1] within 2 n eps of the sum of the coefficients) and the depth line's likewise.
    const Interval& range = (*s.ranges[f])[seg.cell];
    const double cellScale = std::max(std::abs(range.lo), std::abs(range.hi));
    lineError_[f] = kSampleRounding * kEps * cellScale + kSeriesRounding * kEps * sum;
    // The depth line is the extinction field's (the last).
    if (f == fieldCount_ - 1)
        depthLineError_ =
            kSeriesRounding * kEps * p.half *
            (0.5 * std::abs(p.m[1]) + std::abs(p.m[2]) / 3 + 0.25 * std::abs(p.m[3]));
    depthLineT_ = std::numeric_limits<double>::quiet_NaN();
    return true;
}

void VolumeRayMarcher::ClosedLineCrossings(int f, const Segment& seg) {
    const Interval& range = (*setup_->ranges[f])[seg.cell];
    const BreakpointSpan span = BreakpointsIn(f, range.lo, range.hi);
    double last = std::numeric_limits<double>::quiet_NaN();
    for (std::size_t i = span.first; i < span.last; ++i) {
        const double b = span.points[i];
        if (!(b < range.hi)) break;
        if (!(b > range.lo) || b == last) continue;
        last = b;
        if (state_[f].poly)
            PolyLevelCrossings(poly_[f], b, seg.tEnter, seg.tExit, crossings_);
        else
            PyramidLevelCrossings(pyramid_[f], b, seg.tEnter, seg.tExit, crossings_);
    }
}

VolumeRayMarcher::BreakpointSpan VolumeRayMarcher::BreakpointsIn(int f, double lo,
                                                                 double hi) const {
    const VolumeSetup& s = *setup_;
    // The one list merged in the set-up where one field drives both transfer functions.
    const std::vector<double>& points =
        f == 0 ? (s.sameField ? s.breakpoints : s.colorTf.Scalars())
               : s.extinctionTf.Scalars();
    const ShortAscending& few =
        f == 0 ? (s.sameField ? s.shortBreakpoints : s.colorTf.ShortScalars())
               : s.extinctionTf.ShortScalars();
    // Those in (lo, hi) run from the first one > lo to the last one < hi (not counted
    // where lo or hi is NaN).
    if (few.valid && lo <= hi)
        return {points, std::size_t(few.CountAtMost(lo)),
                std::size_t(few.CountBelow(hi))};
    return {points, 0, points.size()};
}

void VolumeRayMarcher::LinearCrossings(int f, const Segment& seg) {
    const FieldState& st = state_[f];
    const double dv = st.valueExit - st.valueEnter;
    if (dv == 0) return;
    const double length = seg.tExit - seg.tEnter;
    // Only a breakpoint strictly between the end values can be crossed (x in (0, 1)). The
    // control points this field drives, ascending: t is monotone in them (the same
    // rounded operations), so the crossings come out in their order.
    const double lo = std::min(st.valueEnter, st.valueExit);
    const double hi = std::max(st.valueEnter, st.valueExit);
    const BreakpointSpan span = BreakpointsIn(f, lo, hi);
    for (std::size_t i = span.first; i < span.last; ++i) {
        const double b = span.points[i];
        if (b >= hi) break;
        if (!(b > lo)) continue;
        const double x = (b - st.valueEnter) / dv;
        if (x > 0 && x < 1) {
            const double t = seg.tEnter + x * length;
            if (t > seg.tEnter && t < seg.tExit) crossings_.push_back(t);
        }
    }
}

void VolumeRayMarcher::BeginConstantCell(std::int64_t cell) {
    const VolumeSetup& s = *setup_;
    // Both transfer functions are constant over the guaranteed ranges: any value in them
    // gives the constants.
    const Interval& rc = (*s.ranges[0])[cell];
    const Interval& re = (*s.ranges.back())[cell];
    s.extinctionTf.Eval(0.5 * (re.lo + re.hi), &constTau_);
    constTau_ = std::max(0.0, constTau_);
    s.colorTf.Eval(0.5 * (rc.lo + rc.hi), constColor_);
}

void VolumeRayMarcher::FindCrossings(int f, const Segment& seg,
                                     RenderCounters& counters) {
    const VolumeSetup& s = *setup_;
    FieldState& st = state_[f];
    if (st.constant) return;
    // The control points of the transfer functions this field drives, strictly inside
    // [lo, hi].
    auto forEachBreakpoint = [&](double lo, double hi, auto&& visit) {
        if (f == 0)
            for (double b : s.colorTf.Scalars())
                if (b > lo && b < hi) visit(b);
        if (f == 1 || s.sameField)
            for (double b : s.extinctionTf.Scalars())
                if (b > lo && b < hi) visit(b);
    };
    if (st.linear) {
        LinearCrossings(f, seg);
        return;
    }
    if (st.pyramid || st.poly) {
        ClosedLineCrossings(f, seg);
        return;
    }
    const Interval& range = (*s.ranges[f])[seg.cell];
    // The control points in the cell's range (often none), without repeats.
    const BreakpointSpan span = BreakpointsIn(f, range.lo, range.hi);
    if (span.first >= span.last) return;
    levels_.clear();
    for (std::size_t i = span.first; i < span.last; ++i) {
        const double b = span.points[i];
        if (!(b < range.hi)) break;
        if (b > range.lo && (levels_.empty() || levels_.back() != b))
            levels_.push_back(b);
    }
    if (levels_.empty()) return;
    SegmentField& sf = field_[f];
    if (pieces_[f].empty()) {
        ProjectionOptions projection = s.projection;
        projection.scaleFloor = s.fieldScale[f];
        projectionStats_ = ProjectionStats{};
        ProjectSegment(sf, seg.tEnter, seg.tExit, projection, pieces_[f],
                       projectionStats_, scratch_);
    }
    auto record = [&](const RootResult& r) {
        if (r.t > seg.tEnter && r.t < seg.tExit) crossings_.push_back(r.t);
        return false;
    };
    if (st.bySeries) {
        // The series is the field up to its rounding (the interpolant of a polynomial of
        // its degree): its crossings of all the breakpoints at once, found on it, which
        // costs no field evaluation.
        const double tol =
            std::max(s.roots.rootTolerance * (seg.tExit - seg.tEnter),
                     4 * kEps * std::max(std::abs(seg.tEnter), std::abs(seg.tExit)));
        SeriesCrossings(pieces_[f][0].p, levels_.data(), int(levels_.size()), tol,
                        samples_[f] + sampleCount_[f], samples_[f], sampleCount_[f],
                        scratch_, points_, derivative_, crossings_);
        return;
    }
    forEachBreakpoint(range.lo, range.hi, [&](double b) {
        counters.rootFailures += FindRoots(sf, pieces_[f], b, s.roots, scratch_, record);
    });
}

double VolumeRayMarcher::FieldAt(int f, double t) {
    const FieldState& st = state_[f];
    if (st.linear) {
        // The ends exactly, without a division (as the interpolation gives them).
        if (st.constant || t == seg_.tEnter) return st.valueEnter;
        if (t == seg_.tExit) return st.valueExit;
        const double x = (t - seg_.tEnter) / (seg_.tExit - seg_.tEnter);
        return (1 - x) * st.valueEnter + x * st.valueExit;
    }
    if (st.bySeries) return pieces_[f][0].p(t);
    if (st.pyramid) return pyramid_[f].At(t);
    if (st.poly) return poly_[f].At(t);
    return field_[f](t);
}

void VolumeRayMarcher::Sample(double t, double& tau, double emission[3]) {
    const VolumeSetup& s = *setup_;
    const double vc = FieldAt(0, t);
    const double ve = s.sameField ? vc : FieldAt(1, t);
    s.extinctionTf.Eval(ve, &tau);
    tau = std::max(0.0, tau);
    s.colorTf.Eval(vc, emission);
    for (int c = 0; c < 3; ++c) {
        emission[c] = std::max(0.0, emission[c]);
        if (s.glow == GlowModel::WilliamsMax) emission[c] *= tau;
    }
}

void VolumeRayMarcher::SetPiece(QueuedPiece& piece, double p0, double p1, bool varying,
                                double tau0, double tau1, const double c0[3],
                                const double c1[3]) {
    piece.p0 = p0;
    piece.p1 = p1;
    piece.length = p1 - p0;
    piece.varying = varying;
    piece.tau0 = std::max(0.0, tau0);
    piece.tau1 = std::max(0.0, tau1);
    for (int c = 0; c < 3; ++c) {
        piece.c0[c] = std::max(0.0, c0[c]);
        piece.c1[c] = std::max(0.0, c1[c]);
    }
    if (!varying) piece.colorError = piece.tauError = 0;
}

void VolumeRayMarcher::LinearPiece(double p0, double p1, RayComposite& composite) {
    QueuedPiece piece;
    if (kind_ == VolumeSetup::kConstant) {
        SetPiece(piece, p0, p1, false, constTau_, constTau_, constColor_, constColor_);
    } else {
        const VolumeSetup& s = *setup_;
        // Each transfer function is affine on the piece: its piece is the one holding the
        // field at the midpoint, extended to both ends (the ends are breakpoints up to
        // rounding).
        double tau0, tau1, c0[3], c1[3];
        const double mid = 0.5 * (p0 + p1);
        const double vc0 = FieldAt(0, p0), vc1 = FieldAt(0, p1), vcm = FieldAt(0, mid);
        const int kc = s.colorTf.IntervalOf(vcm);
        s.colorTf.EvalOn(kc, vc0, c0);
        s.colorTf.EvalOn(kc, vc1, c1);
        const int fe = s.sameField ? 0 : 1;
        const double ve0 = s.sameField ? vc0 : FieldAt(fe, p0);
        const double ve1 = s.sameField ? vc1 : FieldAt(fe, p1);
        const double vem = s.sameField ? vcm : FieldAt(fe, mid);
        const int ke = s.extinctionTf.IntervalOf(vem);
        s.extinctionTf.EvalOn(ke, ve0, &tau0);
        s.extinctionTf.EvalOn(ke, ve1, &tau1);
        SetPiece(piece, p0, p1, true, tau0, tau1, c0, c1);
        // The slopes of the pieces in use turn field errors into value errors.
        piece.colorError = s.colorTf.SteepestOn(kc) * state_[0].error;
        piece.tauError = s.extinctionTf.SteepestOn(ke) * state_[fieldCount_ - 1].error;
    }
    CompositeLinearPiece(
        piece, IntegrateLinearPiece(piece.tau0, piece.tau1, piece.length), composite);
}

void VolumeRayMarcher::CompositeLinearPiece(const QueuedPiece& piece,
                                            const LinearPieceIntegrals& q,
                                            RayComposite& composite) {
    const VolumeSetup& s = *setup_;
    const double length = piece.length, tau0 = piece.tau0, tau1 = piece.tau1;
    const double T = composite.transmittance;
    const bool wm = s.glow == GlowModel::WilliamsMax;
    // The error terms in the order AddColor and AddFieldError add them, summed in
    // registers and stored once: stores of single channels that a wider load of the
    // next term reads back cannot be forwarded, and stall it.
    double error[3] = {composite.error[0], composite.error[1], composite.error[2]};
    double rgb[3];
    for (int c = 0; c < 3; ++c) {
        const double e = wm ? WilliamsMaxEmission(q, piece.c0[c], piece.c1[c])
                            : GlowEmission(q, piece.c0[c], piece.c1[c], length);
        rgb[c] = T * e;
        // Rounding of the closed form (a few ulps; see IntegrateLinearPiece) and of the
        // compositing.
        error[c] += 16 * kEps * rgb[c];
    }
    // The piece's own colour first (RayComposite::AddColor): the depth errors below
    // affect only what lies behind.
    for (int c = 0; c < 3; ++c) {
        composite.rgba[c] += rgb[c];
        error[c] += std::abs(rgb[c]) * composite.depthError;
    }
    if (piece.varying) {
        // AddFieldError.
        const double own =
            FieldErrorOwn(length, 0.5 * length * (tau0 + tau1), std::min(tau0, tau1),
                          piece.colorError, piece.tauError);
        for (double& e : error) e += T * own;
        composite.depthError += length * piece.tauError;
    }
    for (int c = 0; c < 3; ++c) composite.error[c] = error[c];
    composite.rgba[3] += T * q.opacity;
    composite.transmittance = T * q.transmittance;
    composite.depthError += 4 * kEps * length * 0.5 * (tau0 + tau1);
    if (piece.p0 == tStart_ || piece.p1 == tEnd_) {
        double e0[3], e1[3];
        for (int c = 0; c < 3; ++c) {
            e0[c] = wm ? piece.c0[c] * tau0 : piece.c0[c];
            e1[c] = wm ? piece.c1[c] * tau1 : piece.c1[c];
        }
        RecordEnds(piece.p0, piece.p1, tau0, e0, tau1, e1, composite.transmittance);
    }
}

void VolumeRayMarcher::QueueLinearTetPiece(double p0, double p1, bool varying) {
    // Grown in steps, never cleared: no piece is zeroed before it is written.
    if (queued_ == queue_.size()) queue_.resize(queued_ + kQueuedPieces);
    QueuedPiece& piece = queue_[queued_++];
    if (!varying) {
        SetPiece(piece, p0, p1, false, constTau_, constTau_, constColor_, constColor_);
        return;
    }
    // As LinearPiece with one linear field, the colour and extinction at the piece's
    // start kept from the last piece's end where they are the same.
    const VolumeSetup& s = *setup_;
    const FieldState& st = state_[0];
    const double v0 = FieldAt(0, p0), v1 = FieldAt(0, p1),
                 vm = FieldAt(0, 0.5 * (p0 + p1));
    const int kc = s.colorTf.IntervalOf(vm);
    const int ke = s.extinctionTf.IntervalOf(vm);
    double c0[3], c1[3], tau0;
    if (kc == lastColor_.piece && v0 == lastColor_.value) {
        for (int c = 0; c < 3; ++c) c0[c] = lastColor_.out[c];
    } else {
        s.colorTf.EvalOn3(kc, v0, c0[0], c0[1], c0[2]);
    }
    if (ke == lastExtinction_.piece && v0 == lastExtinction_.value) {
        tau0 = lastExtinction_.out[0];
    } else {
        tau0 = s.extinctionTf.EvalOn1(ke, v0);
    }
    s.colorTf.EvalOn3(kc, v1, c1[0], c1[1], c1[2]);
    const double tau1 = s.extinctionTf.EvalOn1(ke, v1);
    lastColor_ = {kc, v1, {c1[0], c1[1], c1[2]}};
    lastExtinction_ = {ke, v1, {tau1, 0, 0}};
    SetPiece(piece, p0, p1, true, tau0, tau1, c0, c1);
    piece.colorError = s.colorTf.SteepestOn(kc) * st.error;
    piece.tauError = s.extinctionTf.SteepestOn(ke) * st.error;
}

[[gnu::flatten]] bool VolumeRayMarcher::FlushLinearTets(RayComposite& composite) {
    const std::size_t n = queued_;
    if (n == 0) return false;
    // The closed forms of all queued pieces at once, then each composited in order with
    // Terminate after it, as Integrate does.
    if (pieceIntegrals_.size() < n) pieceIntegrals_.resize(n);
    // The inputs read from the queue in place.
    IntegrateLinearPieces(
        static_cast<int>(n), reinterpret_cast<const unsigned char*>(queue_.data()),
        sizeof(QueuedPiece), offsetof(QueuedPiece, tau0), offsetof(QueuedPiece, tau1),
        offsetof(QueuedPiece, length), pieceIntegrals_.data());
    bool stop = false;
    for (std::size_t i = 0; i < n && !stop; ++i) {
        CompositeLinearPiece(queue_[i], pieceIntegrals_[i], composite);
        stop = Terminate(queue_[i].p1, composite);
    }
    queued_ = 0;
    return stop;
}

template <int line>
void VolumeRayMarcher::SeriesPieceFor(double p0, double p1, RayComposite& composite) {
    const bool wm = setup_->glow == GlowModel::WilliamsMax, one = fieldCount_ == 1;
    if (wm && one)
        SeriesPieceOf<true, true, line>(p0, p1, composite);
    else if (wm)
        SeriesPieceOf<true, false, line>(p0, p1, composite);
    else if (one)
        SeriesPieceOf<false, true, line>(p0, p1, composite);
    else
        SeriesPieceOf<false, false, line>(p0, p1, composite);
}

void VolumeRayMarcher::SeriesPiece(double p0, double p1, RayComposite& composite) {
    // How the fields are held, the glow model and whether one field drives both transfer
    // functions as constants: the branches on them compiled out of the piece's loops.
    if (polyLine_)
        SeriesPieceFor<kPolyLine>(p0, p1, composite);
    else if (pyramidLine_)
        SeriesPieceFor<kPyramidLine>(p0, p1, composite);
    else
        SeriesPieceFor<kSeriesLine>(p0, p1, composite);
}

template <bool wm, bool oneField, int line>
void VolumeRayMarcher::SeriesPieceOf(double p0, double p1, RayComposite& composite) {
    constexpr bool pyramid = line == kPyramidLine, poly = line == kPolyLine;
    const VolumeSetup& s = *setup_;
    constexpr int fe = oneField ? 0 : 1;
    // The series of the fields (not set, and not read, where pyramid or poly).
    const LegendreSeries* uc = linePtr_[0];
    const LegendreSeries* ue = linePtr_[fe];
    const double length = p1 - p0, mid = 0.5 * (p0 + p1);
    // Each transfer function is affine on the piece (its ends are breakpoints up to
    // rounding): the piece holding the field at the midpoint, extended to both ends.
    // The fields at t (colour, extinction), however they are held.
    auto colorAt = [&](double t) {
        return pyramid ? pyramid_[0].At(t) : poly ? poly_[0].At(t) : uc->At(t);
    };
    auto extinctionAt = [&](double t) {
        return pyramid ? pyramid_[fe].At(t) : poly ? poly_[fe].At(t) : ue->At(t);
    };
    const double c0 = colorAt(mid);
    const double em = fe == 0 ? c0 : extinctionAt(mid);
    double ac[3], bc[3], ae, be;
    s.colorTf.AffineOn3(s.colorTf.IntervalOf(c0), ac, bc);
    s.extinctionTf.AffineOn1(s.extinctionTf.IntervalOf(em), ae, be);
    // Optical depth from p0, exact for the polynomial field: with ue = m + w (m its mean
    // on the segment, V the antiderivative of w), phi(t) = tauM (t - p0) + be (V(t) -
    // V(p0)) for tauM = ae + be m. Taking the mean out keeps V small, and so its rounding.
    double tauM = ae, v0 = 0, v1 = 0;
    if ((pyramid || poly) && be != 0) {
        tauM = ae + be * (pyramid ? pyramidDepth_[fe].mean : poly_[fe].m[0]);
        // Pieces follow each other along the segment: the last end is this start. (V at
        // both ends in one call otherwise: the same lanes as at the nodes.)
        const bool known = p0 == depthLineT_;
        alignas(32) double ends[4] = {p0, p1, p1, p1}, f4[4], v4[4];
#if defined(__AVX2__) && defined(__FMA__)
        if constexpr (pyramid)
            PyramidLineAt4(pyramid_[fe], pyramidDepth_[fe], ends, f4, v4);
        else
            PolyLineAt4(poly_[fe], ends, f4, v4);
#else
        if constexpr (pyramid)
            PyramidLineAt(pyramid_[fe], pyramidDepth_[fe], ends, 2, f4, v4);
        else
            PolyLineAt(poly_[fe], ends, 2, f4, v4);
#endif
        v0 = known ? depthLineV_ : v4[0];
        v1 = v4[1];
        depthLineT_ = p1;
        depthLineV_ = v1;
    } else if (be != 0) {
        if (!haveDepthLine_) {
            ue->Antiderivative(depthLine_, /*withoutMean=*/true);
            double sum = 0;
            for (double c : depthLine_.c) sum += std::abs(c);
            depthLineError_ = kSeriesRounding * kEps * sum;
            haveDepthLine_ = true;
            depthLineT_ = std::numeric_limits<double>::quiet_NaN();
        }
        tauM = ae + be * ue->c[0];
        // Pieces follow each other along the segment: the last end is this start.
        if (p0 == depthLineT_) {
            v0 = depthLineV_;
            v1 = depthLine_.At(p1);
        } else {
            AtTwo(depthLine_, p0, p1, v0, v1);
        }
        depthLineT_ = p1;
        depthLineV_ = v1;
    }
    const double depth = std::max(0.0, tauM * length + be * (v1 - v0));
    // Rounding of the depth: the antiderivative's evaluations and the sums (which may
    // cancel: the bound is on the terms).
    const double depthRounding =
        (be != 0 ? 2 * std::abs(be) * depthLineError_ : 0.0) +
        4 * kEps * (std::abs(tauM) * length + std::abs(be * (v1 - v0)));
    double opacity, attenuation;
    PieceOpacity(depth, opacity, attenuation);
    // Williams-Max: E_c = (ac + bc c0) (1 - e^-D) + bc Q with Q = integral (uc - c0) tau
    // e^-phi, since integral tau e^-phi = 1 - e^-D. Wilhelms-Van Gelder: E_c = (ac + bc
    // c0) J + bc Q with J = integral e^-phi (closed form when tau is constant) and Q =
    // integral (uc - c0) e^-phi. Q and J by Gauss-Kronrod pairs.
    double wJ[3], wQmax = 0, wJmax = 0;
    for (int c = 0; c < 3; ++c) {
        wJ[c] = ac[c] + bc[c] * c0;
        wQmax = std::max(wQmax, std::abs(bc[c]));
        wJmax = std::max(wJmax, std::abs(wJ[c]));
    }
    const bool absorbs = tauM != 0 || be != 0;
    const bool needQ = wQmax > 0 && (absorbs || !wm);
    const bool needJ = !wm && be != 0 && wJmax > 0;
    if (!needQ) wQmax = 0;
    if (!needJ) wJmax = 0;
    const double T = composite.transmittance;
    double Q = 0, J = 0, sigQ = 0, sigJ = 0, absQ = 0, absJ = 0, magQ = 0, magJ = 0;
    double tauMin = std::numeric_limits<double>::infinity();
    if (needQ || needJ) {
        const double budgetPerLength = 0.5 * s.tolerance / pathLength_;
        const NestedQuadratureRules& rules = kQuadratureRules;
        // Padded to whole blocks of eight: a rung's nodes end at 2^r - 1 <= 31 and its
        // new ones start at 0, 7 or 15, so the blocks from any rung's first new node fit.
        constexpr int kNodes = NestedQuadratureRules::kMaxNodes + 1;
        static_assert(kNodes % 8 == 0);
        alignas(32) double nodeT[kNodes], nodeU[kNodes], nodeE[kNodes], nodeDepth[kNodes],
            att[kNodes], gq[kNodes];
        double* ueAt = fe == 0 ? nodeU : nodeE;
        // The integrands at nodes first..n-1 of the interval of midpoint m and half-width
        // half. Inlined into both of its uses below, so that the first rung's (nodes
        // 0..6, known at compile time) runs as straight-line code.
        auto evaluate = [&](int first, int n, double m, double half)
            __attribute__((always_inline)) {
            const int count = n - first;
            for (int i = first; i < n; ++i) nodeT[i] = m + half * rules.nodes[i];
            // Whole blocks of eight in place (the arrays are padded; what lies past the
            // rule's nodes is not read, and the next rung overwrites it).
            const int whole = (count + 7) / 8 * 8;
            for (int i = first + count; i < first + whole; ++i) nodeT[i] = m;
            // The vectorised evaluations where the build has them (bitwise the same).
            auto many = [&](const LegendreSeries& p, double* out) {
                if (!EvalManyKernelWhole(p, nodeT + first, whole, out))
                    p.EvalMany(nodeT + first, count, out);
            };
            auto pair = [&](const LegendreSeries& p, double* outP) {
                if (!EvalPairKernelWhole(p, depthLine_, nodeT + first, whole, outP,
                                         nodeDepth + first))
                    EvalPair(p, depthLine_, nodeT + first, count, outP,
                             nodeDepth + first);
            };
            if constexpr (pyramid) {
                // The colour field, then (if another) the extinction field and its depth.
                double* depth = be != 0 ? nodeDepth + first : nullptr;
                PyramidLineAt(pyramid_[0], pyramidDepth_[0], nodeT + first, whole,
                              nodeU + first, fe == 0 ? depth : nullptr);
                if (fe != 0)
                    PyramidLineAt(pyramid_[fe], pyramidDepth_[fe], nodeT + first, whole,
                                  nodeE + first, depth);
            } else if constexpr (poly) {
                double* depth = be != 0 ? nodeDepth + first : nullptr;
                PolyLineAt(poly_[0], nodeT + first, whole, nodeU + first,
                           fe == 0 ? depth : nullptr);
                if (fe != 0)
                    PolyLineAt(poly_[fe], nodeT + first, whole, nodeE + first, depth);
            } else if (be == 0) {
                many(*uc, nodeU + first);
            } else if (fe == 0) {
                pair(*uc, nodeU + first);
            } else {
                many(*uc, nodeU + first);
                pair(*ue, nodeE + first);
            }
            quadratureNodes_ += count;
            // Whole vectors of four (the arrays are padded; the filler's results are not
            // read).
            const int padded = (count + 3) / 4 * 4;
#if defined(__AVX2__) && defined(__FMA__)
            // The scalar loops' operations lane by lane (std::max(0.0, x) is MAXPD(x, 0):
            // 0 where x is NaN or -0 too). The filler lanes are the nodes' midpoint m
            // (nodeT above) and its evaluations: finite, and not read.
            alignas(32) double tauAt[kNodes];
            const __m256d vp0 = _mm256_set1_pd(p0), vv0 = _mm256_set1_pd(v0),
                          vTauM = _mm256_set1_pd(tauM), vae = _mm256_set1_pd(ae),
                          vbe = _mm256_set1_pd(be), vc0 = _mm256_set1_pd(c0);
            for (int i = first; i < first + padded; i += 4) {
                const __m256d dt = _mm256_sub_pd(_mm256_loadu_pd(nodeT + i), vp0);
                __m256d phi = _mm256_mul_pd(vTauM, dt);
                if (be != 0)
                    phi = _mm256_add_pd(
                        phi,
                        _mm256_mul_pd(
                            vbe, _mm256_sub_pd(_mm256_loadu_pd(nodeDepth + i), vv0)));
                const __m256d a =
                    ExpNegativeLanes(_mm256_max_pd(phi, _mm256_setzero_pd()));
                const __m256d tau =
                    be != 0 ? _mm256_add_pd(vae,
                                            _mm256_mul_pd(vbe, _mm256_loadu_pd(ueAt + i)))
                            : vae;
                __m256d g = _mm256_sub_pd(_mm256_loadu_pd(nodeU + i), vc0);
                if (wm) g = _mm256_mul_pd(g, tau);
                _mm256_storeu_pd(att + i, a);
                _mm256_storeu_pd(gq + i, _mm256_mul_pd(g, a));
                _mm256_storeu_pd(tauAt + i, tau);
            }
            for (int i = first; i < n; ++i) tauMin = std::min(tauMin, tauAt[i]);
#else
            for (int i = first; i < n; ++i) {
                const double dt = nodeT[i] - p0;
                att[i] = std::max(
                    0.0, be != 0 ? tauM * dt + be * (nodeDepth[i] - v0) : tauM * dt);
            }
            for (int i = first + count; i < first + padded; ++i) att[i] = 0;
            ExpNegative(att + first, padded, att + first);
            for (int i = first; i < n; ++i) {
                const double tau = be != 0 ? ae + be * ueAt[i] : ae;
                tauMin = std::min(tauMin, tau);
                gq[i] = (nodeU[i] - c0) * (wm ? tau : 1.0) * att[i];
            }
#endif
        };
        // Rung `level` on an interval of half-width half: the result by rule L, its error
        // estimated by rule L + 1.
        struct Rung {
            double qK, qG, jK, jG, qAbs, sQ, sJ, estimate;
        };
        auto rung = [&](int level, double half) __attribute__((always_inline)) {
            const double* lower = rules.weights[level].data();
            const double* upper = rules.weights[level + 1].data();
            const int nLower = NestedQuadratureRules::Size(level);
            const int n = NestedQuadratureRules::Size(level + 1);
            Rung r{0, 0, 0, 0, 0, 0, 0, 0};
            for (int i = 0; i < nLower; ++i) {
                r.qG += lower[i] * gq[i];
                r.jG += lower[i] * att[i];
            }
            for (int i = 0; i < n; ++i) {
                r.qK += upper[i] * gq[i];
                r.qAbs += upper[i] * std::abs(gq[i]);
                r.jK += upper[i] * att[i];
            }
            r.sQ = half * (r.qK - r.qG);
            r.sJ = half * (r.jK - r.jG);
            r.estimate = T * (1 + kKronrodMargin) *
                         (wQmax * std::abs(r.sQ) + wJmax * std::abs(r.sJ));
            return r;
        };
        auto accept = [&](const Rung& r, double half) __attribute__((always_inline)) {
            const double jAbs = r.jK;
            ++kronrodIntervals_;
            Q += half * r.qG;
            J += half * r.jG;
            sigQ += r.sQ;
            sigJ += r.sJ;
            absQ += std::abs(r.sQ);
            absJ += std::abs(r.sJ);
            magQ += half * r.qAbs;
            magJ += half * jAbs;
        };
        // An interval not accepted: the next rung on it (two if far from the budget), or
        // above the top rung its halves.
        auto climb = [&](const Work& w, double estimate, double allowed) {
            if (w.level < kTopLevel) {
                const int step = estimate > 1e6 * allowed ? 2 : 1;
                stack_.push_back(
                    {w.lo, w.hi, w.depth, std::min(kTopLevel, w.level + step)});
            } else {
                const double m = 0.5 * (w.lo + w.hi);
                stack_.push_back({m, w.hi, w.depth + 1, kTopLevel - 1});
                stack_.push_back({w.lo, m, w.depth + 1, kTopLevel - 1});
            }
        };
        // The piece itself on the first rung, which most pieces stop at: the work stack
        // and the node cache below only where it climbs or bisects.
        constexpr int kFirstNodes = NestedQuadratureRules::Size(kStartLevel + 1);
        const double half = 0.5 * (p1 - p0), m = 0.5 * (p0 + p1);
        evaluate(0, kFirstNodes, m, half);
        const Rung first = rung(kStartLevel, half);
        const double allowed = budgetPerLength * (p1 - p0);
        // The first work item is within the caps of depth and evaluations.
        static_assert(0 < kMaxKronrodDepth && 1 < kMaxKronrodEvaluations);
        if (!(first.estimate > allowed)) {
            accept(first, half);
        } else {
            stack_.clear();
            climb({p0, p1, 0, kStartLevel}, first.estimate, allowed);
            // The integrands at the nodes of the interval last evaluated: the first
            // `cached` nested nodes of [cachedLo, cachedHi]. A rung climbed on the same
            // interval (the next work item) evaluates only the nodes its rule adds.
            double cachedLo = p0, cachedHi = p1;
            int cached = kFirstNodes;
            int evaluations = 1;
            while (!stack_.empty()) {
                const Work w = stack_.back();
                stack_.pop_back();
                ++evaluations;
                const int n = NestedQuadratureRules::Size(w.level + 1);
                const double wHalf = 0.5 * (w.hi - w.lo), wMid = 0.5 * (w.lo + w.hi);
                if (cached == 0 || w.lo != cachedLo || w.hi != cachedHi) {
                    cached = 0;
                    cachedLo = w.lo;
                    cachedHi = w.hi;
                }
                if (cached < n) {
                    evaluate(cached, n, wMid, wHalf);
                    cached = n;
                }
                const Rung r = rung(w.level, wHalf);
                const double wAllowed = budgetPerLength * (w.hi - w.lo);
                if (r.estimate > wAllowed && w.depth < kMaxKronrodDepth &&
                    evaluations < kMaxKronrodEvaluations) {
                    climb(w, r.estimate, wAllowed);
                    continue;
                }
                accept(r, wHalf);
            }
        }
    }
    if (!wm && !needJ) {
        // tau constant on the piece: J = (1 - e^-D) / tau.
        J = depth > 0 ? length * opacity / depth : length;
        magJ = J;
    }
    if (!std::isfinite(tauMin)) tauMin = std::max(0.0, std::min(ae + be * em, tauM));
    double rgb[3];
    for (int c = 0; c < 3; ++c) {
        double e, sig = 0, unsure = 0, rounding;
        if (wm) {
            e = wJ[c] * opacity + bc[c] * Q;
            sig = bc[c] * sigQ;
            unsure = std::abs(bc[c]) * absQ;
            rounding = std::abs(wJ[c]) * opacity + std::abs(bc[c]) * magQ;
        } else {
            e = wJ[c] * J + bc[c] * Q;
            sig = wJ[c] * sigJ + bc[c] * sigQ;
            unsure = std::abs(wJ[c]) * absJ + std::abs(bc[c]) * absQ;
            rounding = std::abs(wJ[c]) * magJ + std::abs(bc[c]) * magQ;
        }
        rgb[c] = T * e;
        composite.signedError[c] += T * sig;
        // The rounding of the depth changes this piece's own emission too (e^-phi at the
        // nodes, 1 - e^-D): at most its terms times depthRounding.
        const double own = std::abs(wJ[c]) * (wm ? 1.0 : J) + std::abs(bc[c]) * magQ;
        composite.error[c] +=
            T * (kKronrodMargin * unsure + 16 * kEps * rounding + own * depthRounding);
    }
    composite.AddColor(rgb);
    // Field errors through the slopes of the pieces in use, and the rounding of the
    // transfer functions' affine forms (offset + slope u: a few ulps of the larger term,
    // which is all there is where the value is near zero).
    double colorError = 0;
    for (int c = 0; c < 3; ++c)
        colorError = std::max(colorError, std::abs(bc[c]) * lineError_[0] +
                                              4 * kEps * (std::abs(ac[c]) + std::abs(bc[c] * c0)));
    const double tauError =
        std::abs(be) * lineError_[fe] + 4 * kEps * (std::abs(ae) + std::abs(be * em));
    AddFieldError(length, depth, std::max(0.0, tauMin), T, colorError, tauError, composite);
    composite.rgba[3] += T * opacity;
    composite.transmittance = T * attenuation;
    // Everything behind is attenuated by the depth's rounding too, and by the
    // attenuation's (3 ulps: as a depth error of 3 eps).
    composite.depthError += depthRounding + 3 * kEps;
    if (p0 == tStart_ || p1 == tEnd_) {
        double tau[2], emission[2][3];
        const double ends[2] = {p0, p1};
        for (int k = 0; k < 2; ++k) {
            const double vc = colorAt(ends[k]);
            const double ve = fe == 0 ? vc : extinctionAt(ends[k]);
            tau[k] = std::max(0.0, ae + be * ve);
            for (int c = 0; c < 3; ++c)
                emission[k][c] = std::max(0.0, ac[c] + bc[c] * vc) * (wm ? tau[k] : 1.0);
        }
        RecordEnds(p0, p1, tau[0], emission[0], tau[1], emission[1],
                   composite.transmittance);
    }
}

void VolumeRayMarcher::KronrodPiece(double p0, double p1, RayComposite& composite) {
    const VolumeSetup& s = *setup_;
    const KronrodRule& rule = GetKronrodRule();
    constexpr int n = KronrodRule::kNodes;
    // The transfer functions are affine on the piece: the slopes of the pieces holding the
    // field at its midpoint turn field errors into value errors.
    double colorSlope, tauSlope;
    {
        const double mid = 0.5 * (p0 + p1);
        const double vc = FieldAt(0, mid), ve = s.sameField ? vc : FieldAt(1, mid);
        colorSlope = s.colorTf.SteepestOn(s.colorTf.IntervalOf(vc));
        tauSlope = s.extinctionTf.SteepestOn(s.extinctionTf.IntervalOf(ve));
    }
    const double budgetPerLength = 0.5 * s.tolerance / pathLength_;
    stack_.clear();
    stack_.push_back({p0, p1, 0});
    int evaluations = 0;
    while (!stack_.empty()) {
        ++evaluations;
        const Work w = stack_.back();
        stack_.pop_back();
        const double half = 0.5 * (w.hi - w.lo), mid = 0.5 * (w.lo + w.hi);
        double tau[n], emission[n][3];
        for (int i = 0; i < n; ++i)
            Sample(mid + half * rule.nodes[i], tau[i], emission[i]);
        quadratureNodes_ += n;
        double dK = 0, dG = 0, cK[3] = {0, 0, 0}, cG[3] = {0, 0, 0};
        for (int i = 0; i < n; ++i) {
            dK += rule.kronrodWeights[i] * tau[i];
            dG += rule.gaussWeights[i] * tau[i];
            // Optical depth from w.lo to node i: the interpolant of tau integrated.
            double phi = 0;
            for (int j = 0; j < n; ++j) phi += rule.cumulative[i][j] * tau[j];
            const double att = std::exp(-half * phi);
            for (int c = 0; c < 3; ++c) {
                const double v = emission[i][c] * att;
                cK[c] += rule.kronrodWeights[i] * v;
                cG[c] += rule.gaussWeights[i] * v;
            }
        }
        dK *= half;
        dG *= half;
        const double errD = std::abs(dK - dG);
        double errC = 0, cMax = 0;
        for (int c = 0; c < 3; ++c) {
            cK[c] *= half;
            cG[c] *= half;
            errC = std::max(errC, std::abs(cK[c] - cG[c]));
            cMax = std::max(cMax, std::abs(cK[c]));
        }
        // The depth error also shifts the attenuation inside this interval.
        errC += cMax * errD;
        const double T = composite.transmittance;
        const double behind = s.glow == GlowModel::WilliamsMax
                                  ? 1.0
                                  : 1.0 + s.colorMax * std::max(0.0, tEnd_ - w.hi);
        const double estimate = T * (1 + kKronrodMargin) * (errC + errD * behind);
        if (estimate > budgetPerLength * (w.hi - w.lo) && w.depth < kMaxKronrodDepth &&
            evaluations < kMaxKronrodEvaluations) {
            stack_.push_back({mid, w.hi, w.depth + 1});
            stack_.push_back({w.lo, mid, w.depth + 1});
            continue;
        }
        ++kronrodIntervals_;
        // The Gauss results are kept: the Kronrod differences estimate their errors
        // sharply (signed for the emission), where they would overstate the Kronrod
        // results' by orders of magnitude. The Kronrod rule's own error is taken as at most
        // kKronrodMargin of the difference; the depth error inside the interval (in the
        // attenuation) stays an absolute term.
        double rgb[3], tauMin = tau[0];
        for (int i = 0; i < n; ++i) tauMin = std::min(tauMin, tau[i]);
        for (int c = 0; c < 3; ++c) {
            rgb[c] = T * cG[c];
            const double d = cK[c] - cG[c];
            composite.signedError[c] += T * d;
            composite.error[c] += T * (kKronrodMargin * std::abs(d) + cMax * errD) +
                                  64 * kEps * std::abs(rgb[c]);
        }
        composite.AddColor(rgb);
        AddFieldError(w.hi - w.lo, dG, tauMin, T, colorSlope * state_[0].error,
                      tauSlope * state_[fieldCount_ - 1].error, composite);
        composite.rgba[3] += T * -std::expm1(-dG);
        composite.transmittance = T * std::exp(-dG);
        composite.depthError += (1 + kKronrodMargin) * errD + 16 * kEps * std::abs(dG);
        // The nodes nearest the ends stand for the ends' emission density.
        RecordEnds(w.lo, w.hi, tau[0], emission[0], tau[n - 1], emission[n - 1],
                   composite.transmittance);
    }
}

bool VolumeRayMarcher::Terminate(double t, RayComposite& composite) {
    const VolumeSetup& s = *setup_;
    // What lies behind t changes the pixel by at most T times this per channel: a convex
    // combination of chromaticities and surface colours (<= 1) for Williams-Max, glow
    // times the remaining length plus surfaces for Wilhelms-Van Gelder.
    const double behind = s.glow == GlowModel::WilliamsMax
                              ? 1.0
                              : 1.0 + s.colorMax * std::max(0.0, tEnd_ - t);
    const double bound = composite.transmittance * behind;
    if (bound > 0.1 * s.tolerance) return false;
    // The bound is an upper one (what lies behind may be transparent): stop only when it
    // is no larger than the error estimated so far (or a floor near rounding), so that
    // the estimate stays close to the true error.
    double sofar = 1e-14;
    for (int c = 0; c < 3; ++c)
        sofar = std::max(sofar, composite.error[c] + std::abs(composite.signedError[c]));
    if (bound > sofar) return false;
    for (double& e : composite.error) e += bound;
    return true;
}

[[gnu::flatten]] VolumeRayMarcher::LinearTetResult VolumeRayMarcher::LinearTet(
    const MeshGeometry& geometry, const Segment& seg, const SegmentEnds& ends,
    RayComposite& composite) {
    const VolumeSetup& s = *setup_;
    const std::uint8_t kind = s.cellKind[seg.cell];
    if (kind == VolumeSetup::kEmpty) return LinearTetResult::kEmpty;
    crossings_.clear();
    if (kind == VolumeSetup::kConstant) {
        seg_ = seg;
        kind_ = kind;
        BeginConstantCell(seg.cell);
    } else {
        if (!linearTetField_ || !ends.enter.Valid() || !ends.exit.Valid() ||
            !geometry.IsDerived(seg.cell))
            return LinearTetResult::kOther;
        seg_ = seg;
        state_[0] = FieldState{};
        // Sets nothing when it fails; BeginSegment then takes the cell's own path.
        if (!LinearFromFacePoints(0, ends)) return LinearTetResult::kOther;
        kind_ = kind;
        fieldCount_ = 1;
        // LinearCrossings gives them in the order of the breakpoints, so ascending where
        // the field rises and descending where it falls: sorted without a sort.
        LinearCrossings(0, seg);
        if (state_[0].valueExit < state_[0].valueEnter)
            std::reverse(crossings_.begin(), crossings_.end());
        crossings_.erase(std::unique(crossings_.begin(), crossings_.end()),
                         crossings_.end());
    }
    mode_ = Mode::kClosed;
    // Integrate(seg.tEnter, seg.tExit) (the crossings lie strictly inside), its pieces
    // queued and composited in order by FlushLinearTets.
    const bool varying = kind == VolumeSetup::kVarying;
    double p0 = seg.tEnter;
    for (const double t : crossings_) {
        QueueLinearTetPiece(p0, t, varying);
        p0 = t;
    }
    QueueLinearTetPiece(p0, seg.tExit, varying);
    if (queued_ < kQueuedPieces) return LinearTetResult::kGoOn;
    return FlushLinearTets(composite) ? LinearTetResult::kStop : LinearTetResult::kGoOn;
}

#if defined(__AVX2__)
namespace {

/// std::max(a, b) and std::min(a, b) lane by lane, NaN included: (a < b) ? b : a and
/// (b < a) ? b : a (MAXPD and MINPD return their second operand where either is NaN).
inline __m256d Max(__m256d a, __m256d b) { return _mm256_max_pd(b, a); }
inline __m256d Min(__m256d a, __m256d b) { return _mm256_min_pd(b, a); }
inline __m256d Abs(__m256d a) { return _mm256_andnot_pd(_mm256_set1_pd(-0.0), a); }

}  // namespace

VolumeRayMarcher::GroupResult VolumeRayMarcher::LinearTetGroup(
    const MeshGeometry& geometry, const Segment* segs, const SegmentEnds* ends,
    double sliverLength, double tMin, double tMax, const IsoCells* isoCells,
    RayComposite& composite) {
    const VolumeSetup& s = *setup_;
    if (!groupable_) return {0, false};
    // LinearTet's conditions for one piece by LinearFromFacePoints, lane by lane: the
    // group is the segments before the first that fails them.
    double gradient[4];
    int lanes = 4;
    for (int j = 0; j < 4; ++j) {
        const Segment& seg = segs[j];
        if (IsSpanEndSliver(seg, sliverLength, tMin, tMax) ||
            s.cellKind[seg.cell] != VolumeSetup::kVarying || !ends[j].enter.Valid() ||
            !ends[j].exit.Valid() || !geometry.IsDerived(seg.cell) ||
            (isoCells && isoCells->Holds(seg.cell))) {
            lanes = j;
            break;
        }
        gradient[j] = (*s.gradientBound[0])[seg.cell];
        if (!(gradient[j] >= 0)) {
            lanes = j;
            break;
        }
    }
    if (lanes == 0) return {0, false};
    // Lanes past the group repeat its first segment (their results are not used).
    int src[4];
    for (int j = 0; j < 4; ++j) {
        src[j] = j < lanes ? j : 0;
        gradient[j] = gradient[src[j]];
    }
    const double* u = s.pointValues[0];
    // LinearFromFacePoints: the face points' sums and the bound of their error.
    // From registers (a vector load of four scalar stores just made would wait for them).
    const __m256d g = _mm256_setr_pd(gradient[0], gradient[1], gradient[2], gradient[3]);
    const __m256d grad0 = _mm256_mul_pd(g, _mm256_set1_pd(frameGradient_[0]));
    const __m256d grad1 = _mm256_mul_pd(g, _mm256_set1_pd(frameGradient_[1]));
    const __m256d grad2 = _mm256_mul_pd(g, _mm256_set1_pd(frameGradient_[2]));
    __m256d value[2], t[2], error = _mm256_setzero_pd();
    for (int e = 0; e < 2; ++e) {
        const FacePoint* q[4];
        for (int j = 0; j < 4; ++j)
            q[j] = e == 0 ? &ends[src[j]].enter : &ends[src[j]].exit;
        auto field = [&](int m) {
            return _mm256_setr_pd(u[q[0]->v[m]], u[q[1]->v[m]], u[q[2]->v[m]],
                                  u[q[3]->v[m]]);
        };
        auto member = [&](auto get) {
            return _mm256_setr_pd(get(*q[0]), get(*q[1]), get(*q[2]), get(*q[3]));
        };
        const __m256d u0 = field(0), u1 = field(1), u2 = field(2);
        const __m256d w0 = member([](const FacePoint& p) { return p.w[0]; });
        const __m256d w1 = member([](const FacePoint& p) { return p.w[1]; });
        const __m256d w2 = member([](const FacePoint& p) { return p.w[2]; });
        const __m256d au = Max(Max(Abs(u0), Abs(u1)), Abs(u2));
        value[e] =
            _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(w0, u0), _mm256_mul_pd(w1, u1)),
                          _mm256_mul_pd(w2, u2));
        const __m256d rounding = _mm256_mul_pd(_mm256_set1_pd(4 * kEps), au);
        const __m256d off0 = member([](const FacePoint& p) { return p.off[0]; });
        const __m256d off1 = member([](const FacePoint& p) { return p.off[1]; });
        const __m256d off2 = member([](const FacePoint& p) { return p.off[2]; });
        const __m256d off = _mm256_add_pd(
            _mm256_add_pd(_mm256_mul_pd(grad0, off0), _mm256_mul_pd(grad1, off1)),
            _mm256_mul_pd(grad2, off2));
        error =
            Max(error, _mm256_add_pd(_mm256_mul_pd(_mm256_set1_pd(2.0), off), rounding));
        t[e] = member([](const FacePoint& p) { return p.t; });
    }
    const __m256d tEnter = _mm256_setr_pd(segs[src[0]].tEnter, segs[src[1]].tEnter,
                                          segs[src[2]].tEnter, segs[src[3]].tEnter);
    const __m256d tExit = _mm256_setr_pd(segs[src[0]].tExit, segs[src[1]].tExit,
                                         segs[src[2]].tExit, segs[src[3]].tExit);
    const __m256d slope =
        _mm256_div_pd(_mm256_sub_pd(value[1], value[0]), _mm256_sub_pd(t[1], t[0]));
    const __m256d valueEnter = _mm256_blendv_pd(
        _mm256_add_pd(value[0], _mm256_mul_pd(slope, _mm256_sub_pd(tEnter, t[0]))),
        value[0], _mm256_cmp_pd(tEnter, t[0], _CMP_EQ_OQ));
    const __m256d valueExit = _mm256_blendv_pd(
        _mm256_add_pd(value[0], _mm256_mul_pd(slope, _mm256_sub_pd(tExit, t[0]))),
        value[1], _mm256_cmp_pd(tExit, t[1], _CMP_EQ_OQ));
    const __m256d fieldError =
        _mm256_add_pd(_mm256_set1_pd(8 * kEps * s.fieldScale[0]), error);
    // LinearCrossings: only a breakpoint strictly between the end values can split a
    // segment into more pieces; the group ends before the first segment where one lies
    // so.
    const __m256d lo = Min(valueEnter, valueExit), hi = Max(valueEnter, valueExit);
    __m256d inside = _mm256_setzero_pd();
    for (const double b : s.breakpoints) {
        const __m256d bv = _mm256_set1_pd(b);
        inside = _mm256_or_pd(inside, _mm256_and_pd(_mm256_cmp_pd(lo, bv, _CMP_LT_OQ),
                                                    _mm256_cmp_pd(bv, hi, _CMP_LT_OQ)));
    }
    if (const int split = _mm256_movemask_pd(inside); split != 0) {
        lanes = std::min(lanes, __builtin_ctz(static_cast<unsigned>(split)));
        if (lanes == 0) return {0, false};
    }
    // QueueLinearTetPiece over the whole segment: the field at its middle picks each
    // transfer function's piece (FieldAt: the ends exactly, else interpolated).
    const __m256d mid = _mm256_mul_pd(_mm256_set1_pd(0.5), _mm256_add_pd(tEnter, tExit));
    const __m256d x =
        _mm256_div_pd(_mm256_sub_pd(mid, tEnter), _mm256_sub_pd(tExit, tEnter));
    __m256d middle =
        _mm256_add_pd(_mm256_mul_pd(_mm256_sub_pd(_mm256_set1_pd(1.0), x), valueEnter),
                      _mm256_mul_pd(x, valueExit));
    middle = _mm256_blendv_pd(middle, valueExit, _mm256_cmp_pd(mid, tExit, _CMP_EQ_OQ));
    middle = _mm256_blendv_pd(middle, valueEnter, _mm256_cmp_pd(mid, tEnter, _CMP_EQ_OQ));
    const __m256i kc = s.colorTf.IntervalOf4(middle);
    const __m256i ke = s.extinctionTf.IntervalOf4(middle);
    __m256d c0[3], c1[3], tau0, tau1;
    s.colorTf.EvalOn3x4(kc, valueEnter, valueExit, c0, c1);
    s.extinctionTf.EvalOn1x4(ke, valueEnter, valueExit, tau0, tau1);
    const __m256d zero = _mm256_setzero_pd();
    alignas(32) double out[13][4];
    _mm256_store_pd(out[0], Max(zero, tau0));
    _mm256_store_pd(out[1], Max(zero, tau1));
    for (int c = 0; c < 3; ++c) {
        _mm256_store_pd(out[2 + c], Max(zero, c0[c]));
        _mm256_store_pd(out[5 + c], Max(zero, c1[c]));
    }
    _mm256_store_pd(out[8], _mm256_mul_pd(s.colorTf.SteepestOn4(kc), fieldError));
    _mm256_store_pd(out[9], _mm256_mul_pd(s.extinctionTf.SteepestOn4(ke), fieldError));
    _mm256_store_pd(out[10], valueEnter);
    _mm256_store_pd(out[11], valueExit);
    _mm256_store_pd(out[12], fieldError);
    // LinearTet's state as after the last segment; the caches of face point sums and
    // transfer-function values (which only save work) are dropped.
    const int last = lanes - 1;
    seg_ = segs[last];
    FieldState& st = state_[0];
    st.constant = st.bySeries = false;
    st.linear = true;
    st.valueEnter = out[10][last];
    st.valueExit = out[11][last];
    st.error = out[12][last];
    kind_ = VolumeSetup::kVarying;
    fieldCount_ = 1;
    mode_ = Mode::kClosed;
    crossings_.clear();
    faceSums_[0].t = std::numeric_limits<double>::quiet_NaN();
    lastColor_.piece = lastExtinction_.piece = -2;
    // Queued: FlushLinearTets integrates the queue's pieces in batches (of eight where
    // the processor has AVX-512, which a group of four alone would not fill) and
    // composites each as LinearTet's own.
    groupedSegments_ += lanes;
    for (int j = 0; j < lanes; ++j) {
        if (queued_ == queue_.size()) queue_.resize(queued_ + kQueuedPieces);
        QueuedPiece& piece = queue_[queued_++];
        piece.p0 = segs[j].tEnter;
        piece.p1 = segs[j].tExit;
        piece.length = piece.p1 - piece.p0;
        piece.varying = true;
        piece.tau0 = out[0][j];
        piece.tau1 = out[1][j];
        for (int c = 0; c < 3; ++c) {
            piece.c0[c] = out[2 + c][j];
            piece.c1[c] = out[5 + c][j];
        }
        piece.colorError = out[8][j];
        piece.tauError = out[9][j];
        if (queued_ >= kQueuedPieces && FlushLinearTets(composite)) return {j + 1, true};
    }
    return {lanes, false};
}
#else
VolumeRayMarcher::GroupResult VolumeRayMarcher::LinearTetGroup(
    const MeshGeometry&, const Segment*, const SegmentEnds*, double, double, double,
    const IsoCells*, RayComposite&) {
    return {0, false};
}
#endif

[[gnu::flatten]] VolumeRayMarcher::LinearTetRunResult VolumeRayMarcher::LinearTetRun(
    const MeshGeometry& geometry, const Segment* segs, const SegmentEnds* ends,
    std::size_t first, std::size_t last, double sliverLength, double tMin, double tMax,
    const IsoCells* isoCells, RayComposite& composite) {
    LinearTetRunResult r{last, false, false, 0.0};
    // A segment that ended a group is known not to start one.
    std::size_t ungroupable = last;
    for (std::size_t k = first; k < last; ++k) {
        if (k + 4 <= last && k != ungroupable) {
            const GroupResult g =
                LinearTetGroup(geometry, segs + k, ends + k, sliverLength, tMin, tMax,
                               isoCells, composite);
            if (g.stop) {
                r.seen = r.stop = true;
                r.next = k + std::size_t(g.taken);
                return r;
            }
            if (g.taken > 0) {
                r.seen = true;
                k += std::size_t(g.taken) - 1;
                if (g.taken < 4) ungroupable = k + 1;
                continue;
            }
        }
        const Segment& seg = segs[k];
        if (IsSpanEndSliver(seg, sliverLength, tMin, tMax)) {
            r.culled += 1;
            continue;
        }
        // An isosurface may lie here: the general path takes the segment.
        if (isoCells && isoCells->Holds(seg.cell)) {
            r.next = k;
            return r;
        }
        switch (LinearTet(geometry, seg, ends[k], composite)) {
            case LinearTetResult::kEmpty:
                r.culled += 1;
                break;
            case LinearTetResult::kGoOn:
                r.seen = true;
                break;
            case LinearTetResult::kStop:
                r.seen = r.stop = true;
                r.next = k + 1;
                return r;
            case LinearTetResult::kOther:
                r.next = k;
                return r;
        }
    }
    return r;
}

bool VolumeRayMarcher::Integrate(double a, double b, RayComposite& composite,
                                 RenderCounters& counters) {
    if (!(b > a)) return Terminate(b, composite);
    bounds_.clear();
    bounds_.push_back(a);
    for (double t : crossings_)
        if (t > a && t < b) bounds_.push_back(t);
    bounds_.push_back(b);
    const bool closed = kind_ == VolumeSetup::kConstant || mode_ == Mode::kClosed;
    bool stop = false;
    for (std::size_t k = 0; k + 1 < bounds_.size(); ++k) {
        const double p0 = bounds_[k], p1 = bounds_[k + 1];
        if (closed) {
            LinearPiece(p0, p1, composite);
        } else if (mode_ == Mode::kSeries) {
            SeriesPiece(p0, p1, composite);
        } else {
            KronrodPiece(p0, p1, composite);
        }
        if (Terminate(p1, composite)) {
            stop = true;
            break;
        }
    }
    if (kind_ == VolumeSetup::kVarying)
        for (int f = 0; f < fieldCount_; ++f)
            if (!state_[f].constant) field_[f].AddCountersTo(counters);
    counters.volumeNodes += quadratureNodes_;
    quadratureNodes_ = 0;
    return stop;
}

}  // namespace hpray
