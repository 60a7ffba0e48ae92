// Legendre–Gauss–Lobatto rules and Legendre series arithmetic.
#include "render/legendre.h"

#include <cmath>
#include <memory>
#include <mutex>

#include "util/check.h"

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
    return r;
}

}  // namespace

const LglRule& LglNodes(int n) {
    HPRAY_CHECK(n >= 1 && n <= kMaxLegendreDegree);
    static std::once_flag flags[kMaxLegendreDegree + 1];
    static std::unique_ptr<LglRule> rules[kMaxLegendreDegree + 1];
    std::call_once(flags[n], [n] { rules[n] = std::make_unique<LglRule>(BuildRule(n)); });
    return *rules[n];
}

double LegendreSeries::operator()(double t) const {
    double v, d;
    Eval(t, v, d);
    return v;
}

void LegendreSeries::Eval(double t, double& value, double& derivative) const {
    const double x = (2 * t - a - b) / (b - a);
    // Forward recurrence for P_k and P_k' together: stable for |x| <= 1.
    double p0 = 1, p1 = x, d0 = 0, d1 = 1;
    double v = c[0], dv = 0;
    const int n = Degree();
    if (n >= 1) {
        v += c[1] * x;
        dv += c[1];
    }
    for (int k = 2; k <= n; ++k) {
        const double p2 = ((2 * k - 1) * x * p1 - (k - 1) * p0) / k;
        const double d2 = d0 + (2 * k - 1) * p1;  // P_k' = P_{k-2}' + (2k-1) P_{k-1}
        v += c[k] * p2;
        dv += c[k] * d2;
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
    // p' = sum_k d_k P_k with d_{k-1} = (2k-1) sum_{j >= k, j - k even} c_j (in x), then
    // scaled by dx/dt = 2 / (b - a).
    LegendreSeries d;
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
    return d;
}

LegendreSeries InterpolateLgl(const double* values, int n, double a, double b) {
    const LglRule& rule = LglNodes(n);
    LegendreSeries s;
    s.a = a;
    s.b = b;
    s.c.assign(n + 1, 0.0);
    for (int k = 0; k <= n; ++k) {
        double sum = 0;
        for (int i = 0; i <= n; ++i)
            sum += rule.weights[i] * values[i] * rule.legendreAtNodes[i * (n + 1) + k];
        // Discrete norms: 2 / (2k + 1), except 2 / n for k = n under Lobatto quadrature.
        const double norm = (k < n) ? 2.0 / (2 * k + 1) : 2.0 / n;
        s.c[k] = sum / norm;
    }
    return s;
}

LegendreSeries Restrict(const LegendreSeries& p, double lo, double hi,
                        std::vector<double>& scratch) {
    const int n = std::max(p.Degree(), 1);
    const LglRule& rule = LglNodes(n);
    scratch.resize(n + 1);
    for (int i = 0; i <= n; ++i)
        scratch[i] = p(0.5 * (lo + hi) + 0.5 * (hi - lo) * rule.nodes[i]);
    return InterpolateLgl(scratch.data(), n, lo, hi);
}

}  // namespace hpray
