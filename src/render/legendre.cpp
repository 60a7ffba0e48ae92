// Legendre–Gauss–Lobatto rules and Legendre series arithmetic.
#include "render/legendre.h"

#if defined(__AVX2__) && defined(__FMA__)
#include <immintrin.h>
#endif

#include <algorithm>
#include <atomic>
#include <cmath>
#include <memory>
#include <mutex>

#include "util/check.h"
#include "util/dense_inverse.h"

namespace hpray {
namespace {

// P_n(x) and P_n'(x) by the three-term recurrence.
void Legendre(int n, double x, double& p, double& dp) {
    double p0 = 1, p1 = x;
    if (n == 0) {
        p = 1;
        dp = 0;
        return;
    }
    for (int k = 2; k <= n; ++k) {
        const double p2 = ((2 * k - 1) * x * p1 - (k - 1) * p0) / k;
        p0 = p1;
        p1 = p2;
    }
    p = p1;
    // P_n'(x) = n (x P_n - P_{n-1}) / (x^2 - 1), valid for |x| < 1.
    dp = n * (x * p1 - p0) / (x * x - 1);
}

LglRule BuildRule(int n) {
    LglRule r;
    r.nodes.resize(n + 1);
    r.weights.resize(n + 1);
    r.nodes[0] = -1;
    r.nodes[n] = 1;
    // Interior nodes: roots of P_n'; Newton from the Chebyshev–Gauss–Lobatto points, using
    // (1 - x^2) P_n'' = 2x P_n' - n(n+1) P_n.
    for (int i = 1; i < n; ++i) {
        double x = -std::cos(M_PI * i / n);
        for (int it = 0; it < 100; ++it) {
            double p, dp;
            Legendre(n, x, p, dp);
            const double d2p = (2 * x * dp - n * (n + 1) * p) / (1 - x * x);
            const double dx = dp / d2p;
            x -= dx;
            if (std::abs(dx) < 1e-16) break;
        }
        r.nodes[i] = x;
    }
    // Symmetrise: the rule is exactly symmetric about 0.
    for (int i = 0; i <= n / 2; ++i) {
        const double x = 0.5 * (r.nodes[n - i] - r.nodes[i]);
        r.nodes[i] = -x;
        r.nodes[n - i] = x;
    }
    if (n % 2 == 0) r.nodes[n / 2] = 0;
    for (int i = 0; i <= n; ++i) {
        double p, dp;
        Legendre(n, r.nodes[i], p, dp);
        if (i == 0 || i == n) p = (i == n || n % 2 == 0) ? 1.0 : -1.0;
        r.weights[i] = 2.0 / (n * (n + 1) * p * p);
    }
    r.legendreAtNodes.resize((n + 1) * (n + 1));
    for (int i = 0; i <= n; ++i) {
        const double x = r.nodes[i];
        double p0 = 1, p1 = x;
        r.legendreAtNodes[i * (n + 1)] = 1;
        if (n >= 1) r.legendreAtNodes[i * (n + 1) + 1] = x;
        for (int k = 2; k <= n; ++k) {
            const double p2 = ((2 * k - 1) * x * p1 - (k - 1) * p0) / k;
            r.legendreAtNodes[i * (n + 1) + k] = p2;
            p0 = p1;
            p1 = p2;
        }
    }
    // Discrete norms: 2 / (2k + 1), except 2 / n for k = n under Lobatto quadrature.
    r.transform.resize((n + 1) * (n + 1));
    r.transformStride = (n + 1 + 3) / 4 * 4;
    r.transformByNode.assign(std::size_t(n + 1) * r.transformStride, 0.0);
    for (int k = 0; k <= n; ++k) {
        const double norm = (k < n) ? 2.0 / (2 * k + 1) : 2.0 / n;
        for (int i = 0; i <= n; ++i) {
            const double v = r.weights[i] * r.legendreAtNodes[i * (n + 1) + k] / norm;
            r.transform[k * (n + 1) + i] = v;
            r.transformByNode[i * r.transformStride + k] = v;
        }
    }
    return r;
}

}  // namespace

namespace detail {
std::atomic<const LglRule*> lglBuilt[kMaxLegendreDegree + 1];

const LglRule& BuildLglNodes(int n) {
    HPRAY_CHECK(n >= 1 && n <= kMaxLegendreDegree);
    static std::once_flag flags[kMaxLegendreDegree + 1];
    static std::unique_ptr<LglRule> rules[kMaxLegendreDegree + 1];
    // Published for LglNodes' lookup once built (std::call_once sets thread-locals and
    // calls pthread_once on every call: not for the per-segment path).
    std::call_once(flags[n], [n] {
        rules[n] = std::make_unique<LglRule>(BuildRule(n));
        lglBuilt[n].store(rules[n].get(), std::memory_order_release);
    });
    return *rules[n];
}
}  // namespace detail

namespace {}  // namespace

void LegendreValuesLong(long double x, int n, long double* p) {
    p[0] = 1;
    if (n >= 1) p[1] = x;
    for (int k = 1; k < n; ++k)
        p[k + 1] = ((2 * k + 1) * x * p[k] - k * p[k - 1]) / (k + 1);
}

namespace {

ChebyshevLobattoRule BuildChebyshevLobatto(int n) {
    ChebyshevLobattoRule r;
    r.nodes.resize(n + 1);
    // sin of the angle from the middle: exactly antisymmetric, and the argument of node j
    // of n is bitwise that of node 2j of 2n (numerator and denominator both doubled).
    for (int j = 0; j <= n; ++j)
        r.nodes[j] = std::sin(M_PI * double(2 * j - n) / double(2 * n));
    r.nodes[0] = -1;
    r.nodes[n] = 1;
    if (n % 2 == 0) r.nodes[n / 2] = 0;
    // The inverse of V[i][k] = P_k(x_i) in long double (V is well conditioned at these
    // nodes: the rounding left is far below a double's).
    const int m = n + 1;
    std::vector<long double> v(std::size_t(m) * m);
    for (int i = 0; i < m; ++i) LegendreValuesLong(r.nodes[i], n, &v[std::size_t(i) * m]);
    const std::vector<long double> inv = InvertDense(m, std::move(v));
    // Row k of the inverse maps the values to coefficient k.
    r.transformStride = (m + 3) / 4 * 4;
    r.transformByNode.assign(std::size_t(m) * r.transformStride, 0.0);
    for (int k = 0; k < m; ++k)
        for (int i = 0; i < m; ++i)
            r.transformByNode[std::size_t(i) * r.transformStride + k] =
                static_cast<double>(inv[std::size_t(k) * m + i]);
    return r;
}

}  // namespace

const ChebyshevLobattoRule& ChebyshevLobattoNodes(int n) {
    HPRAY_CHECK(n >= 1 && n <= kMaxLegendreDegree);
    static std::once_flag flags[kMaxLegendreDegree + 1];
    static std::unique_ptr<ChebyshevLobattoRule> rules[kMaxLegendreDegree + 1];
    std::call_once(flags[n], [n] {
        rules[n] = std::make_unique<ChebyshevLobattoRule>(BuildChebyshevLobatto(n));
    });
    return *rules[n];
}

namespace {

constexpr int kRecurrenceSize = LegendreRecurrence::kSize;
constexpr const LegendreRecurrence& kRec = kLegendreRecurrence;

}  // namespace

double LegendreSeries::operator()(double t) const { return At(t); }

void LegendreSeries::EvalMany(const double* t, int count, double* out) const {
    const int n = Degree();
    HPRAY_CHECK(n < kRecurrenceSize);
    const double scale = 2 / (b - a), shift = (a + b) / (b - a);
    constexpr int kBlock = 8;
    for (int s0 = 0; s0 < count; s0 += kBlock) {
        const int m = std::min(kBlock, count - s0);
        double x[kBlock], p0[kBlock], p1[kBlock], v[kBlock];
        for (int s = 0; s < kBlock; ++s) {
            // Padding lanes repeat the block's first point.
            x[s] = (s < m ? t[s0 + s] : t[s0]) * scale - shift;
            p0[s] = 1;
            p1[s] = x[s];
            v[s] = c[0];
        }
        if (n >= 1)
            for (int s = 0; s < kBlock; ++s) v[s] += c[1] * x[s];
        for (int k = 2; k <= n; ++k) {
            const double ak = kRec.a[k], bk = kRec.b[k], ck = c[k];
            for (int s = 0; s < kBlock; ++s) {
                const double p2 = std::fma(ak * x[s], p1[s], -bk * p0[s]);
                v[s] = std::fma(ck, p2, v[s]);
                p0[s] = p1[s];
                p1[s] = p2;
            }
        }
        for (int s = 0; s < m; ++s) out[s0 + s] = v[s];
    }
}

void EvalPair(const LegendreSeries& p, const LegendreSeries& q, const double* t, int count,
              double* outP, double* outQ) {
    HPRAY_CHECK(p.a == q.a && p.b == q.b);
    const int np = p.Degree(), nq = q.Degree(), n = std::max(np, nq);
    HPRAY_CHECK(n < kRecurrenceSize);
    const double scale = 2 / (p.b - p.a), shift = (p.a + p.b) / (p.b - p.a);
    constexpr int kBlock = 8;
    for (int s0 = 0; s0 < count; s0 += kBlock) {
        const int m = std::min(kBlock, count - s0);
        double x[kBlock], p0[kBlock], p1[kBlock], v[kBlock], w[kBlock];
        for (int s = 0; s < kBlock; ++s) {
            x[s] = (s < m ? t[s0 + s] : t[s0]) * scale - shift;
            p0[s] = 1;
            p1[s] = x[s];
            v[s] = p.c[0];
            w[s] = q.c[0];
        }
        if (np >= 1)
            for (int s = 0; s < kBlock; ++s) v[s] += p.c[1] * x[s];
        if (nq >= 1)
            for (int s = 0; s < kBlock; ++s) w[s] += q.c[1] * x[s];
        for (int k = 2; k <= n; ++k) {
            const double ak = kRec.a[k], bk = kRec.b[k];
            const double ck = k <= np ? p.c[k] : 0.0, dk = k <= nq ? q.c[k] : 0.0;
            for (int s = 0; s < kBlock; ++s) {
                const double p2 = std::fma(ak * x[s], p1[s], -bk * p0[s]);
                v[s] = std::fma(ck, p2, v[s]);
                w[s] = std::fma(dk, p2, w[s]);
                p0[s] = p1[s];
                p1[s] = p2;
            }
        }
        for (int s = 0; s < m; ++s) {
            outP[s0 + s] = v[s];
            outQ[s0 + s] = w[s];
        }
    }
}

void LegendreSeries::Eval(double t, double& value, double& derivative) const {
    const double x = (2 * t - a - b) / (b - a);
    // Forward recurrence for P_k and P_k' together: stable for |x| <= 1.
    double p0 = 1, p1 = x, d0 = 0, d1 = 1;
    double v = c[0], dv = 0;
    const int n = Degree();
    HPRAY_CHECK(n < kRecurrenceSize);
    if (n >= 1) {
        v += c[1] * x;
        dv += c[1];
    }
    for (int k = 2; k <= n; ++k) {
        const double p2 = std::fma(kRec.a[k] * x, p1, -kRec.b[k] * p0);
        const double d2 = std::fma(2 * k - 1, p1, d0);  // P_k' = P_{k-2}' + (2k-1) P_{k-1}
        v = std::fma(c[k], p2, v);
        dv = std::fma(c[k], d2, dv);
        p0 = p1;
        p1 = p2;
        d0 = d1;
        d1 = d2;
    }
    value = v;
    derivative = dv * 2 / (b - a);
}

double LegendreSeries::Tail() const {
    double s = 0;
    for (std::size_t k = 1; k < c.size(); ++k) s += std::abs(c[k]);
    return s;
}

LegendreSeries LegendreSeries::Derivative() const {
    LegendreSeries d;
    Derivative(d);
    return d;
}

void LegendreSeries::Derivative(LegendreSeries& d) const {
    // p' = sum_k d_k P_k with d_{k-1} = (2k-1) sum_{j >= k, j - k even} c_j (in x), then
    // scaled by dx/dt = 2 / (b - a).
    d.a = a;
    d.b = b;
    const int n = Degree();
    d.c.assign(std::max(n, 1), 0.0);
    double even = 0, odd = 0;  // running sums of c_j over j of each parity, from the top
    for (int j = n; j >= 1; --j) {
        if (j % 2 == 0) even += c[j];
        else odd += c[j];
        // d_{j-1} = (2(j-1)+1) * sum_{m >= j, m - j even} c_m
        d.c[j - 1] = (2 * (j - 1) + 1) * ((j % 2 == 0) ? even : odd);
    }
    for (double& v : d.c) v *= 2 / (b - a);
}

LegendreSeries LegendreSeries::Antiderivative() const {
    LegendreSeries r;
    Antiderivative(r);
    return r;
}

void LegendreSeries::Antiderivative(LegendreSeries& r, bool withoutMean) const {
    // integral_{-1}^x P_0 = P_1 + P_0; integral_{-1}^x P_k = (P_{k+1} - P_{k-1}) / (2k + 1)
    // for k >= 1 (zero at -1); times dt/dx = (b - a) / 2.
    HPRAY_CHECK(&r != this);
    r.a = a;
    r.b = b;
    const int n = Degree();
    r.c.resize(n + 2);
    double* out = r.c.data();
    const double h = 0.5 * (b - a);
    // The sums of the identity above, term by term in their order of accumulation:
    // r_0 = (0 + h c_0) - q_1, r_1 = (0 + h c_0) - q_2 and r_j = (0 + q_{j-1}) - q_{j+1},
    // where q_k = h c_k / (2k + 1) for 1 <= k <= n and there is no q beyond n. The zeros
    // the sums start from are kept (0 + x turns a -0 into +0).
    // Each q_k enters two sums: computed once (the divisions are most of the cost), and
    // kept while the sums two terms on still need it.
    auto q = [&](int k) { return h * c[k] / (2 * k + 1); };
    const double h0 = 0.0 + h * (withoutMean ? 0.0 : c[0]);
    double qLo = n >= 1 ? q(1) : 0, qHi = n >= 2 ? q(2) : 0;  // q_{j-1}, q_j for j = 2
    out[0] = n >= 1 ? h0 - qLo : h0;
    out[1] = n >= 2 ? h0 - qHi : h0;
    for (int j = 2; j <= n + 1; ++j) {
        const double up = 0.0 + qLo;
        double qNext = 0;
        if (j + 1 <= n) {
            qNext = q(j + 1);
            out[j] = up - qNext;
        } else {
            out[j] = up;
        }
        qLo = qHi;
        qHi = qNext;
    }
}

LegendreSeries InterpolateLgl(const double* values, int n, double a, double b) {
    LegendreSeries s;
    InterpolateLgl(values, n, a, b, s);
    return s;
}

namespace {
#if defined(__AVX2__) && defined(__FMA__)
// ApplyTransform's sums for rows of V whole vectors, held in registers across the rows:
// per lane the same fused multiply-adds in the same order.
template <int V>
void TransformRows(const double* m, int stride, const double* values, int n, double* c) {
    __m256d acc[V];
    for (int q = 0; q < V; ++q) acc[q] = _mm256_setzero_pd();
    for (int i = 0; i <= n; ++i, m += stride) {
        const __m256d v = _mm256_set1_pd(values[i]);
        for (int q = 0; q < V; ++q)
            acc[q] = _mm256_fmadd_pd(_mm256_loadu_pd(m + 4 * q), v, acc[q]);
    }
    for (int q = 0; q < V; ++q) _mm256_storeu_pd(c + 4 * q, acc[q]);
}
#endif

// The series of degree n on [a, b] whose coefficients are the transform applied to the
// values: c += value_i * row i of transformByNode (vectorised over k; rows padded to
// whole vectors, up to 8 of them summed in registers).
void ApplyTransform(const std::vector<double>& transformByNode, int stride,
                    const double* values, int n, double a, double b, LegendreSeries& s) {
    s.a = a;
    s.b = b;
    // Written whole by the vectorised rows; zeroed only for the scalar sums.
    double c[kMaxLegendreDegree + 4];
    const double* m = transformByNode.data();
#if defined(__AVX2__) && defined(__FMA__)
    using Rows = void (*)(const double*, int, const double*, int, double*);
    static constexpr Rows kRows[9] = {
        nullptr,           &TransformRows<1>, &TransformRows<2>,
        &TransformRows<3>, &TransformRows<4>, &TransformRows<5>,
        &TransformRows<6>, &TransformRows<7>, &TransformRows<8>};
    if (stride % 4 == 0 && stride / 4 <= 8) {
        kRows[stride / 4](m, stride, values, n, c);
        s.c.assign(c, c + n + 1);
        return;
    }
#endif
    std::fill_n(c, stride, 0.0);
    for (int i = 0; i <= n; ++i, m += stride) {
        const double v = values[i];
        for (int k = 0; k < stride; ++k) c[k] = std::fma(m[k], v, c[k]);
    }
    s.c.assign(c, c + n + 1);
}
}  // namespace

void InterpolateLgl(const double* values, int n, double a, double b, LegendreSeries& s) {
    const LglRule& rule = LglNodes(n);
    ApplyTransform(rule.transformByNode, rule.transformStride, values, n, a, b, s);
}

void InterpolateChebyshevLobatto(const double* values, int n, double a, double b,
                                 LegendreSeries& s) {
    const ChebyshevLobattoRule& rule = ChebyshevLobattoNodes(n);
    ApplyTransform(rule.transformByNode, rule.transformStride, values, n, a, b, s);
}

LegendreSeries Restrict(const LegendreSeries& p, double lo, double hi,
                        std::vector<double>& scratch) {
    LegendreSeries out;
    Restrict(p, lo, hi, scratch, out);
    return out;
}

void Restrict(const LegendreSeries& p, double lo, double hi, std::vector<double>& scratch,
              LegendreSeries& out) {
    const int n = std::max(p.Degree(), 1);
    const LglRule& rule = LglNodes(n);
    scratch.resize(2 * (n + 1));
    double* ts = scratch.data() + n + 1;
    for (int i = 0; i <= n; ++i) ts[i] = 0.5 * (lo + hi) + 0.5 * (hi - lo) * rule.nodes[i];
    p.EvalMany(ts, n + 1, scratch.data());
    InterpolateLgl(scratch.data(), n, lo, hi, out);
}

}  // namespace hpray
