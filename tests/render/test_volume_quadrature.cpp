// The nested quadrature ladder of the series-mode volume integrator
// (GetNestedQuadratureRules): each rule against Patterson's published nodes and weights
// (Math. Comp. 22, 1968, table of the 3-7-15-31 sequence) and the polynomial degree each
// integrates exactly, and the nesting that lets a rung reuse the nodes of the one below.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "render/volume.h"

namespace hpray {
namespace {

using Rules = NestedQuadratureRules;

/// integral_{-1}^1 x^k dx.
double MonomialIntegral(int k) { return k % 2 == 1 ? 0.0 : 2.0 / (k + 1); }

template <typename F>
double Apply(const Rules& r, int rule, const F& f) {
    double sum = 0;
    for (int i = 0; i < Rules::Size(rule); ++i) sum += r.weights[rule][i] * f(r.nodes[i]);
    return sum;
}

TEST(NestedQuadrature, NodesAndWeightsArePattersons) {
    const Rules& r = GetNestedQuadratureRules();
    // Positive nodes and weights of the 15- and 31-point rules (the 15-point nodes are
    // among the 31-point ones), to 20 digits.
    const double x15[8] = {0.0,
                           0.22338668642896688163,
                           0.43424374934680255800,
                           0.62110294673722640294,
                           0.77459666924148337704,
                           0.88845923287225699889,
                           0.96049126870802028342,
                           0.99383196321275502221};
    const double w15[8] = {0.22551049979820668739, 0.21915685840158749640,
                           0.20062852937698902103, 0.17151190913639138079,
                           0.13441525524378422036, 0.09292719531512453768,
                           0.05160328299707973969, 0.01700171962994026033};
    const double x31new[8] = {0.11248894313318662575, 0.33113539325797683309,
                              0.53131974364437562397, 0.70249620649152707861,
                              0.83672593816886873550, 0.92965485742974005667,
                              0.98153114955374010687, 0.99909812496766759766};
    auto find = [&](double x, int size) {
        int best = 0;
        for (int i = 1; i < size; ++i)
            if (std::abs(r.nodes[i] - x) < std::abs(r.nodes[best] - x)) best = i;
        return best;
    };
    for (int k = 0; k < 8; ++k) {
        const int i = find(x15[k], Rules::Size(3));
        EXPECT_NEAR(r.nodes[i], x15[k], 2e-16) << k;
        EXPECT_NEAR(r.weights[3][i], w15[k], 2e-16) << k;
        const int j = find(x31new[k], Rules::Size(4));
        EXPECT_GE(j, Rules::Size(3)) << k;
        EXPECT_NEAR(r.nodes[j], x31new[k], 2e-16) << k;
    }
    // Gauss 3 and the midpoint in closed form.
    EXPECT_EQ(r.nodes[0], 0.0);
    EXPECT_EQ(r.weights[0][0], 2.0);
    EXPECT_NEAR(r.weights[1][0], 8.0 / 9, 1e-16);
    EXPECT_NEAR(std::abs(r.nodes[1]), std::sqrt(0.6), 1e-16);
    EXPECT_NEAR(r.weights[1][1], 5.0 / 9, 1e-16);
}

TEST(NestedQuadrature, EachRuleIsExactToItsDegreeAndNoFurther) {
    const Rules& r = GetNestedQuadratureRules();
    for (int rule = 0; rule < Rules::kRules; ++rule) {
        const int n = Rules::Size(rule);
        double sum = 0;
        for (int i = 0; i < n; ++i) {
            EXPECT_GT(r.weights[rule][i], 0) << rule << " " << i;
            EXPECT_LT(std::abs(r.nodes[i]), 1.0);
            for (int j = 0; j < i; ++j) EXPECT_NE(r.nodes[i], r.nodes[j]);
            sum += r.weights[rule][i];
        }
        for (int i = n; i < Rules::kMaxNodes; ++i) EXPECT_EQ(r.weights[rule][i], 0.0);
        EXPECT_NEAR(sum, 2.0, 1e-15);
        const int degree = Rules::Degree(rule);
        for (int k = 0; k <= degree; ++k) {
            const double q = Apply(r, rule, [&](double x) { return std::pow(x, k); });
            EXPECT_NEAR(q, MonomialIntegral(k), 1e-15) << "rule " << rule << " x^" << k;
        }
        // The first even degree beyond is not integrated exactly (the degree is sharp;
        // for the 31-point rule that miss is below double's rounding).
        if (rule + 1 < Rules::kRules) {
            const int beyond = degree + 1 + (degree + 1) % 2;
            const double q =
                Apply(r, rule, [&](double x) { return std::pow(x, beyond); });
            EXPECT_GT(std::abs(q - MonomialIntegral(beyond)), 1e-9) << "rule " << rule;
        }
    }
}

TEST(NestedQuadrature, RandomPolynomialsAndASmoothIntegrand) {
    const Rules& r = GetNestedQuadratureRules();
    // Random Legendre series of each rule's degree: only the constant term integrates to
    // non-zero.
    for (int seed = 0; seed < 200; ++seed) {
        std::mt19937_64 rng(seed);
        std::uniform_real_distribution<double> u(-1, 1);
        const int rule = seed % Rules::kRules;
        const int degree = Rules::Degree(rule);
        std::vector<double> c(degree + 1);
        for (double& v : c) v = u(rng);
        auto series = [&](double x) {
            double p0 = 1, p1 = x, s = c[0] + (degree >= 1 ? c[1] * x : 0.0);
            for (int k = 1; k < degree; ++k) {
                const double p2 = ((2 * k + 1) * x * p1 - k * p0) / (k + 1);
                s += c[k + 1] * p2;
                p0 = p1;
                p1 = p2;
            }
            return s;
        };
        EXPECT_NEAR(Apply(r, rule, series), 2 * c[0], 2e-14) << seed;
    }
    // exp(3x): the error falls with each rule; the 31-point rule to rounding.
    const double truth = (std::exp(3.0) - std::exp(-3.0)) / 3;
    double last = 1e300;
    for (int rule = 0; rule < Rules::kRules; ++rule) {
        const double err =
            std::abs(Apply(r, rule, [](double x) { return std::exp(3 * x); }) - truth);
        EXPECT_LT(err, last) << rule;
        last = std::max(err, 1e-300);
    }
    EXPECT_LT(last, 1e-14);
}

}  // namespace
}  // namespace hpray
