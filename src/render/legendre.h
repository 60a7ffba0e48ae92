// Legendre series on an interval: Legendre–Gauss–Lobatto nodes, interpolation, evaluation.
#pragma once

#include <atomic>
#include <cmath>
#include <vector>

#include "util/check.h"

namespace hpray {

/// The n + 1 Legendre–Gauss–Lobatto nodes on [-1, 1] (ascending, endpoints exact) and their
/// quadrature weights. Cached per n; thread-safe. 1 <= n <= kMaxLegendreDegree.
struct LglRule {
    std::vector<double> nodes;
    std::vector<double> weights;
    /// pk[i * (n + 1) + k] = P_k(nodes[i]): the interpolation transform's matrix.
    std::vector<double> legendreAtNodes;
    /// transform[k * (n + 1) + i] = weights[i] P_k(nodes[i]) / (discrete norm of P_k): the
    /// interpolation transform, coefficient k = sum_i transform[k][i] value_i.
    std::vector<double> transform;
    /// The same transposed, each row padded with zeros to transformStride (a multiple of
    /// 4): [i * transformStride + k].
    std::vector<double> transformByNode;
    int transformStride = 0;
};
inline constexpr int kMaxLegendreDegree = 64;
namespace detail {
/// The rules built so far (null: not yet), and the call that builds one.
extern std::atomic<const LglRule*> lglBuilt[kMaxLegendreDegree + 1];
const LglRule& BuildLglNodes(int n);
}  // namespace detail
/// Looked up for every exact series of a segment: once built, one acquire load.
inline const LglRule& LglNodes(int n) {
    HPRAY_CHECK(n >= 1 && n <= kMaxLegendreDegree);
    if (const LglRule* r = detail::lglBuilt[n].load(std::memory_order_acquire)) return *r;
    return detail::BuildLglNodes(n);
}

/// The three-term recurrence P_k = a[k] x P_{k-1} - b[k] P_{k-2} with a[k] = (2k - 1) / k
/// and b[k] = (k - 1) / k as products (no division per term): the one table of every
/// evaluation of Legendre series, so that all of them round alike.
struct LegendreRecurrence {
    static constexpr int kSize = 2 * kMaxLegendreDegree + 4;
    double a[kSize] = {}, b[kSize] = {};
    constexpr LegendreRecurrence() {
        for (int k = 2; k < kSize; ++k) {
            a[k] = double(2 * k - 1) / k;
            b[k] = double(k - 1) / k;
        }
    }
};
inline constexpr LegendreRecurrence kLegendreRecurrence{};

/// P_0(x) .. P_n(x) into p[0..n] in long double, for tables built once.
void LegendreValuesLong(long double x, int n, long double* p);

/// The n + 1 Chebyshev–Lobatto nodes x_j = sin(pi (2j - n) / (2n)) = -cos(j pi / n) on
/// [-1, 1] (ascending, endpoints exact, exactly antisymmetric), with the transform from
/// values at them to the Legendre coefficients of their interpolant. The nodes nest:
/// those of n are bitwise the even-indexed nodes of 2n, so a projection raised from
/// degree n to 2n keeps its n + 1 samples and adds n. Cached per n; thread-safe. 1 <= n
/// <= kMaxLegendreDegree.
struct ChebyshevLobattoRule {
    std::vector<double> nodes;
    /// transformByNode[i * transformStride + k]: coefficient k = sum_i of it times
    /// value_i (rows padded with zeros to a multiple of 4).
    std::vector<double> transformByNode;
    int transformStride = 0;
};
const ChebyshevLobattoRule& ChebyshevLobattoNodes(int n);

/// A polynomial of degree coeffs.size() - 1 on [a, b], p(t) = sum_k c_k P_k(x(t)) with
/// x = (2t - a - b) / (b - a) in [-1, 1].
struct LegendreSeries {
    double a = 0, b = 1;
    std::vector<double> c;

    int Degree() const { return static_cast<int>(c.size()) - 1; }
    /// p(t) by the three-term recurrence (any t; accurate on [a, b]). The evaluations use
    /// explicit fused multiply-adds.
    double operator()(double t) const;
    /// The same, inline (the same operations: bitwise the same value), for the few hot
    /// loops that evaluate short series many times; elsewhere operator() keeps callers
    /// small.
    double At(double t) const;
    /// p(t[s]) into out[s] for s < count, the points evaluated together (vectorised).
    void EvalMany(const double* t, int count, double* out) const;
    /// p(t) and dp/dt.
    void Eval(double t, double& value, double& derivative) const;
    /// sum_{k>=1} |c_k|: |p(t) - c_0| <= Tail() on [a, b] since |P_k| <= 1 there.
    double Tail() const;
    /// The derivative dp/dt as a series of degree n - 1 on the same interval.
    LegendreSeries Derivative() const;
    /// The same into `out` (reusing its storage).
    void Derivative(LegendreSeries& out) const;
    /// The antiderivative integral_a^t p as a series of degree n + 1 on the same interval
    /// (zero at t = a).
    LegendreSeries Antiderivative() const;
    /// The same into `out` (reusing its storage; not *this). With withoutMean, that of
    /// p - c_0 (the same operations as on a copy whose c_0 is zero).
    void Antiderivative(LegendreSeries& out, bool withoutMean = false) const;
};

inline double LegendreSeries::At(double t) const {
    const double x = (2 * t - a - b) / (b - a);
    const int n = Degree();
    HPRAY_CHECK(n < LegendreRecurrence::kSize);
    const LegendreRecurrence& rec = kLegendreRecurrence;
    double v = c[0];
    if (n >= 1) v += c[1] * x;
    double p0 = 1, p1 = x;
    for (int k = 2; k <= n; ++k) {
        const double p2 = std::fma(rec.a[k] * x, p1, -rec.b[k] * p0);
        v = std::fma(c[k], p2, v);
        p0 = p1;
        p1 = p2;
    }
    return v;
}

/// p(t[s]) into outP[s] and q(t[s]) into outQ[s] for s < count, for two series on the same
/// interval (any degrees): the Legendre polynomials are computed once for both.
void EvalPair(const LegendreSeries& p, const LegendreSeries& q, const double* t, int count,
              double* outP, double* outQ);

/// Interpolates `values` at the n + 1 LGL nodes of [a, b] (values[i] at node i) exactly by
/// the degree-n Legendre series (discrete Legendre transform with the Lobatto correction
/// of the last coefficient).
LegendreSeries InterpolateLgl(const double* values, int n, double a, double b);
/// The same into `out` (reusing its storage).
void InterpolateLgl(const double* values, int n, double a, double b, LegendreSeries& out);

/// Interpolates `values` at the n + 1 Chebyshev–Lobatto nodes of [a, b] (values[i] at
/// node i) by the degree-n Legendre series, into `out` (reusing its storage).
void InterpolateChebyshevLobatto(const double* values, int n, double a, double b,
                                 LegendreSeries& out);

/// Re-expands `p` on the sub-interval [lo, hi] (same degree), by evaluating it at the LGL
/// nodes of [lo, hi]. `scratch` is caller-owned and resized as needed.
LegendreSeries Restrict(const LegendreSeries& p, double lo, double hi,
                        std::vector<double>& scratch);
/// The same into `out` (reusing its storage; `out` must not be `p`).
void Restrict(const LegendreSeries& p, double lo, double hi, std::vector<double>& scratch,
              LegendreSeries& out);

}  // namespace hpray
