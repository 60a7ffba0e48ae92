// Volume rendering against independent truth: the closed form of a linear piece against
// long-double quadrature in every regime (d -> 0, huge and tiny depth, tiny segments),
// whole images of linear tets against a long-double ODE reference of docs/contracts.md's
// integrals (both glow models, transfer functions on different fields, breakpoints at
// vertex values), HIAC's refinement check, constant extinction over every cell type
// against the analytic chord, clipping, slices and thread invariance.
#include <gtest/gtest.h>

#include <algorithm>
#include <boost/math/quadrature/gauss.hpp>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <random>

#include "mesh/builtin.h"
#include "render/brick_renderer.h"
#include "render/legendre.h"
#include "render/ray_field.h"
#include "render/render_job.h"
#include "render/test_volume_reference.h"
#include "render/volume.h"
#include "render/volume_ray.h"
#include "scene/camera.h"
#include "scene/scene.h"
#include "trace/trace_test_meshes.h"
#include "util/error.h"

namespace hpray {
namespace {

// The camera's ray through pixel (i, j), as the traverser takes it.
Ray PixelRay(const Camera& camera, int i, int j) {
    const CameraRay cr = camera.PixelRay(i, j);
    Ray ray;
    for (int d = 0; d < 3; ++d) {
        ray.origin[d] = cr.origin[d];
        ray.dir[d] = cr.direction[d];
    }
    return ray;
}

using testing::LD;
using testing::RefPixel;
using testing::RefSurface;
using testing::RefTf;

Scene MakeScene(const std::string& yaml) { return ParseScene(yaml, "test.yaml", {}, ""); }

// ---------------------------------------------------------------------------------------
// Transfer functions.

TEST(VolumeTf, PiecewiseLinearClampedWithExactControlValues) {
    const PiecewiseLinearTf tf({-1.0, 0.5, 2.0}, {0.2, 1.0, 0.0}, 1);
    double v;
    tf.Eval(-5.0, &v);
    EXPECT_EQ(v, 0.2);
    tf.Eval(7.0, &v);
    EXPECT_EQ(v, 0.0);
    tf.Eval(0.5, &v);
    EXPECT_EQ(v, 1.0);
    tf.Eval(-0.25, &v);
    EXPECT_DOUBLE_EQ(v, 0.6);
    EXPECT_EQ(tf.IntervalOf(-1.0), 0);
    EXPECT_EQ(tf.IntervalOf(-1.5), -1);
    EXPECT_EQ(tf.IntervalOf(2.0), 2);
    EXPECT_EQ(tf.IntervalOf(std::nan("")), -1);
    // The extended affine piece reproduces the next control value exactly.
    tf.EvalOn(0, 0.5, &v);
    EXPECT_EQ(v, 1.0);
    double lo, hi;
    tf.RangeOver(-0.5, 1.0, &lo, &hi);
    EXPECT_DOUBLE_EQ(lo, 0.2 + 0.8 / 3);
    EXPECT_EQ(hi, 1.0);
    tf.RangeOver(3, 4, &lo, &hi);
    EXPECT_EQ(lo, 0.0);
    EXPECT_EQ(hi, 0.0);
}

// Values to look a transfer function up at: NaN, both infinities, each control point and
// its neighbours, and `random` values from `unit`.
std::vector<double> TfProbes(const std::vector<double>& points, int random,
                             std::mt19937& rng,
                             std::uniform_real_distribution<double>& unit) {
    std::vector<double> probes = {std::nan(""), -std::numeric_limits<double>::infinity(),
                                  std::numeric_limits<double>::infinity()};
    for (double p : points) {
        probes.push_back(p);
        probes.push_back(std::nextafter(p, -10.0));
        probes.push_back(std::nextafter(p, 10.0));
    }
    for (int k = 0; k < random; ++k) probes.push_back(unit(rng));
    return probes;
}

// IntervalOf by its definition (control points <= s, minus one; NaN counts none) for
// every list length around the fixed-count lookup's limit (ShortAscending::kMax), at the
// control points, between them, beyond them, at infinities and NaN; and ShortAscending's
// counts.
TEST(VolumeTf, IntervalOfIsItsDefinitionForShortAndLongLists) {
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> unit(-3.0, 3.0);
    for (int n = 1; n <= 2 * ShortAscending::kMax + 3; ++n) {
        std::vector<double> points;
        double x = -2.5;
        for (int k = 0; k < n; ++k) points.push_back(x += 0.1 + 0.3 * (k % 3));
        const PiecewiseLinearTf tf(points, std::vector<double>(points.size(), 1.0), 1);
        ShortAscending few;
        few.Set(points);
        EXPECT_EQ(few.valid, n <= ShortAscending::kMax);
        const std::vector<double> probes = TfProbes(points, 50, rng, unit);
        for (double s : probes) {
            int atMost = 0, below = 0;
            for (double p : points) {
                atMost += p <= s;
                below += p < s;
            }
            EXPECT_EQ(tf.IntervalOf(s), atMost - 1) << "n " << n << " s " << s;
            if (few.valid) {
                EXPECT_EQ(few.CountAtMost(s), atMost) << "n " << n << " s " << s;
                EXPECT_EQ(few.CountBelow(s), below) << "n " << n << " s " << s;
            }
        }
    }
}

#if defined(__AVX2__)
// The four-lane transfer-function lookups by their scalar definitions, bitwise: for
// functions of 1 to 8 control points with 1 and 3 channels, at control points, their
// neighbours, between and beyond them, at infinities and NaN, in lanes that mix clamped
// and inner pieces.
TEST(VolumeTf, FourLaneLookupsAreTheScalarOnesBitwise) {
    std::mt19937 rng(11);
    std::uniform_real_distribution<double> unit(-3.0, 3.0);
    auto same = [](double a, double b) {
        return std::memcmp(&a, &b, sizeof a) == 0 || (std::isnan(a) && std::isnan(b));
    };
    int checked = 0;
    for (int n = 1; n <= ShortAscending::kMax; ++n) {
        for (int channels : {1, 3}) {
            std::vector<double> points, values;
            double x = -2.5;
            for (int k = 0; k < n; ++k) points.push_back(x += 0.1 + 0.37 * (k % 3));
            for (int k = 0; k < n * channels; ++k) values.push_back(unit(rng));
            const PiecewiseLinearTf tf(points, values, channels);
            std::vector<double> probes = TfProbes(points, 60, rng, unit);
            std::shuffle(probes.begin(), probes.end(), rng);
            for (std::size_t i = 0; i + 8 <= probes.size(); i += 4) {
                // Lane j looks up piece k of probe i + j (from its own interval, or a
                // neighbour's: EvalOn extends a piece beyond it) at probes i + j and i +
                // 4 + j.
                alignas(32) double s[4], a[4], b[4];
                alignas(32) std::int64_t piece[4];
                for (int j = 0; j < 4; ++j) {
                    s[j] = probes[i + j];
                    a[j] = probes[i + j];
                    b[j] = probes[i + 4 + j];
                }
                const __m256i k4 = tf.IntervalOf4(_mm256_load_pd(s));
                _mm256_store_si256(reinterpret_cast<__m256i*>(piece), k4);
                for (int j = 0; j < 4; ++j)
                    ASSERT_EQ(piece[j], tf.IntervalOf(s[j]))
                        << "n " << n << " s " << s[j];
                for (int j = 0; j < 4; ++j)
                    if (j % 2 == 1)
                        piece[j] = std::min<std::int64_t>(piece[j] + 1, n - 1);
                const __m256i k =
                    _mm256_load_si256(reinterpret_cast<const __m256i*>(piece));
                alignas(32) double outA[3][4], outB[3][4], steep[4];
                _mm256_store_pd(steep, tf.SteepestOn4(k));
                if (channels == 3) {
                    __m256d va[3], vb[3];
                    tf.EvalOn3x4(k, _mm256_load_pd(a), _mm256_load_pd(b), va, vb);
                    for (int c = 0; c < 3; ++c) {
                        _mm256_store_pd(outA[c], va[c]);
                        _mm256_store_pd(outB[c], vb[c]);
                    }
                } else {
                    __m256d va, vb;
                    tf.EvalOn1x4(k, _mm256_load_pd(a), _mm256_load_pd(b), va, vb);
                    _mm256_store_pd(outA[0], va);
                    _mm256_store_pd(outB[0], vb);
                }
                for (int j = 0; j < 4; ++j) {
                    const int kj = static_cast<int>(piece[j]);
                    EXPECT_TRUE(same(steep[j], tf.SteepestOn(kj)));
                    double ra[3], rb[3];
                    tf.EvalOn(kj, a[j], ra);
                    tf.EvalOn(kj, b[j], rb);
                    for (int c = 0; c < channels; ++c) {
                        EXPECT_TRUE(same(outA[c][j], ra[c]))
                            << "n " << n << " piece " << kj << " s " << a[j] << ": "
                            << outA[c][j] << " against " << ra[c];
                        EXPECT_TRUE(same(outB[c][j], rb[c]))
                            << "n " << n << " piece " << kj << " s " << b[j];
                        ++checked;
                    }
                }
            }
        }
    }
    EXPECT_GT(checked, 2000);
}
#endif

// ---------------------------------------------------------------------------------------
// Closed form of a linear piece.

struct RefIntegrals {
    LD T, A, I0, I1, P;
};

// Long-double Gauss-Legendre of the defining integrals on [0, 1], on cuts where the
// optical depth D(x) = alpha x + beta x^2 (increasing on [0, 1]) grows by 1/2, so the
// integrand varies by at most e^(1/2) on each; cut off where D > 80 (e^-80 relative).
RefIntegrals ReferencePiece(LD tau0, LD tau1, LD length) {
    const LD alpha = length * tau0, beta = length * (tau1 - tau0) / 2;
    auto T = [&](LD x) { return std::exp(-alpha * x - beta * x * x); };
    std::vector<LD> cuts = {0};
    for (int k = 1; k <= 160; ++k) {
        const LD D = k / 2.0L;
        if (alpha + beta <= D) break;
        // The root of alpha x + beta x^2 = D in (0, 1), in the form without cancellation.
        const LD disc = alpha * alpha + 4 * beta * D;
        cuts.push_back(2 * D / (alpha + std::sqrt(std::max<LD>(0, disc))));
    }
    cuts.push_back(1);
    auto integrate = [&](auto f) {
        LD sum = 0;
        for (std::size_t k = 0; k + 1 < cuts.size(); ++k)
            sum += boost::math::quadrature::gauss<LD, 30>::integrate(f, cuts[k],
                                                                     cuts[k + 1]);
        return sum;
    };
    RefIntegrals r;
    r.T = std::exp(-(alpha + beta));
    r.A = -std::expm1(-(alpha + beta));
    r.I0 = integrate([&](LD x) { return T(x); });
    r.I1 = integrate([&](LD x) { return x * T(x); });
    r.P = integrate([&](LD x) { return x * (alpha + 2 * beta * x) * T(x); });
    return r;
}

void ExpectPiece(double tau0, double tau1, double length, double rel = 2e-13) {
    const LinearPieceIntegrals q = IntegrateLinearPiece(tau0, tau1, length);
    const RefIntegrals r = ReferencePiece(tau0, tau1, length);
    const std::string at = "tau0=" + std::to_string(tau0) +
                           " tau1=" + std::to_string(tau1) +
                           " length=" + std::to_string(length);
    auto near = [&](double got, LD want, LD scale, const char* what) {
        EXPECT_LE(std::abs(got - want), rel * scale + 1e-300)
            << what << " " << at << " got " << got << " want " << double(want);
    };
    near(q.transmittance, r.T, r.T, "T");
    near(q.opacity, r.A, r.A, "A");
    near(q.mean, r.I0, r.I0, "I0");
    // I1 and P enter the emission next to I0 and A: relative to those.
    near(q.firstMoment, r.I1, std::max(r.I1, r.I0 * 1e-3L), "I1");
    near(q.farWeight, r.P, std::max(r.P, r.A * 1e-3L), "P");
    // The emissions are what the pixel gets: relative to themselves.
    const double wm = WilliamsMaxEmission(q, 0.3, 0.9);
    const LD wmRef = 0.3L * (r.A - r.P) + 0.9L * r.P;
    near(wm, wmRef, wmRef, "WM");
    const double g = GlowEmission(q, 0.7, 0.2, length);
    const LD gRef = length * (0.7L * (r.I0 - r.I1) + 0.2L * r.I1);
    near(g, gRef, gRef, "WVG");
}

// The exponentials of the series pieces' quadrature nodes against long double's, in
// units in the last place: 3 at most (the rounding terms of the pieces' error bars count
// 16 eps per term), over small and large arguments, the range's ends and past 708.
TEST(VolumeExp, ExpNegativeWithinThreeUlpsOfLongDouble) {
    std::mt19937_64 rng(7);
    std::uniform_real_distribution<double> small(0, 1e-3), large(0, 700);
    double worst = 0;
    for (int round = 0; round < 200000; ++round) {
        double x[8], out[8];
        for (int k = 0; k < 8; ++k) x[k] = round % 2 ? large(rng) : small(rng);
        if (round == 0) {
            x[0] = 0;
            x[1] = 708;
            x[2] = 708.5;
            x[3] = 1e300;
        }
        // Counts of 8 and of 5 (a partly filled last vector).
        ExpNegative(x, round % 3 ? 8 : 5, out);
        for (int k = 0; k < (round % 3 ? 8 : 5); ++k) {
            if (x[k] > 708) {
                EXPECT_EQ(out[k], 0.0) << x[k];
                continue;
            }
            const long double truth = std::exp(-static_cast<long double>(x[k]));
            const double near = static_cast<double>(truth);
            const double ulp = std::nextafter(near, 2 * near + 1) - near;
            worst = std::max(worst, double(std::abs(out[k] - truth) / ulp));
        }
    }
    EXPECT_LE(worst, 3.0);
    EXPECT_GT(worst, 0.0);  // the comparison saw the rounding
}

// A series piece's opacity and attenuation against long double's expm1 and exp, in ulps
// of each: within 3 below depth 0.5, where the Taylor
// series by Estrin's scheme gives both, and above, where exp does; 0 gives 0 and 1.
TEST(VolumeExp, PieceOpacityWithinItsUlpsOfLongDouble) {
    std::mt19937_64 rng(13);
    std::uniform_real_distribution<double> small(0, 0.5), exponent(-30, 5.7);
    double worstOpacity = 0, worstAttenuation = 0;
    auto ulps = [](double got, long double truth) {
        const double near = static_cast<double>(truth);
        const double ulp = std::nextafter(near, 2 * near + 1) - near;
        return double(std::abs(got - truth) / ulp);
    };
    for (int round = 0; round < 400000; ++round) {
        double d = round % 2 ? small(rng) : std::pow(2.0, exponent(rng));
        if (round == 0) d = 0.5;
        if (round == 1) d = std::nextafter(0.5, 0.0);
        double opacity, attenuation;
        PieceOpacity(d, opacity, attenuation);
        const long double o = -std::expm1(-static_cast<long double>(d));
        const long double a = std::exp(-static_cast<long double>(d));
        worstOpacity = std::max(worstOpacity, ulps(opacity, o));
        worstAttenuation = std::max(worstAttenuation, ulps(attenuation, a));
    }
    std::printf("worst: opacity %.3g ulps, attenuation %.3g ulps\n", worstOpacity,
                worstAttenuation);
    EXPECT_LE(worstOpacity, 3.0);
    EXPECT_LE(worstAttenuation, 3.0);
    EXPECT_GT(worstOpacity, 0.0);  // the comparison saw the rounding
    double opacity = -1, attenuation = -1;
    PieceOpacity(0, opacity, attenuation);
    EXPECT_EQ(opacity, 0.0);
    EXPECT_EQ(attenuation, 1.0);
}

// The logarithms of a linear pyramid's optical depth (at its quadrature nodes) against
// long double's: within 2 eps of the larger of 1 and |ln x| (the pyramid's depth bound
// takes 4), over the range the depth line feeds it ([1/1024, 2)), the mantissa's split
// at sqrt(2), powers of two and far beyond; counts of 1 to 9 (partly filled vectors).
TEST(VolumeLog, NaturalLogWithinTwoEpsOfLongDouble) {
    std::mt19937_64 rng(11);
    std::uniform_real_distribution<double> exponent(-10, 1.01), wide(-700, 700);
    double worst = 0;
    for (int round = 0; round < 200000; ++round) {
        double x[9], out[9];
        const int n = 1 + round % 9;
        for (int k = 0; k < n; ++k)
            x[k] = std::pow(2.0, round % 5 == 4 ? wide(rng) : exponent(rng));
        if (round < 2) {
            const double special[9] = {1.0,
                                       2.0,
                                       0.5,
                                       std::sqrt(2.0),
                                       std::nextafter(std::sqrt(2.0), 2.0),
                                       std::nextafter(std::sqrt(2.0), 1.0),
                                       1.0 / 1024,
                                       std::nextafter(1.0, 0.0),
                                       std::nextafter(1.0, 2.0)};
            for (int k = 0; k < n; ++k) x[k] = special[k];
        }
        NaturalLog(x, n, out);
        for (int k = 0; k < n; ++k) {
            const long double truth = std::log(static_cast<long double>(x[k]));
            const double scale = std::max(1.0, double(std::abs(truth)));
            worst = std::max(worst, double(std::abs(out[k] - truth)) /
                                        (std::numeric_limits<double>::epsilon() * scale));
        }
    }
    EXPECT_LE(worst, 2.0);
    EXPECT_GT(worst, 0.0);  // the comparison saw the rounding
}

// A piece's opacity (its series for depths below 0.5, lane by lane where pieces are
// batched) and transmittance (exp beyond) against long double's, in units in the last
// place: within 2 of the one computed directly, 3 of the other (1 - it).
TEST(VolumeClosedForm, OpacityAndTransmittanceWithinUlpsOfLongDouble) {
    std::mt19937_64 rng(5);
    std::uniform_real_distribution<double> unit(0, 1);
    auto ulps = [](double x, long double truth) {
        const double near = static_cast<double>(truth);
        const double ulp = std::nextafter(near, 2 * near + 1) - near;
        return double(std::abs(x - truth) / ulp);
    };
    double worstSmall = 0, worstLarge = 0;
    for (int trial = 0; trial < 200000; ++trial) {
        // Depths over many scales below 0.5, and up to 40 above.
        const double depth = trial % 2 ? 0.5 * unit(rng) * std::ldexp(1.0, -(trial % 40))
                                       : 0.5 + 40 * unit(rng);
        // Constant extinction: the depth is length * tau.
        const LinearPieceIntegrals q = IntegrateLinearPiece(depth, depth, 1.0);
        const long double opacity = -std::expm1(-static_cast<long double>(depth));
        const long double transmittance = std::exp(-static_cast<long double>(depth));
        if (depth < 0.5) {
            if (depth > 0) worstSmall = std::max(worstSmall, ulps(q.opacity, opacity));
            EXPECT_LE(ulps(q.transmittance, transmittance), 3.0) << depth;
        } else {
            worstLarge = std::max(worstLarge, ulps(q.transmittance, transmittance));
            EXPECT_LE(ulps(q.opacity, opacity), 3.0) << depth;
        }
    }
    EXPECT_LE(worstSmall, 2.0);
    EXPECT_LE(worstLarge, 2.0);
    EXPECT_GT(worstSmall, 0.0);  // the comparisons saw the rounding
}

TEST(VolumeClosedForm, AllRegimesAgainstLongDoubleQuadrature) {
    // alpha = tau0 (length 1) and beta = (tau1 - tau0) / 2 across the Taylor,
    // slope-series and erfcx / Dawson regimes and their borders.
    const double alphas[] = {0,  1e-9, 0.3, 0.999, 1.001, 2.5, 7,
                             40, 127,  129, 500,   1e4,   1e6};
    const double betas[] = {0, 1e-12, 1e-6, 0.2, 0.999, 1.001, 3, 30, 64, 200, 5e3, 1e6};
    int checked = 0;
    for (double a : alphas)
        for (double b : betas)
            for (int sign : {1, -1}) {
                const double beta = sign * b;
                if (a + 2 * beta < 0) continue;  // tau1 < 0
                ExpectPiece(a, a + 2 * beta, 1.0);
                ++checked;
            }
    // The extreme decreasing extinction: tau1 = 0 exactly.
    for (double a : alphas) ExpectPiece(a, 0.0, 1.0);
    EXPECT_GT(checked, 200);
}

TEST(VolumeClosedForm, SlopeToZeroIsSmooth) {
    // tau1 = tau0 (1 + d) for d -> 0 in each regime of tau0: no jump at any threshold and
    // the constant-extinction limit exactly.
    for (double tau0 : {0.01, 0.7, 3.0, 150.0, 2e5})
        for (int k = 1; k <= 17; ++k) {
            const double d = std::pow(10.0, -k);
            ExpectPiece(tau0, tau0 * (1 + d), 1.0);
            ExpectPiece(tau0, tau0 * (1 - d), 1.0);
        }
    for (double tau : {0.01, 0.7, 3.0, 150.0, 2e5}) {
        const LinearPieceIntegrals q = IntegrateLinearPiece(tau, tau, 1.0);
        EXPECT_NEAR(q.mean, -std::expm1(-tau) / tau, 1e-15 * q.mean);
        EXPECT_EQ(q.transmittance, std::exp(-tau));
    }
}

TEST(VolumeClosedForm, HugeDepthTinySegmentsAndZeroExtinction) {
    // Extinction 1e6 over unit and longer lengths: no overflow, no NaN, T underflows to
    // 0.
    for (double length : {1.0, 1e3}) {
        const LinearPieceIntegrals q = IntegrateLinearPiece(1e6, 3e6, length);
        EXPECT_EQ(q.transmittance, 0.0);
        EXPECT_EQ(q.opacity, 1.0);
        EXPECT_NEAR(q.mean, 1.0 / (1e6 * length), 1e-5 / (1e6 * length));
        EXPECT_TRUE(std::isfinite(q.firstMoment) && std::isfinite(q.farWeight));
    }
    ExpectPiece(1e6, 1e6, 1.0);
    ExpectPiece(1e6, 0.0, 1.0);
    ExpectPiece(0.0, 1e6, 1.0);
    ExpectPiece(1e6, 2e6, 1e-3);
    // Segments of length 1e-12 (and 0): emission proportional to the length, relatively
    // accurate.
    for (double length : {1e-12, 1e-15, 1e-300}) {
        ExpectPiece(2.0, 5.0, length);
        const LinearPieceIntegrals q = IntegrateLinearPiece(2.0, 5.0, length);
        EXPECT_NEAR(q.opacity, 3.5 * length, 4e-12 * 3.5 * length);
        // P = integral x tau(x) l T dx -> l (tau0 / 2 + (tau1 - tau0) / 3).
        EXPECT_NEAR(q.farWeight, length * (1.0 + 1.0), 4e-12 * 2 * length);
    }
    const LinearPieceIntegrals zero = IntegrateLinearPiece(1.0, 2.0, 0.0);
    EXPECT_EQ(zero.opacity, 0.0);
    EXPECT_EQ(zero.transmittance, 1.0);
    EXPECT_EQ(GlowEmission(zero, 1, 1, 0.0), 0.0);
    // Zero extinction: no opacity, glow integrates to g * length exactly.
    const LinearPieceIntegrals clear = IntegrateLinearPiece(0.0, 0.0, 2.5);
    EXPECT_EQ(clear.opacity, 0.0);
    EXPECT_EQ(clear.transmittance, 1.0);
    EXPECT_EQ(WilliamsMaxEmission(clear, 1, 1), 0.0);
    EXPECT_DOUBLE_EQ(GlowEmission(clear, 0.4, 0.8, 2.5), 2.5 * 0.6);
}

// The batched closed form gives every piece bitwise what the single one gives, in every
// regime and for any number of pieces (full and partial batches of four, and of eight
// where the processor has AVX-512).
TEST(VolumeClosedForm, BatchedPiecesEqualSinglePiecesBitwise) {
    std::mt19937_64 rng(7);
    std::uniform_real_distribution<double> uni(0, 1);
    for (int n : {1, 2, 3, 4, 5, 7, 8, 9, 13, 16, 64, 200}) {
        std::vector<double> tau0(n), tau1(n), length(n);
        for (int i = 0; i < n; ++i) {
            // Scales from 1e-6 to 1e3 for the extinction and the length, so that the
            // Taylor regime and the others mix within a batch; some zero extinction.
            tau0[i] = i % 7 == 3 ? 0.0 : std::pow(10.0, -3 + 6 * uni(rng));
            tau1[i] = i % 5 == 2 ? 0.0 : std::pow(10.0, -3 + 6 * uni(rng));
            length[i] = std::pow(10.0, -3 + 3 * uni(rng));
        }
        std::vector<LinearPieceIntegrals> batch(n), strided(n), narrow(n);
        IntegrateLinearPieces(n, tau0.data(), tau1.data(), length.data(), batch.data());
        IntegrateLinearPieces(n, tau0.data(), tau1.data(), length.data(), narrow.data(),
                              false);
        // The same inputs in an array of structures, in another order than the arguments.
        struct Piece {
            double length, pad, tau1, tau0;
            int flag;
        };
        std::vector<Piece> pieces(n);
        for (int i = 0; i < n; ++i) pieces[i] = {length[i], -1.0, tau1[i], tau0[i], i};
        IntegrateLinearPieces(n, reinterpret_cast<const unsigned char*>(pieces.data()),
                              sizeof(Piece), offsetof(Piece, tau0), offsetof(Piece, tau1),
                              offsetof(Piece, length), strided.data());
        int taylor = 0;
        for (int i = 0; i < n; ++i) {
            const LinearPieceIntegrals q =
                IntegrateLinearPiece(tau0[i], tau1[i], length[i]);
            taylor += length[i] * (tau0[i] + std::abs(tau1[i] - tau0[i]) / 2) <= 1;
            for (const LinearPieceIntegrals* b : {&batch[i], &strided[i], &narrow[i]}) {
                EXPECT_EQ(b->transmittance, q.transmittance) << n << " " << i;
                EXPECT_EQ(b->opacity, q.opacity) << n << " " << i;
                EXPECT_EQ(b->mean, q.mean) << n << " " << i;
                EXPECT_EQ(b->firstMoment, q.firstMoment) << n << " " << i;
                EXPECT_EQ(b->farWeight, q.farWeight) << n << " " << i;
            }
        }
        if (n >= 64) {
            EXPECT_GT(taylor, n / 8);
            EXPECT_LT(taylor, n - n / 8);
        }
    }
}

TEST(VolumeClosedForm, KronrodRuleIntegratesPolynomials) {
    const KronrodRule& rule = GetKronrodRule();
    // Kronrod: exact to degree 22; Gauss: degree 13; cumulative: degree 14 at every node.
    for (int p = 0; p <= 14; ++p) {
        double k = 0, g = 0;
        for (int i = 0; i < 15; ++i) {
            k += rule.kronrodWeights[i] * std::pow(rule.nodes[i], p);
            g += rule.gaussWeights[i] * std::pow(rule.nodes[i], p);
            double cum = 0;
            for (int j = 0; j < 15; ++j)
                cum += rule.cumulative[i][j] * std::pow(rule.nodes[j], p);
            const double exact =
                (std::pow(rule.nodes[i], p + 1) - std::pow(-1.0, p + 1)) / (p + 1);
            EXPECT_NEAR(cum, exact, 1e-14) << p << " " << i;
        }
        const double exact = p % 2 ? 0.0 : 2.0 / (p + 1);
        EXPECT_NEAR(k, exact, 1e-15) << p;
        if (p <= 13) {
            EXPECT_NEAR(g, exact, 1e-15) << p;
        }
    }
}

// ---------------------------------------------------------------------------------------
// Images of linear tets against the ODE reference.

// cube-tets-N with u = x + 2y + 3z and a second linear field v = 3x - y + z/2 + 1.
Mesh CubeTetsTwoFields(int n) {
    Mesh mesh = MakeBuiltin("builtin:cube-tets-" + std::to_string(n));
    Field v{"v", Association::Point, 1, {}};
    for (std::int64_t i = 0; i < mesh.PointCount(); ++i) {
        const double* x = &mesh.points[3 * i];
        v.values.push_back(3 * x[0] - x[1] + 0.5 * x[2] + 1);
    }
    mesh.pointFields.push_back(std::move(v));
    return mesh;
}

struct LinearFieldRay {
    std::array<double, 3> o, d;
    LD At(const std::array<LD, 4>& coef, LD t) const {
        LD s = coef[3];
        for (int a = 0; a < 3; ++a) s += coef[a] * (LD(o[a]) + t * LD(d[a]));
        return s;
    }
    // t where the linear field crosses each scalar.
    void Crossings(const std::array<LD, 4>& coef, const std::vector<LD>& scalars,
                   std::vector<LD>& out) const {
        LD slope = 0;
        for (int a = 0; a < 3; ++a) slope += coef[a] * LD(d[a]);
        if (slope == 0) return;
        const LD at0 = At(coef, 0);
        for (LD s : scalars) out.push_back((s - at0) / slope);
    }
};

const std::array<LD, 4> kU = {1, 2, 3, 0};
const std::array<LD, 4> kV = {3, -1, 0.5L, 1};

// Compares every pixel of `image` with the reference along the same camera ray, with
// the chord of `box` (clipped further to [near, far]) and optional surfaces.
struct CompareResult {
    int pixels = 0;
    double maxRel = 0;
};
// With `errorBound`, each pixel's vol.error must also bound its RGB's true error.
CompareResult CompareLinearImage(const Scene& scene, const Image& image,
                                 const std::string& cf, const std::string& ef, double rel,
                                 const std::array<LD, 3>& lo = {0, 0, 0},
                                 const std::array<LD, 3>& hi = {1, 1, 1},
                                 bool errorBound = false) {
    const Camera camera(scene.camera);
    const RefTf ctf = RefTf::Color(scene.volume->colorTf);
    const RefTf etf = RefTf::Extinction(scene.volume->extinctionTf);
    const bool wm = scene.volume->glow == GlowModel::WilliamsMax;
    const auto& cCoef = cf == "u" ? kU : kV;
    const auto& eCoef = ef == "u" ? kU : kV;
    CompareResult result;
    for (int j = 0; j < image.height; ++j)
        for (int i = 0; i < image.width; ++i) {
            const CameraRay cr = camera.PixelRay(i, j);
            const LinearFieldRay ray{cr.origin, cr.direction};
            LD t0, t1;
            const std::size_t p = std::size_t(j) * image.width + i;
            const bool hit =
                testing::RefBoxChord(cr.origin, cr.direction, lo, hi, t0, t1);
            t0 = std::max<LD>(t0, scene.clip.near);
            t1 = std::min<LD>(t1, scene.clip.far);
            if (!hit || t1 - t0 < 1e-5) {
                // Grazing chords are known only to rounding of their ends.
                if (!hit || t1 <= t0) {
                    EXPECT_EQ(image.a[p], 0.0) << i << "," << j;
                }
                continue;
            }
            std::vector<LD> kinks;
            ray.Crossings(cCoef, ctf.scalars, kinks);
            ray.Crossings(eCoef, etf.scalars, kinks);
            const RefPixel ref = testing::ReferenceRay(
                t0, t1, [&](LD t) { return ray.At(cCoef, t); },
                [&](LD t) { return ray.At(eCoef, t); }, ctf, etf, wm, kinks);
            const double got[4] = {image.r[p], image.g[p], image.b[p], image.a[p]};
            const LD want[4] = {ref.rgb[0], ref.rgb[1], ref.rgb[2], ref.alpha};
            for (int c = 0; c < 4; ++c) {
                const LD denom = want[c] > 0 ? want[c] : 1;
                const double err = double(std::abs(got[c] - want[c]) / denom);
                result.maxRel = std::max(result.maxRel, err);
                EXPECT_LE(err, rel) << "pixel " << i << "," << j << " channel " << c
                                    << " got " << got[c] << " want " << double(want[c]);
                if (errorBound && c < 3) {
                    EXPECT_LE(double(std::abs(got[c] - want[c])), image.volError[p])
                        << "pixel " << i << "," << j << " channel " << c;
                }
            }
            ++result.pixels;
        }
    return result;
}

const char* kLinearScene = R"(
data: {mesh: "builtin:cube-tets-4"}
camera: {position: [2.3, 1.7, 2.9], look_at: [0.5, 0.45, 0.5], up: [0, 1, 0], fov_y: 32,
         width: 28, height: 24}
volume:
  color_field: u
  extinction_field: v
  glow: williams-max
  color_tf: [[0.5, 0.1, 0.2, 0.9], [2.0, 0.2, 0.9, 0.3], [3.1, 1.0, 0.9, 0.1],
             [5.0, 0.9, 0.1, 0.4]]
  extinction_tf: [[0.0, 0.3], [1.5, 0.05], [2.2, 6.0], [3.0, 0.0], [4.0, 2.0]]
accuracy: {volume_tolerance: 1e-12}
)";

TEST(VolumeLinear, WilliamsMaxOnTwoFieldsMatchesReference) {
    const Mesh mesh = CubeTetsTwoFields(4);
    const Scene scene = MakeScene(kLinearScene);
    RenderStats stats;
    const Image image = RenderMeshJob(mesh, scene, stats);
    const CompareResult r = CompareLinearImage(scene, image, "u", "v", 1e-10);
    EXPECT_GT(r.pixels, 250);
    // Closed forms only: the estimate is at the rounding level.
    EXPECT_LT(stats.counters.volumeErrorMax, 1e-12);
    EXPECT_GT(stats.counters.volumePixels, 250);
}

// Linear tetrahedra take their fields from the face points of the walk (the values of the
// faces' linear interpolants where the ray crosses them): on a jittered mesh, whose faces
// lie at every angle to the rays, the image matches the reference and every pixel's
// vol.error bounds its true error.
TEST(VolumeLinear, FacePointFieldsOnAJitteredMeshAreWithinTheirErrorBound) {
    Mesh mesh =
        testing::GridMesh(6, 0.25, [](int, int, int) { return testing::CubeCut::Tets5; });
    Field u{"u", Association::Point, 1, {}}, v{"v", Association::Point, 1, {}};
    for (std::int64_t i = 0; i < mesh.PointCount(); ++i) {
        const double* x = &mesh.points[3 * i];
        u.values.push_back(x[0] + 2 * x[1] + 3 * x[2]);
        v.values.push_back(3 * x[0] - x[1] + 0.5 * x[2] + 1);
    }
    mesh.pointFields.push_back(std::move(u));
    mesh.pointFields.push_back(std::move(v));
    ASSERT_TRUE(BrickTraverser(Brick::WholeMesh(mesh)).FacePoints());
    const Scene scene = MakeScene(kLinearScene);
    RenderStats stats;
    const Image image = RenderMeshJob(mesh, scene, stats);
    // The image against the reference, and every pixel's vol.error bounds its error.
    EXPECT_GT(
        CompareLinearImage(scene, image, "u", "v", 1e-10, {0, 0, 0}, {1, 1, 1}, true)
            .pixels,
        250);
    EXPECT_LT(stats.counters.volumeErrorMax, 1e-12);
}

// The gradient bound that turns a face point's distance from the ray into a field error:
// on random tetrahedra (some nearly flat) with a linear field of known gradient, it is at
// least the gradient's norm and within 1e-5 of it, and NaN (the cell's own path) exactly
// where the tetrahedron is too flat to bound it.
TEST(VolumeLinear, GradientBoundOfATetrahedronHoldsTheTrueGradient) {
    std::mt19937_64 rng(11);
    std::uniform_real_distribution<double> uni(-1, 1);
    int bounded = 0, flat = 0;
    for (int trial = 0; trial < 20000; ++trial) {
        double points[12], u[4];
        const double g[3] = {uni(rng) * 10, uni(rng), uni(rng) * 1e-3};
        const double c = uni(rng);
        // Every fourth tetrahedron nearly flat: its fourth corner within 10^-k of the
        // plane of the others.
        const double flatness = trial % 4 == 0 ? std::pow(10.0, -9 * (uni(rng) + 1)) : 1;
        for (int k = 0; k < 4; ++k)
            for (int d = 0; d < 3; ++d) points[3 * k + d] = 3 + uni(rng);
        if (flatness < 1) {
            const double w = 0.5 + 0.5 * uni(rng);
            for (int d = 0; d < 3; ++d)
                points[9 + d] = w * points[d] + (1 - w) * points[3 + d] +
                                0.3 * (points[6 + d] - points[d]) +
                                flatness * (d == 2 ? 1 : 0);
        }
        for (int k = 0; k < 4; ++k)
            u[k] = c + g[0] * points[3 * k] + g[1] * points[3 * k + 1] +
                   g[2] * points[3 * k + 2];
        const std::int64_t ids[4] = {0, 1, 2, 3};
        const float bound = LinearTetGradientBound(points, u, ids);
        // The tetrahedron's determinant against the product of its edge rows' 1-norms.
        using LD = long double;
        LD e[3][3], scale = 1;
        for (int k = 0; k < 3; ++k) {
            LD norm = 0;
            for (int d = 0; d < 3; ++d) {
                e[k][d] = LD(points[3 * (k + 1) + d]) - LD(points[d]);
                norm += std::abs(e[k][d]);
            }
            scale *= norm;
        }
        const LD det = e[0][0] * (e[1][1] * e[2][2] - e[1][2] * e[2][1]) -
                       e[0][1] * (e[1][0] * e[2][2] - e[1][2] * e[2][0]) +
                       e[0][2] * (e[1][0] * e[2][1] - e[1][1] * e[2][0]);
        const LD ratio = std::abs(det) / scale;
        if (std::isnan(bound)) {
            ++flat;
            EXPECT_LT(ratio, 1.001e-6L) << trial;
            continue;
        }
        ++bounded;
        EXPECT_GT(ratio, 0.999e-6L) << trial;
        // The rounding of the values (|u| up to about 50) against the gradient, through
        // the inverse edges: 1e-16 * 50 / (1e-6 of the edges' size) at most.
        const double norm = std::sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]);
        const double slack = double(1e-14L / ratio);
        EXPECT_GE(double(bound), norm * (1 - slack)) << trial;
        EXPECT_LE(double(bound), norm * (1 + 1e-5) + slack * norm + 1e-6) << trial;
    }
    EXPECT_GT(bounded, 14000);
    EXPECT_GT(flat, 1000);
}

// Linear tetrahedra of a jittered 6^3 grid with u = x + 2y + 3z + 0.3 sin(7x) at the
// nodes.
Mesh JitteredTetsWithWavyField() {
    Mesh mesh =
        testing::GridMesh(6, 0.25, [](int, int, int) { return testing::CubeCut::Tets5; });
    Field u{"u", Association::Point, 1, {}};
    for (std::int64_t i = 0; i < mesh.PointCount(); ++i) {
        const double* x = &mesh.points[3 * i];
        u.values.push_back(x[0] + 2 * x[1] + 3 * x[2] + 0.3 * std::sin(7 * x[0]));
    }
    mesh.pointFields.push_back(std::move(u));
    return mesh;
}

// The lean path of linear tetrahedra (VolumeRayMarcher::LinearTet, taken when one point
// field drives a volume alone; its pieces queued and composited in batches) gives bitwise
// the pixel of the general one (BeginSegment and Integrate per segment), stops where it
// stops, and takes nearly every segment that holds something.
TEST(VolumeLinear, LinearTetPathEqualsTheGeneralPathBitwise) {
    Mesh mesh = JitteredTetsWithWavyField();
    // A copy of u under another name: extinction from it is the same volume, which the
    // lean path does not take (two fields) except in constant and empty cells.
    Field w = mesh.pointFields[0];
    w.name = "w";
    mesh.pointFields.push_back(std::move(w));
    const MeshGeometry geometry = MeshGeometry::Build(mesh);
    const BrickTraverser traverser(Brick::WholeMesh(mesh));
    ASSERT_TRUE(traverser.FacePoints());
    Scene scene = MakeScene(kLinearScene);
    scene.volume->extinctionField = "u";
    // Breakpoints inside segments, a constant stretch, and zero extinction (empty cells).
    scene.volume->extinctionTf = {{0.5, 0.0}, {1.0, 0.0}, {1.5, 2.0},
                                  {2.2, 2.0}, {3.0, 9.0}, {4.0, 0.5}};
    using R = VolumeRayMarcher::LinearTetResult;
    // The third pass: extinction 1e4 times higher, so that rays stop early. The fourth:
    // extinction from w, so that lean and general segments alternate along the rays.
    for (int pass = 0; pass < 4; ++pass) {
        scene.volume->glow =
            pass == 1 ? GlowModel::WilhelmsVanGelder : GlowModel::WilliamsMax;
        if (pass == 2)
            for (auto& p : scene.volume->extinctionTf) p.extinction *= 1e4;
        if (pass == 3) {
            for (auto& p : scene.volume->extinctionTf) p.extinction *= 1e-4;
            scene.volume->extinctionField = "w";
        }
        const BrickSetup setup = MakeBrickSetup(mesh, geometry, traverser, scene);
        ASSERT_TRUE(setup.volume.has_value());
        const Camera camera(scene.camera);
        VolumeRayMarcher lean, general, runner;
        RenderCounters counters;
        std::vector<Segment> segments;
        std::vector<SegmentEnds> ends;
        int taken = 0, other = 0, rays = 0, stopped = 0, runs = 0;
        for (int j = 0; j < 24; ++j)
            for (int i = 0; i < 28; ++i) {
                const Ray ray = PixelRay(camera, i, j);
                traverser.Trace(ray, 0, 1e30, segments, &ends);
                if (segments.empty()) continue;
                ++rays;
                double rgbaLean[4] = {0, 0, 0, 0}, rgbaGeneral[4] = {0, 0, 0, 0};
                RayComposite a, b;
                a.rgba = rgbaLean;
                b.rgba = rgbaGeneral;
                lean.BeginRay(*setup.volume, ray, segments.front().tEnter,
                              segments.back().tExit);
                general.BeginRay(*setup.volume, ray, segments.front().tEnter,
                                 segments.back().tExit);
                bool stopA = false, stopB = false;
                for (std::size_t k = 0; k < segments.size() && !stopB; ++k) {
                    const Segment& seg = segments[k];
                    if (general.BeginSegment(mesh, geometry, seg, counters, &ends[k]))
                        stopB = general.Integrate(seg.tEnter, seg.tExit, b, counters);
                }
                // The lean path queues pieces: it stops at the same piece, later.
                for (std::size_t k = 0; k < segments.size() && !stopA; ++k) {
                    const Segment& seg = segments[k];
                    const R r = lean.LinearTet(geometry, seg, ends[k], a);
                    if (r == R::kOther) {
                        ++other;
                        stopA = lean.FlushLinearTets(a);
                        if (!stopA &&
                            lean.BeginSegment(mesh, geometry, seg, counters, &ends[k]))
                            stopA = lean.Integrate(seg.tEnter, seg.tExit, a, counters);
                    } else {
                        taken += r != R::kEmpty;
                        stopA = r == R::kStop;
                    }
                }
                if (!stopA) stopA = lean.FlushLinearTets(a);
                ASSERT_EQ(stopA, stopB) << i << "," << j;
                stopped += stopB;
                lean.FinishRay(a);
                general.FinishRay(b);
                for (int c = 0; c < 4; ++c) EXPECT_EQ(rgbaLean[c], rgbaGeneral[c]);
                for (int c = 0; c < 3; ++c) EXPECT_EQ(a.error[c], b.error[c]);
                EXPECT_EQ(a.transmittance, b.transmittance);
                // Runs of segments in one call (LinearTetRun, as the renderer takes them
                // without isosurfaces), the segment ending a run the general way.
                double rgbaRun[4] = {0, 0, 0, 0};
                RayComposite c;
                c.rgba = rgbaRun;
                runner.BeginRay(*setup.volume, ray, segments.front().tEnter,
                                segments.back().tExit);
                bool stopC = false;
                for (std::size_t k = 0; k < segments.size() && !stopC;) {
                    const auto r =
                        runner.LinearTetRun(geometry, segments.data(), ends.data(), k,
                                            segments.size(), 0.0, 0.0, 1e30, nullptr, c);
                    ++runs;
                    stopC = r.stop;
                    if (stopC || r.next == segments.size()) break;
                    k = r.next;
                    stopC = runner.FlushLinearTets(c);
                    if (!stopC && runner.BeginSegment(mesh, geometry, segments[k],
                                                      counters, &ends[k]))
                        stopC = runner.Integrate(segments[k].tEnter, segments[k].tExit, c,
                                                 counters);
                    ++k;
                }
                if (!stopC) stopC = runner.FlushLinearTets(c);
                ASSERT_EQ(stopC, stopB) << i << "," << j;
                runner.FinishRay(c);
                for (int q = 0; q < 4; ++q) EXPECT_EQ(rgbaRun[q], rgbaGeneral[q]);
                for (int q = 0; q < 3; ++q) EXPECT_EQ(c.error[q], b.error[q]);
                EXPECT_EQ(c.transmittance, b.transmittance);
            }
        EXPECT_GT(rays, 250);
        EXPECT_LT(runs, rays + other + 1);  // a run per ray, and one after each other
#if defined(__AVX2__)
        // Runs took segments four at a time (LinearTetGroup) where they could.
        if (pass != 3) {
            EXPECT_GT(runner.GroupedSegments(), rays);
        }
#endif
        if (pass == 3) {
            EXPECT_GT(other, 5 * rays);
            EXPECT_GT(taken, 10);
            continue;
        }
        EXPECT_GT(taken, (pass == 2 ? 1 : 5) * rays);
        EXPECT_LT(other, taken / 100 + 1);
        if (pass == 2) {
            EXPECT_GT(stopped, rays / 2);
        }
    }
}

// With isosurfaces in the scene, linear tetrahedra whose cells no isovalue can cross
// still take the lean path (queued pieces), and those an isosurface may cross the general
// one, after the queue: the image is bitwise that of the general path for every segment
// (which a slice plane forces, here one outside the data, which draws nothing).
TEST(VolumeLinear, LeanPathBesideIsosurfacesEqualsTheGeneralPathBitwise) {
    const Mesh mesh = JitteredTetsWithWavyField();
    for (const char* opacity : {"0.4", "1.0"}) {
        Scene scene = MakeScene(std::string(kLinearScene) + R"(
isosurfaces:
  - {field: u, value: 2.1, color: [0.9, 0.6, 0.2], opacity: )" +
                                opacity + R"(}
  - {field: u, value: 3.4, color: [0.2, 0.6, 0.9], opacity: 0.5}
)");
        scene.volume->extinctionField = "u";
        RenderStats lean, general;
        const Image a = RenderMeshJob(mesh, scene, lean);
        scene.slices.push_back(MakeScene(R"(
data: {mesh: "builtin:cube-tets-4"}
slices:
  - {point: [0, 0, 9], normal: [0, 0, 1], field: u, color_tf: [[0, 1, 1, 1]]}
)")
                                   .slices[0]);
        const Image b = RenderMeshJob(mesh, scene, general);
        ASSERT_EQ(a.PixelCount(), b.PixelCount());
        int volume = 0;
        for (std::size_t p = 0; p < a.PixelCount(); ++p) {
            EXPECT_EQ(a.r[p], b.r[p]) << p;
            EXPECT_EQ(a.g[p], b.g[p]) << p;
            EXPECT_EQ(a.b[p], b.b[p]) << p;
            EXPECT_EQ(a.a[p], b.a[p]) << p;
            EXPECT_EQ(a.volError[p], b.volError[p]) << p;
            EXPECT_EQ(a.z[p], b.z[p]) << p;
            volume += a.a[p] > 0;
        }
        EXPECT_EQ(lean.counters.isoHits, general.counters.isoHits);
        EXPECT_GT(lean.counters.isoHits, 50);
        EXPECT_GT(volume, 200);
    }
}

TEST(VolumeLinear, WilhelmsVanGelderOnTwoFieldsMatchesReference) {
    const Mesh mesh = CubeTetsTwoFields(4);
    Scene scene = MakeScene(kLinearScene);
    scene.volume->glow = GlowModel::WilhelmsVanGelder;
    scene.volume->colorTf[1].rgb = {2.0, 0.0, 0.5};  // glow may exceed 1
    RenderStats stats;
    const Image image = RenderMeshJob(mesh, scene, stats);
    EXPECT_GT(CompareLinearImage(scene, image, "u", "v", 1e-10).pixels, 250);
    // Colour and extinction swapped between the fields.
    scene.volume->colorField = "v";
    scene.volume->extinctionField = "u";
    const Image swapped = RenderMeshJob(mesh, scene, stats);
    EXPECT_GT(CompareLinearImage(scene, swapped, "v", "u", 1e-10).pixels, 250);
}

// Transfer-function breakpoints at vertex values: cube-tets-3 has u = (i + 2j + 3k) / 3
// at its vertices, and every breakpoint below is such a value. Zero extinction below
// u = 4/3 and between 3 and 11/3 also exercises empty-space skipping.
TEST(VolumeLinear, BreakpointsEqualToVertexValues) {
    const Mesh mesh = CubeTetsTwoFields(3);
    Scene scene = MakeScene(kLinearScene);
    scene.data.mesh = "builtin:cube-tets-3";
    scene.volume->extinctionField = "u";
    scene.volume->colorTf = {
        {1.0 / 3, {0.1, 0.2, 0.9}}, {2.0, {0.2, 0.9, 0.3}}, {11.0 / 3, {1.0, 0.9, 0.1}}};
    scene.volume->extinctionTf = {{4.0 / 3, 0.0}, {5.0 / 3, 3.0},  {7.0 / 3, 3.0},
                                  {3.0, 0.0},     {11.0 / 3, 0.0}, {14.0 / 3, 5.0}};
    for (GlowModel glow : {GlowModel::WilliamsMax, GlowModel::WilhelmsVanGelder}) {
        scene.volume->glow = glow;
        RenderStats stats;
        const Image image = RenderMeshJob(mesh, scene, stats);
        EXPECT_GT(CompareLinearImage(scene, image, "u", "u", 1e-10).pixels, 250);
        if (glow == GlowModel::WilliamsMax) {
            EXPECT_GT(stats.counters.segmentsCulled, 0);  // cells with zero extinction
        }
    }
}

// Extinction 1e6 (optical depth ~1e6 over the cube): alpha 1, the colour is the
// chromaticity at the entry point, early termination stops the ray.
TEST(VolumeLinear, HugeExtinction) {
    const Mesh mesh = CubeTetsTwoFields(4);
    Scene scene = MakeScene(kLinearScene);
    scene.volume->extinctionTf = {{0.0, 1e6}, {4.0, 3e6}};
    RenderStats stats;
    const Image image = RenderMeshJob(mesh, scene, stats);
    EXPECT_GT(CompareLinearImage(scene, image, "u", "v", 1e-10).pixels, 250);
    EXPECT_LE(stats.counters.volumeErrorMax, scene.accuracy.volumeTolerance);
    // Early termination: far fewer than all segments need evaluation; every ray stops in
    // its first cells, so the field is evaluated about twice per ray.
    EXPECT_LT(stats.counters.fieldEvaluations, 8 * stats.counters.rays);
}

// HIAC's check: the cube as 5 tets and as 5 * 40^3 tets (each smaller than a pixel) give
// the same image: no small cell is lost.
TEST(VolumeLinear, OneCellAndSubPixelCellsAgree) {
    Scene scene = MakeScene(kLinearScene);
    scene.volume->extinctionField = "u";
    scene.camera.width = scene.camera.height = 24;
    RenderStats s1, s40;
    const Image one = RenderMeshJob(MakeBuiltin("builtin:cube-tets-1"), scene, s1);
    const Image fine = RenderMeshJob(MakeBuiltin("builtin:cube-tets-40"), scene, s40);
    double maxDiff = 0;
    for (std::size_t p = 0; p < one.PixelCount(); ++p) {
        maxDiff = std::max(
            {maxDiff, std::abs(one.r[p] - fine.r[p]), std::abs(one.g[p] - fine.g[p]),
             std::abs(one.b[p] - fine.b[p]), std::abs(one.a[p] - fine.a[p])});
    }
    EXPECT_LE(maxDiff, 1e-9);
    EXPECT_GT(s40.counters.segments, 30 * s1.counters.segments);
}

// Clipping: near/far along the ray and a box cut the integral exactly there.
TEST(VolumeLinear, ClipPlanesAndBoxCutExactly) {
    const Mesh mesh = CubeTetsTwoFields(4);
    Scene scene = MakeScene(kLinearScene);
    scene.clip.near = 3.6;
    scene.clip.far = 4.3;
    RenderStats stats;
    Image image = RenderMeshJob(mesh, scene, stats);
    EXPECT_GT(CompareLinearImage(scene, image, "u", "v", 1e-10).pixels, 80);
    scene.clip.near = 0;
    scene.clip.far = INFINITY;
    scene.clip.box = Box{{0.2, 0.1, 0.3}, {0.9, 0.8, 0.7}};
    image = RenderMeshJob(mesh, scene, stats);
    EXPECT_GT(CompareLinearImage(scene, image, "u", "v", 1e-10, {0.2L, 0.1L, 0.3L},
                                 {0.9L, 0.8L, 0.7L})
                  .pixels,
              80);
}

// ---------------------------------------------------------------------------------------
// Constant extinction over meshes of every cell type: alpha = 1 - exp(-sigma L).

TEST(VolumeConstant, AlphaIsOneMinusExpOfSigmaTimesChordForEveryCellType) {
    using testing::CubeCut;
    const CubeCut cuts[] = {CubeCut::Hex, CubeCut::Wedges, CubeCut::Pyramids,
                            CubeCut::PyramidsTetsX, CubeCut::Tets5};
    const double sigma = 2.7;
    Scene scene = MakeScene(R"(
data: {mesh: "builtin:cube-tets-1"}
volume:
  color_field: u
  color_tf: [[0.0, 1.0, 0.5, 0.25]]
  extinction_tf: [[0.0, 2.7]]
)");
    for (CubeCut cut : cuts) {
        Mesh mesh = testing::GridMesh(4, 0.25, [&](int, int, int) { return cut; });
        Field u{"u", Association::Point, 1, {}};
        for (std::int64_t i = 0; i < mesh.PointCount(); ++i)
            u.values.push_back(std::sin(7 * mesh.points[3 * i]) + mesh.points[3 * i + 2]);
        mesh.pointFields.push_back(std::move(u));
        const MeshGeometry geometry = MeshGeometry::Build(mesh);
        const BrickTraverser traverser(Brick::WholeMesh(mesh));
        const BrickSetup setup = MakeBrickSetup(mesh, geometry, traverser, scene);
        RenderCounters counters;
        Pixel sample;
        int checked = 0;
        for (int trial = 0; trial < 300; ++trial) {
            std::mt19937 rng(trial);
            std::uniform_real_distribution<double> uni(0.05, 0.95);
            std::normal_distribution<double> g;
            const testing::Vec3 through = {uni(rng), uni(rng), uni(rng)};
            const Ray ray = testing::MakeRayDir(through, {g(rng), g(rng), g(rng)});
            LD t0, t1;
            const std::array<double, 3> o = {ray.origin[0], ray.origin[1], ray.origin[2]};
            const std::array<double, 3> d = {ray.dir[0], ray.dir[1], ray.dir[2]};
            ASSERT_TRUE(testing::RefBoxChord(o, d, {0, 0, 0}, {1, 1, 1}, t0, t1));
            IntegrateRay(setup, ray, sample, counters);
            const LD alpha = -std::expm1(-LD(sigma) * (t1 - t0));
            EXPECT_NEAR(sample.rgba[3], double(alpha), 1e-12 * double(alpha))
                << int(cut) << " " << trial;
            // Williams-Max with constant chromaticity: RGB = kappa * alpha.
            EXPECT_NEAR(sample.rgba[1], 0.5 * double(alpha), 1e-12 * double(alpha));
            ++checked;
        }
        EXPECT_EQ(checked, 300);
        // Constant transfer functions: no field is evaluated.
        EXPECT_EQ(counters.fieldEvaluations, 0) << int(cut);
    }
}

// The same on curved isoparametric hexes with extinction linear in u = x (the world x
// coordinate, exact on the curved cells): tau = a + b x(t) along the ray, so the optical
// depth is a L + b integral x dt in closed form, while the renderer takes the Kronrod
// path.
TEST(VolumeConstant, LinearExtinctionOfXOnCurvedHexes) {
    const Mesh mesh = testing::CurvedHexesWithFieldX(0.06);
    Scene scene = MakeScene(R"(
data: {mesh: "builtin:nk-sinc"}
volume:
  color_field: u
  color_tf: [[0.0, 1.0, 1.0, 1.0]]
  extinction_tf: [[-1.0, 0.5], [2.0, 6.5]]
accuracy: {volume_tolerance: 1e-12}
)");
    const MeshGeometry geometry = MeshGeometry::Build(mesh);
    const BrickTraverser traverser(Brick::WholeMesh(mesh));
    const BrickSetup setup = MakeBrickSetup(mesh, geometry, traverser, scene);
    RenderCounters counters;
    Pixel sample;
    for (int trial = 0; trial < 100; ++trial) {
        std::mt19937 rng(trial);
        std::uniform_real_distribution<double> uni(0.05, 0.95);
        std::normal_distribution<double> g;
        const Ray ray =
            testing::MakeRayDir({uni(rng), uni(rng), uni(rng)}, {g(rng), g(rng), g(rng)});
        LD t0, t1;
        const std::array<double, 3> o = {ray.origin[0], ray.origin[1], ray.origin[2]};
        const std::array<double, 3> d = {ray.dir[0], ray.dir[1], ray.dir[2]};
        ASSERT_TRUE(testing::RefBoxChord(o, d, {0, 0, 0}, {1, 1, 1}, t0, t1));
        IntegrateRay(setup, ray, sample, counters);
        // tau(u) = 2.5 + 2 u; integral of x over the chord = L (x(t0) + x(t1)) / 2.
        const LD L = t1 - t0;
        const LD xMid = LD(o[0]) + (t0 + t1) / 2 * LD(d[0]);
        const LD alpha = -std::expm1(-(2.5L * L + 2 * L * xMid));
        EXPECT_NEAR(sample.rgba[3], double(alpha), 1e-12) << trial;
        EXPECT_LE(sample.volError, 1e-11) << trial;
        // Williams-Max with white chromaticity: RGB = alpha.
        EXPECT_NEAR(sample.rgba[0], double(alpha), 1e-11) << trial;
    }
    EXPECT_GT(counters.inversions, 0);  // the curved cells were evaluated through Newton
    EXPECT_EQ(counters.inversionFailures, 0);
}

// ---------------------------------------------------------------------------------------
// Linear pyramids: the field is rational along a ray. The truth, written without the
// renderer's basis: in a cube cut into six pyramids about its centre, the field at x is
// the bilinear interpolant of the face's corner values at the projection of x from the
// centre onto the face, blended linearly with the centre's value by how far x is from
// the centre (1 on the face, 0 at the centre), in long double.

namespace {

// A mesh's geometry and walk, and a SegmentField of its first point field begun on each
// segment of a ray.
struct FieldAlongRays {
    explicit FieldAlongRays(const Mesh& m)
        : mesh(m),
          geometry(MeshGeometry::Build(m)),
          sel{&m.pointFields[0], 0},
          traverser(Brick::WholeMesh(m)) {}
    // visit(segment) for the ray's segments from tMin, sf begun on each.
    template <typename Visit>
    void ForEachSegment(const Ray& ray, double tMin, Visit&& visit) {
        traverser.Trace(ray, tMin, 1e30, segs);
        for (const Segment& seg : segs) {
            sf.Begin(mesh, geometry, sel, seg.cell, ray, InversionOptions{});
            visit(seg);
        }
    }
    const Mesh& mesh;
    const MeshGeometry geometry;
    const ScalarSelector sel;
    const BrickTraverser traverser;
    std::vector<Segment> segs;
    SegmentField sf;
    CellScratch scratch;
};

// A point field "u" on mesh, its values uniform in [-amplitude, amplitude] from rng.
void AddUniformPointField(Mesh& mesh, std::mt19937_64& rng, double amplitude) {
    std::uniform_real_distribution<double> val(-amplitude, amplitude);
    Field u{"u", Association::Point, 1, {}};
    for (std::int64_t i = 0; i < mesh.PointCount(); ++i) u.values.push_back(val(rng));
    mesh.pointFields.push_back(std::move(u));
}

// The scene of the checks against the ODE reference: transfer functions with breakpoints
// inside the fields' ranges, a tight tolerance.
constexpr const char* kOdeReferenceScene = R"(
data: {mesh: "builtin:cube-tets-1"}
volume:
  color_field: u
  color_tf: [[-0.5, 0.1, 0.2, 0.9], [0.2, 1.0, 0.6, 0.2], [1.0, 0.3, 1.0, 0.4]]
  extinction_tf: [[-0.5, 0.2], [0.1, 3.0], [0.6, 0.5], [1.2, 2.0]]
accuracy: {volume_tolerance: 1e-10}
)";

struct OdeCheck {
    double worst = 0;  ///< largest RGB error of a pixel
    int checked = 0;
};

// The volume of kOdeReferenceScene over mesh on rays through random points of [0.05,
// 0.95]^3 (ray `trial` from seed `trial`; `adjust` may move the point) in random
// directions, each pixel against the ODE reference of the
// field `truth` along the ray inside the unit cube, whose kinks are the t that `cuts`
// appends and the transfer functions' breakpoints crossed between them: the error bar
// holds and the tolerance is met on every ray.
// With two fields: colour from `truth` (field u), extinction from `extinction` (field v).
template <typename Adjust, typename Truth, typename Extinction, typename Cuts>
OdeCheck CheckTwoFieldsAgainstTheOdeReference(const Mesh& mesh, const char* sceneText,
                                              int rays, RenderCounters& counters,
                                              Adjust&& adjust, Truth&& truth,
                                              Extinction&& extinction, Cuts&& cuts) {
    const Scene scene = MakeScene(sceneText);
    const MeshGeometry geometry = MeshGeometry::Build(mesh);
    const BrickTraverser traverser(Brick::WholeMesh(mesh));
    const BrickSetup setup = MakeBrickSetup(mesh, geometry, traverser, scene);
    const RefTf ctf = RefTf::Color(scene.volume->colorTf);
    const RefTf etf = RefTf::Extinction(scene.volume->extinctionTf);
    OdeCheck out;
    Pixel sample;
    for (int trial = 0; trial < rays; ++trial) {
        std::mt19937 rng(trial);
        std::uniform_real_distribution<double> uni(0.05, 0.95);
        std::normal_distribution<double> gauss;
        testing::Vec3 through = {uni(rng), uni(rng), uni(rng)};
        adjust(trial, through);
        const Ray ray =
            testing::MakeRayDir(through, {gauss(rng), gauss(rng), gauss(rng)});
        const std::array<double, 3> o = {ray.origin[0], ray.origin[1], ray.origin[2]};
        const std::array<double, 3> d = {ray.dir[0], ray.dir[1], ray.dir[2]};
        LD t0, t1;
        EXPECT_TRUE(testing::RefBoxChord(o, d, {0, 0, 0}, {1, 1, 1}, t0, t1)) << trial;
        auto field = [&](LD t) {
            return truth(
                std::array<LD, 3>{o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]});
        };
        auto efield = [&](LD t) {
            return extinction(
                std::array<LD, 3>{o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]});
        };
        std::vector<LD> bounds;
        cuts(o, d, bounds);
        bounds.push_back(t0);
        bounds.push_back(t1);
        std::sort(bounds.begin(), bounds.end());
        std::vector<LD> kinks;
        for (std::size_t k = 0; k + 1 < bounds.size(); ++k) {
            const LD a = std::max(bounds[k], t0), b = std::min(bounds[k + 1], t1);
            if (!(b > a)) continue;
            kinks.push_back(a);
            for (const auto& p : scene.volume->colorTf)
                testing::SampledCrossings(field, a, b, p.scalar, 64, kinks);
            for (const auto& p : scene.volume->extinctionTf)
                testing::SampledCrossings(efield, a, b, p.scalar, 64, kinks);
        }
        const RefPixel ref = testing::ReferenceRay(t0, t1, field, efield, ctf, etf, true,
                                                   kinks, {}, 1e-16L);
        IntegrateRay(setup, ray, sample, counters);
        double err = 0;
        for (int c = 0; c < 3; ++c)
            err = std::max(err, double(std::abs(sample.rgba[c] - ref.rgb[c])));
        EXPECT_LE(err, sample.volError + 1e-14) << trial;  // the error bar holds
        EXPECT_LE(err, scene.accuracy.volumeTolerance) << trial;
        EXPECT_NEAR(sample.rgba[3], double(ref.alpha), 1e-10) << trial;
        out.worst = std::max(out.worst, err);
        ++out.checked;
    }
    return out;
}

template <typename Adjust, typename Truth, typename Cuts>
OdeCheck CheckAgainstTheOdeReference(const Mesh& mesh, int rays, RenderCounters& counters,
                                     Adjust&& adjust, Truth&& truth, Cuts&& cuts) {
    return CheckTwoFieldsAgainstTheOdeReference(mesh, kOdeReferenceScene, rays, counters,
                                                adjust, truth, truth, cuts);
}

struct PyramidGridTruth {
    int n;
    std::function<LD(LD, LD, LD)> g;  // the nodal values are g at the nodes
    LD operator()(const std::array<LD, 3>& x) const {
        const LD h = LD(1) / n;
        int cube[3];
        LD c[3], d[3];
        for (int k = 0; k < 3; ++k) {
            cube[k] = std::clamp(int(std::floor(x[k] / h)), 0, n - 1);
            c[k] = (cube[k] + LD(0.5)) * h;
            d[k] = x[k] - c[k];
        }
        int axis = 0;
        for (int k = 1; k < 3; ++k)
            if (std::abs(d[k]) > std::abs(d[axis])) axis = k;
        const LD centre = g(c[0], c[1], c[2]);
        const LD reach = std::abs(d[axis]) / (h / 2);  // 1 on the face, 0 at the centre
        if (reach == 0) return centre;
        // The projection onto the face, and the face's bilinear interpolant there.
        LD p[3];
        for (int k = 0; k < 3; ++k) p[k] = c[k] + d[k] / reach;
        const int a = (axis + 1) % 3, b = (axis + 2) % 3;
        const LD wa = (p[a] - cube[a] * h) / h, wb = (p[b] - cube[b] * h) / h;
        auto corner = [&](int ia, int ib) {
            LD q[3];
            q[axis] = p[axis];
            q[a] = (cube[a] + ia) * h;
            q[b] = (cube[b] + ib) * h;
            return g(q[0], q[1], q[2]);
        };
        const LD face = (1 - wa) * (1 - wb) * corner(0, 0) +
                        wa * (1 - wb) * corner(1, 0) + (1 - wa) * wb * corner(0, 1) +
                        wa * wb * corner(1, 1);
        return reach * face + (1 - reach) * centre;
    }
};

// The t where the ray o + t d crosses a face of the n^3 grid of unit cubes, and with
// `pyramids` a face of the pyramids each cube is cut into (x_i - c_i = +-(x_j - c_j)
// about its centre c): the kinks of a cell-wise field along the ray.
void GridCuts(int n, bool pyramids, const std::array<double, 3>& o,
              const std::array<double, 3>& d, std::vector<LD>& cuts) {
    for (int axis = 0; axis < 3; ++axis)
        for (int k = 0; k <= n; ++k)
            if (d[axis] != 0) cuts.push_back((LD(k) / n - o[axis]) / d[axis]);
    if (!pyramids) return;
    for (int cz = 0; cz < n; ++cz)
        for (int cy = 0; cy < n; ++cy)
            for (int cx = 0; cx < n; ++cx) {
                const LD c[3] = {(cx + LD(0.5)) / n, (cy + LD(0.5)) / n,
                                 (cz + LD(0.5)) / n};
                for (int i = 0; i < 3; ++i)
                    for (int j = i + 1; j < 3; ++j)
                        for (int s : {-1, 1}) {
                            const LD den = d[i] - s * d[j];
                            if (den != 0)
                                cuts.push_back((c[i] - o[i] - s * (c[j] - o[j])) / den);
                        }
            }
}

// The trilinear interpolant, in the cube of the n^3 grid holding p, of g's values (in
// double, as the mesh holds them) at the cube's corners.
template <typename G>
LD TrilinearGridTruth(int n, const G& g, const std::array<LD, 3>& p) {
    int cube[3];
    LD w[3];
    for (int a = 0; a < 3; ++a) {
        const LD s = p[a] * n;
        cube[a] = std::clamp(int(std::floor(double(s))), 0, n - 1);
        w[a] = s - cube[a];
    }
    LD f = 0;
    for (int c = 0; c < 8; ++c) {
        const int i = c & 1, j = c >> 1 & 1, k = c >> 2 & 1;
        const LD corner =
            g(double(cube[0] + i) / n, double(cube[1] + j) / n, double(cube[2] + k) / n);
        f += corner * (i ? w[0] : 1 - w[0]) * (j ? w[1] : 1 - w[1]) *
             (k ? w[2] : 1 - w[2]);
    }
    return f;
}

}  // namespace

TEST(VolumePyramids, RationalFieldAgainstTheOdeReference) {
    const int n = 3;
    Mesh mesh = testing::GridMesh(
        n, 0.0, [](int, int, int) { return testing::CubeCut::Pyramids; });
    const auto g = [](LD x, LD y, LD z) {
        return std::sin(3 * x) * std::cos(2 * y) + z * z;
    };
    Field u{"u", Association::Point, 1, {}};
    for (std::int64_t i = 0; i < mesh.PointCount(); ++i)
        u.values.push_back(double(
            g(mesh.points[3 * i], mesh.points[3 * i + 1], mesh.points[3 * i + 2])));
    mesh.pointFields.push_back(std::move(u));
    const PyramidGridTruth truth{
        n, [&](LD x, LD y, LD z) {
            // The nodes' values as the mesh holds them (double).
            return LD(double(g(double(x), double(y), double(z))));
        }};
    RenderCounters counters;
    const OdeCheck check = CheckAgainstTheOdeReference(
        mesh, 60, counters,
        [](int trial, testing::Vec3& through) {
            // Every fifth ray passes through a cube centre (a pyramid apex), along which
            // the field is a polynomial; the others mostly pass apex planes at some
            // distance.
            if (trial % 5 == 0) through = {0.5, 0.5, 1.0 / 6};
        },
        [&](const std::array<LD, 3>& p) { return truth(p); },
        [&](const std::array<double, 3>& o, const std::array<double, 3>& d,
            std::vector<LD>& cuts) { GridCuts(n, true, o, d, cuts); });
    EXPECT_EQ(check.checked, 60);
    EXPECT_GT(check.worst, 0);
    EXPECT_EQ(counters.inversionFailures, 0);
    // The pyramids' closed form (BeginPyramidLine), which samples nothing, and where it
    // does not apply (the pole far off, or at the segment) their series (ProjectRational:
    // one sample per node of the degree it needs), instead of the general path's adaptive
    // projection and quadrature on the field, which take about 34 evaluations a segment
    // on these rays. The series alone took 7.8 a segment, the closed form and the series
    // 2.2.
    EXPECT_LT(counters.fieldEvaluations, 4 * counters.segments);
}

// SampleBatch on each segment of `ray` (1 to 11 points in turn, the first at the
// segment's entry, the others at random) against the field point by point from the same
// start (begun again: a curved cell's inversions are warm-started by the points before),
// bitwise; `visit(segment)` after each, `compared` counting them.
template <typename Visit>
void ExpectSampleBatchBitwise(FieldAlongRays& rig, const Mesh& mesh, const Ray& ray,
                              std::mt19937_64& rng, int& compared, Visit&& visit) {
    std::uniform_real_distribution<double> along(0, 1);
    rig.ForEachSegment(ray, 0, [&](const Segment& seg) {
        const int n = 1 + (compared % 11);
        std::vector<double> t(n), batch(n);
        for (double& x : t) x = seg.tEnter + along(rng) * (seg.tExit - seg.tEnter);
        t[0] = seg.tEnter;
        rig.sf.SampleBatch(t.data(), n, batch.data());
        rig.sf.Begin(mesh, rig.geometry, rig.sel, seg.cell, ray, InversionOptions{});
        for (int k = 0; k < n; ++k) {
            const double single = rig.sf(t[k]);
            ASSERT_EQ(std::memcmp(&batch[k], &single, sizeof single), 0)
                << batch[k] << " " << single << " at " << k << " of " << n;
        }
        visit(seg);
        ++compared;
    });
}

// SampleBatch of affine linear pyramids and wedges (pyramids four points at a time in
// vector lanes) gives bitwise the values of the field point by point, for every count
// (whole vectors and the rest).
TEST(VolumePyramids, SampleBatchIsTheFieldPointByPointBitwise) {
    for (const testing::CubeCut cut :
         {testing::CubeCut::Pyramids, testing::CubeCut::Wedges}) {
        Mesh mesh = testing::GridMesh(2, 0.0, [&](int, int, int) { return cut; });
        std::mt19937_64 rng(11);
        std::uniform_real_distribution<double> uni(0.02, 0.98);
        std::normal_distribution<double> gauss;
        AddUniformPointField(mesh, rng, 1);
        FieldAlongRays rig(mesh);
        int compared = 0;
        for (int trial = 0; trial < 40; ++trial) {
            const Ray ray = testing::MakeRayDir({uni(rng), uni(rng), uni(rng)},
                                                {gauss(rng), gauss(rng), gauss(rng)});
            ExpectSampleBatchBitwise(rig, mesh, ray, rng, compared,
                                     [](const Segment&) {});
        }
        EXPECT_GT(compared, 40);
    }
}

// Curved quadratic tetrahedra (ball-p2, its points bent further): SampleBatch inverts the
// points in order and takes their values together (four at a time in vector lanes) —
// bitwise the field point by point from the same start (the inversions' warm starts
// depend on the points before).
TEST(VolumeCurvedTets, SampleBatchIsTheFieldPointByPointBitwise) {
    Mesh mesh = MakeBuiltin("builtin:ball-p2?n=3");
    for (std::int64_t i = 0; i < mesh.PointCount(); ++i) {
        double* x = &mesh.points[3 * i];
        x[2] += 0.2 * (x[0] * x[0] - x[1] * x[1]);
    }
    mesh.pointFields.clear();
    std::mt19937_64 rng(19);
    std::uniform_real_distribution<double> uni(-0.5, 0.5);
    std::normal_distribution<double> gauss;
    AddUniformPointField(mesh, rng, 1);
    FieldAlongRays rig(mesh);
    int compared = 0, curved = 0;
    for (int trial = 0; trial < 60; ++trial) {
        const Ray ray = testing::MakeRayDir({uni(rng), uni(rng), uni(rng)},
                                            {gauss(rng), gauss(rng), gauss(rng)});
        ExpectSampleBatchBitwise(rig, mesh, ray, rng, compared, [&](const Segment& seg) {
            curved += !rig.geometry.Cell(seg.cell, rig.scratch).affine;
        });
    }
    EXPECT_GT(compared, 100);
    EXPECT_GT(curved, 50);
}

// The decomposition RationalPole gives: along a line through an affine linear pyramid the
// field minus residue / (x - pole) is linear in x, and a series of degree n misses it by
// no more than the Chebyshev tail of 1 / (x - pole) allows (the bound ProjectRational
// takes, without its factor of 2 for rounding).
TEST(VolumePyramids, RationalPoleAndTheInterpolationBound) {
    Mesh mesh = testing::GridMesh(
        1, 0.0, [](int, int, int) { return testing::CubeCut::Pyramids; });
    std::mt19937_64 rng(7);
    std::uniform_real_distribution<double> uni(0.02, 0.98);
    std::normal_distribution<double> gauss;
    AddUniformPointField(mesh, rng, 1);
    FieldAlongRays rig(mesh);
    SegmentField& sf = rig.sf;
    // visit(trial, segment) for the segments of `rays` random rays, sf begun on each.
    auto forEachSegment = [&](int rays, auto&& visit) {
        for (int trial = 0; trial < rays; ++trial) {
            const Ray ray = testing::MakeRayDir({uni(rng), uni(rng), uni(rng)},
                                                {gauss(rng), gauss(rng), gauss(rng)});
            rig.ForEachSegment(ray, 0, [&](const Segment& seg) { visit(trial, seg); });
        }
    };
    // The largest |p - f| at 201 points of the segment, p the interpolant of degree deg.
    auto interpolationMiss = [&](const Segment& seg, int deg) {
        const double mid = 0.5 * (seg.tEnter + seg.tExit),
                     half = 0.5 * (seg.tExit - seg.tEnter);
        const LglRule& rule = LglNodes(deg);
        std::vector<double> values(deg + 1);
        for (int i = 0; i <= deg; ++i) values[i] = sf(mid + half * rule.nodes[i]);
        LegendreSeries p;
        InterpolateLgl(values.data(), deg, seg.tEnter, seg.tExit, p);
        double miss = 0;
        for (int k = 0; k <= 200; ++k) {
            const double t = seg.tEnter + (seg.tExit - seg.tEnter) * k / 200;
            miss = std::max(miss, std::abs(p(t) - sf(t)));
        }
        return miss;
    };
    int poles = 0, tight = 0;
    forEachSegment(400, [&](int trial, const Segment& seg) {
        double pole, gap, residue;
        if (!sf.RationalPole(seg.tEnter, seg.tExit, pole, gap, residue)) return;
        ++poles;
        EXPECT_NEAR(std::abs(pole) - 1, gap, 1e-9 * std::abs(pole));
        ASSERT_GT(gap, 0);
        const double mid = 0.5 * (seg.tEnter + seg.tExit),
                     half = 0.5 * (seg.tExit - seg.tEnter);
        auto rest = [&](double x) { return sf(mid + half * x) - residue / (x - pole); };
        // Linear: second differences vanish to rounding (relative to the terms).
        const double scale = 1 + std::abs(residue) / gap;
        for (double x : {-0.9, -0.3, 0.2, 0.7})
            EXPECT_NEAR(rest(x - 0.1) - 2 * rest(x) + rest(x + 0.1), 0, 1e-11 * scale);
        // The interpolation miss against the bound, for a few degrees.
        const double root = std::sqrt(gap * (gap + 2)), rho = 1 + gap + root;
        const double K = 2 * std::abs(residue) / (root * (1 - 1 / rho));
        for (int deg : {2, 5, 9, 16}) {
            const double miss = interpolationMiss(seg, deg);
            const double bound = 4 * K * std::pow(rho, -(deg + 1));
            EXPECT_LE(miss, bound + 1e-13) << trial << " degree " << deg;
            if (miss > 1e-3 * bound && bound > 1e-12) ++tight;
        }
    });
    EXPECT_GT(poles, 300);
    EXPECT_GT(tight, 100);  // the bound is not vacuous: often within 1000x of the miss

    // A linear field (no twist: the pyramids are affine, the nodal values exact): no
    // rational part, the pole at infinity, and degree 2 reproduces the field.
    for (std::int64_t i = 0; i < mesh.PointCount(); ++i) {
        const double* x = &mesh.points[3 * i];
        mesh.pointFields[0].values[i] = x[0] + 2 * x[1] - 3 * x[2];
    }
    int linear = 0;
    forEachSegment(100, [&](int trial, const Segment& seg) {
        double pole, gap, residue;
        ASSERT_TRUE(sf.RationalPole(seg.tEnter, seg.tExit, pole, gap, residue)) << trial;
        EXPECT_EQ(residue, 0);
        EXPECT_TRUE(std::isinf(pole) && std::isinf(gap));
        EXPECT_LE(interpolationMiss(seg, 2), 1e-14) << trial;
        ++linear;
    });
    EXPECT_GT(linear, 100);
}

// A linear pyramid's field along a ray in closed form (PyramidLine, MakePyramidDepthLine,
// PyramidLineAt, PyramidLevelCrossings), on random rays and rays that pass the apices
// closely (poles next to the segments): the field against the basis point by point
// within fieldError; V's differences against the integral of the field less the mean
// (long-double Gauss-Legendre on pieces graded towards the pole) within twice
// depthError; the crossings of levels inside the segment's range against sign changes
// of the field sampled densely, each within rounding of one, and each a root.
TEST(VolumePyramids, ClosedFormAgainstTheBasisAndQuadrature) {
    Mesh mesh = testing::GridMesh(
        2, 0.0, [](int, int, int) { return testing::CubeCut::Pyramids; });
    std::mt19937_64 rng(5);
    std::uniform_real_distribution<double> uni(0.02, 0.98), unit(0, 1), tiny(-1e-3, 1e-3);
    std::normal_distribution<double> gauss;
    AddUniformPointField(mesh, rng, 1);
    FieldAlongRays rig(mesh);
    SegmentField& sf = rig.sf;
    const auto& [gl, gw] = testing::GaussRuleLD(20);
    int closed = 0, nearPole = 0, crossingsFound = 0, trials = 0;
    double worstField = 0, worstDepth = 0;
    for (int trial = 0; trial < 600; ++trial) {
        // Every third ray passes within 1e-3 of a cube centre (an apex of six pyramids).
        testing::Vec3 through = {uni(rng), uni(rng), uni(rng)};
        if (trial % 3 == 0)
            through = {0.25 + 0.5 * (trial % 2) + tiny(rng), 0.25 + tiny(rng),
                       0.75 + tiny(rng)};
        const Ray ray =
            testing::MakeRayDir(through, {gauss(rng), gauss(rng), gauss(rng)});
        rig.ForEachSegment(ray, 0, [&](const Segment& seg) {
            ++trials;
            PyramidLine p;
            if (!sf.PyramidLineOn(seg.tEnter, seg.tExit, p)) return;
            const double* v = sf.NodalValues();
            double sumV = 0, cellScale = 0;
            for (int i = 0; i < 5; ++i) {
                sumV += std::abs(v[i]);
                cellScale = std::max(cellScale, std::abs(v[i]));
            }
            PyramidDepthLine d;
            if (!MakePyramidDepthLine(p, cellScale, sumV, d)) return;
            ++closed;
            if (std::abs(d.rho) > 0.9) ++nearPole;
            // The field, at the ends and 61 points between.
            std::vector<double> t(63), f(63), depth(63);
            t[0] = seg.tEnter;
            t[62] = seg.tExit;
            for (int k = 1; k < 62; ++k)
                t[k] = seg.tEnter + (seg.tExit - seg.tEnter) * unit(rng);
            PyramidLineAt(p, d, t.data(), 63, f.data(), depth.data());
            for (int k = 0; k < 63; ++k) {
                const double miss = std::abs(f[k] - sf(t[k]));
                EXPECT_LE(miss, d.fieldError) << trial << " at " << t[k];
                worstField = std::max(worstField, miss / d.fieldError);
                // The scalar form and the vector lanes alike.
                EXPECT_EQ(f[k], p.At(t[k])) << trial;
            }
            // The field in long double from the same coefficients, and its integral less
            // the mean from t[0] to each t[k].
            const LD xp = -LD(p.u0) / LD(p.u1);
            auto fieldLd = [&](LD x) {
                const LD R = LD(p.r0) + LD(p.r1) * x, S = LD(p.s0) + LD(p.s1) * x,
                         U = LD(p.u0) + LD(p.u1) * x;
                return LD(p.l0) + LD(p.l1) * x + LD(p.k) * R * S / U;
            };
            auto integral = [&](LD a, LD b) {  // of field - mean over x in [a, b], in t
                LD sum = 0;
                while (a < b) {
                    // Pieces no wider than a quarter of their distance from the pole.
                    const LD gap = std::min(std::abs(a - xp), std::abs(b - xp));
                    LD end = std::min(b, a + std::max(LD(0.25) * gap, LD(1e-6)));
                    if (xp < a)
                        end = std::min(b, a + std::max(LD(0.25) * (a - xp), LD(1e-6)));
                    const LD m = (a + end) / 2, h = (end - a) / 2;
                    for (std::size_t i = 0; i < gl.size(); ++i)
                        sum += gw[i] * h * (fieldLd(m + h * gl[i]) - LD(d.mean));
                    a = end;
                }
                return sum * LD(p.half);
            };
            for (int k = 1; k < 63; k += 7) {
                const LD x0 = (LD(t[0]) - LD(p.mid)) / LD(p.half);
                const LD x1 = (LD(t[k]) - LD(p.mid)) / LD(p.half);
                const LD truth = x1 > x0 ? integral(x0, x1) : -integral(x1, x0);
                const double miss = double(std::abs(LD(depth[k]) - LD(depth[0]) - truth));
                EXPECT_LE(miss, 2 * d.depthError) << trial << " rho " << d.rho;
                worstDepth = std::max(worstDepth, miss / (2 * d.depthError));
            }
            // Crossings of levels inside the range the field spans on the segment.
            double lo = f[0], hi = f[0];
            for (double value : f) {
                lo = std::min(lo, value);
                hi = std::max(hi, value);
            }
            for (int level = 1; level <= 3; ++level) {
                const double c = lo + (hi - lo) * level / 4;
                std::vector<double> found;
                PyramidLevelCrossings(p, c, seg.tEnter, seg.tExit, found);
                // Sign changes of the field (long double) at 4001 points, bisected.
                const int samples = 4000;
                std::vector<LD> grid;
                for (int i = 0; i <= samples; ++i)
                    grid.push_back(-1 + LD(2) * i / samples);
                std::vector<LD> roots;
                testing::GridCrossings(fieldLd, c, grid, roots);
                for (LD& x : roots) x = LD(p.mid) + LD(p.half) * x;
                EXPECT_EQ(found.size(), roots.size()) << trial << " level " << c;
                const double tol = 1e-9 * (seg.tExit - seg.tEnter);
                for (LD r : roots) {
                    bool matched = false;
                    for (double tf : found)
                        matched = matched || std::abs(LD(tf) - r) <= tol;
                    EXPECT_TRUE(matched)
                        << trial << " level " << c << " root " << double(r);
                }
                for (double tf : found)
                    EXPECT_LE(std::abs(p.At(tf) - c), 1e-12 * (1 + sumV)) << trial;
                crossingsFound += int(found.size());
            }
        });
    }
    EXPECT_GT(closed, 500);
    EXPECT_GT(nearPole, 20);
    EXPECT_GT(crossingsFound, 1000);
    // The bounds hold with room, and are not vacuous.
    EXPECT_GT(worstField, 1e-3);
    EXPECT_GT(worstDepth, 1e-4);
    std::printf(
        "%d of %d segments in closed form (%d with the pole within 0.11 half-lengths); "
        "worst field miss %.3g, depth miss %.3g of the bounds\n",
        closed, trials, nearPole, worstField, worstDepth);
}

// ---------------------------------------------------------------------------------------
// Linear hexahedra and wedges: the field along a ray in closed form.

// SegmentField::LinearCellLine's polynomial against the field as the general evaluators
// give it (the hexahedron kernel, LinearWedgeValue) at points of each segment, on cells
// sheared by an affine map so that the reference directions mix; and no polynomial for
// the other cell types.
TEST(VolumeLinearCells, LinearCellLineIsTheFieldAlongTheRay) {
    using testing::CubeCut;
    for (CubeCut cut :
         {CubeCut::Hex, CubeCut::Wedges, CubeCut::Pyramids, CubeCut::Tets5}) {
        Mesh mesh = testing::GridMesh(2, 0.0, [&](int, int, int) { return cut; });
        for (std::int64_t i = 0; i < mesh.PointCount(); ++i) {
            double* x = &mesh.points[3 * i];
            const double p[3] = {x[0], x[1], x[2]};
            x[0] = 1.3 * p[0] + 0.4 * p[1] - 0.2 * p[2] + 0.1;
            x[1] = -0.3 * p[0] + 0.9 * p[1] + 0.5 * p[2];
            x[2] = 0.2 * p[0] - 0.6 * p[1] + 1.1 * p[2] - 0.3;
        }
        std::mt19937_64 rng(11);
        AddUniformPointField(mesh, rng, 3);
        FieldAlongRays rig(mesh);
        std::uniform_real_distribution<double> uni(0.05, 0.95);
        std::normal_distribution<double> gauss;
        int checked = 0, declined = 0;
        for (int trial = 0; trial < 200; ++trial) {
            // Rays through the sheared cube's interior (the image of [0.05, 0.95]^3).
            const double p[3] = {uni(rng), uni(rng), uni(rng)};
            const testing::Vec3 through = {1.3 * p[0] + 0.4 * p[1] - 0.2 * p[2] + 0.1,
                                           -0.3 * p[0] + 0.9 * p[1] + 0.5 * p[2],
                                           0.2 * p[0] - 0.6 * p[1] + 1.1 * p[2] - 0.3};
            const Ray ray =
                testing::MakeRayDir(through, {gauss(rng), gauss(rng), gauss(rng)});
            rig.ForEachSegment(ray, -1e30, [&](const Segment& seg) {
                double mono[4], magnitude = 0;
                int degree = -1;
                const bool has =
                    rig.sf.LinearCellLine(seg.tEnter, seg.tExit, mono, degree, magnitude);
                if (cut == CubeCut::Pyramids || cut == CubeCut::Tets5) {
                    EXPECT_FALSE(has) << int(cut);
                    ++declined;
                    return;
                }
                ASSERT_TRUE(has) << int(cut) << " " << trial;
                EXPECT_EQ(degree, cut == CubeCut::Hex ? 3 : 2);
                EXPECT_EQ(degree, rig.sf.LineDegree());
                EXPECT_GT(magnitude, 0);
                const double mid = 0.5 * (seg.tEnter + seg.tExit),
                             half = 0.5 * (seg.tExit - seg.tEnter);
                for (int k = 0; k <= 8; ++k) {
                    const double x = -1 + k / 4.0;
                    double v = mono[degree];
                    for (int q = degree - 1; q >= 0; --q) v = v * x + mono[q];
                    EXPECT_NEAR(v, rig.sf(mid + half * x), 1e-14 * magnitude)
                        << int(cut) << " " << trial << " x " << x;
                }
                ++checked;
            });
        }
        if (cut == CubeCut::Hex || cut == CubeCut::Wedges)
            EXPECT_GT(checked, 300) << int(cut);
        else
            EXPECT_GT(declined, 300) << int(cut);
    }
}

// PolyLine (an affine linear hexahedron's or wedge's polynomial along a segment, as the
// volume integrates it) on random cubics and quadratics over [-1, 1]: PolyLineAt's lanes
// are bitwise PolyLine::AtX for every count; its depth line's differences are the
// polynomial's integral less m0 (long double) within the series' bound of their rounding;
// PolyLevelCrossings finds every crossing of levels spread over the range and of levels
// within 1e-9 of a critical value (two crossings close together, or none), each within
// 1e-12 of a root bisected in long double (or what rounding of the values moves it by at
// the slope there), and no other.
TEST(VolumeLinearCells, PolyLineAgainstLongDoubleAndSampledCrossings) {
    std::mt19937_64 rng(17);
    std::uniform_real_distribution<double> coef(-2, 2), unit(0, 1);
    int crossings = 0, nearTangent = 0;
    double worstDepth = 0;
    for (int trial = 0; trial < 3000; ++trial) {
        PolyLine p;
        p.mid = coef(rng);
        p.half = 0.01 + unit(rng);
        p.inverseHalf = 1 / p.half;
        const int degree = trial % 2 ? 3 : 2;
        for (int k = 0; k <= degree; ++k) p.m[k] = coef(rng);
        double sum = 0;
        for (double c : p.m) sum += std::abs(c);
        auto fieldLd = [&](LD x) {
            return ((LD(p.m[3]) * x + p.m[2]) * x + p.m[1]) * x + p.m[0];
        };
        // Field and depth line at 1 to 9 points.
        const int n = 1 + trial % 9;
        std::vector<double> t(n), f(n), v(n);
        for (double& ti : t) ti = p.mid + p.half * (2 * unit(rng) - 1);
        t[0] = p.mid - p.half;
        PolyLineAt(p, t.data(), n, f.data(), v.data());
        const double bound =
            2 * 8 * std::numeric_limits<double>::epsilon() * p.half *
            (0.5 * std::abs(p.m[1]) + std::abs(p.m[2]) / 3 + 0.25 * std::abs(p.m[3]));
        for (int i = 0; i < n; ++i) {
            EXPECT_EQ(f[i], p.At(t[i])) << trial;
            const LD x0 = (LD(t[0]) - p.mid) / p.half, x1 = (LD(t[i]) - p.mid) / p.half;
            LD integral = 0;
            for (int k = 1; k <= 3; ++k)
                integral +=
                    LD(p.m[k]) * (std::pow(x1, k + 1) - std::pow(x0, k + 1)) / (k + 1);
            integral *= p.half;
            const double miss = double(std::abs(LD(v[i]) - LD(v[0]) - integral));
            EXPECT_LE(miss,
                      bound + 4 * std::numeric_limits<double>::epsilon() * p.half * sum)
                << trial;
            worstDepth = std::max(worstDepth, miss / bound);
        }
        // Levels: three across the range on [-1, 1], and the values at the critical
        // points shifted by +-1e-9.
        std::vector<double> levels;
        double lo = 1e300, hi = -1e300;
        for (int k = 0; k <= 200; ++k) {
            const double value = p.AtX(-1 + k / 100.0);
            lo = std::min(lo, value);
            hi = std::max(hi, value);
        }
        for (int k = 1; k <= 3; ++k) levels.push_back(lo + (hi - lo) * k / 4);
        {
            const LD a = 3 * LD(p.m[3]), b = 2 * LD(p.m[2]), c = p.m[1];
            const LD disc = b * b - 4 * a * c;
            if (a != 0 && disc > 0)
                for (int s : {-1, 1}) {
                    const LD xc = (-b + s * std::sqrt(disc)) / (2 * a);
                    if (std::abs(xc) < 0.9) {
                        levels.push_back(double(fieldLd(xc)) + 1e-9);
                        levels.push_back(double(fieldLd(xc)) - 1e-9);
                        nearTangent += 2;
                    }
                }
        }
        for (double level : levels) {
            std::vector<double> found;
            PolyLevelCrossings(p, level, p.mid - p.half, p.mid + p.half, found);
            // Sign changes on a grid of 20000 steps that holds the critical points (in
            // long double), bisected.
            std::vector<LD> grid;
            for (int i = 0; i <= 4000; ++i) grid.push_back(-1 + LD(2) * i / 4000);
            {
                const LD a = 3 * LD(p.m[3]), b = 2 * LD(p.m[2]), c = p.m[1];
                const LD disc = b * b - 4 * a * c;
                LD crit[2];
                int nc = 0;
                if (a != 0 && disc > 0)
                    for (int s : {-1, 1})
                        crit[nc++] = (-b + s * std::sqrt(disc)) / (2 * a);
                if (a == 0 && b != 0) crit[nc++] = -c / b;
                for (int k = 0; k < nc; ++k)
                    if (crit[k] > -1 && crit[k] < 1) grid.push_back(crit[k]);
            }
            std::sort(grid.begin(), grid.end());
            std::vector<LD> roots;
            testing::GridCrossings(fieldLd, level, grid, roots);
            for (LD& x : roots) x = LD(p.mid) + LD(p.half) * x;
            EXPECT_EQ(found.size(), roots.size()) << trial << " level " << level;
            for (LD r : roots) {
                // Within 1e-12, or what the rounding of the values (8 eps of the sum of
                // the coefficients) moves a root at the slope there (near a critical
                // value, two close roots are ill-conditioned).
                const LD x = (r - p.mid) / p.half;
                const LD slope =
                    std::abs((3 * LD(p.m[3]) * x + 2 * LD(p.m[2])) * x + p.m[1]) / p.half;
                const LD tol =
                    1e-12L + 8 * std::numeric_limits<double>::epsilon() * sum / slope;
                bool matched = false;
                for (double tf : found) matched = matched || std::abs(LD(tf) - r) <= tol;
                EXPECT_TRUE(matched)
                    << trial << " level " << level << " root " << double(r);
            }
            crossings += int(found.size());
        }
    }
    EXPECT_GT(crossings, 5000);
    EXPECT_GT(nearTangent, 500);
    EXPECT_GT(worstDepth, 1e-3);  // the bound is not vacuous
    EXPECT_LE(worstDepth, 1.0);
}

// Isosurfaces on affine linear hexahedra, wedges and pyramids take their roots in closed
// form (PolyRoots and PyramidRoots, src/render/brick_renderer.cpp): every pixel's hit
// against the first sign change of the field (the cells' own basis, SegmentField) along
// the camera ray, scanned at 400 points per segment and bisected: the same pixels hit,
// each within 1e-9 of the scanned root, its residual below 1e-13 of the range. Rays that
// come within 1e-7 of the isovalue before their first crossing (where the scan may miss
// two close roots) are left out: fewer than 2% of them. Almost no segment falls back to
// the projection (rounding-close decisions only).
TEST(VolumeLinearCells, IsosurfaceRootsInClosedFormAgainstADenseScan) {
    using testing::CubeCut;
    for (CubeCut cut : {CubeCut::Hex, CubeCut::Wedges, CubeCut::Pyramids}) {
        Mesh mesh = testing::GridMesh(3, 0.0, [&](int, int, int) { return cut; });
        Field u{"u", Association::Point, 1, {}};
        for (std::int64_t i = 0; i < mesh.PointCount(); ++i) {
            const double* x = &mesh.points[3 * i];
            u.values.push_back(std::sin(3 * x[0]) * std::cos(2 * x[1]) + x[2] * x[2]);
        }
        mesh.pointFields.push_back(std::move(u));
        const double C = 0.45;
        const Scene scene = MakeScene(R"(
data: {mesh: "builtin:cube-tets-4"}
camera: {position: [2.3, 1.7, 2.9], look_at: [0.5, 0.45, 0.5], up: [0, 1, 0], fov_y: 32,
         width: 40, height: 36}
isosurfaces:
  - {field: u, value: 0.45, color: [0.9, 0.5, 0.2], opacity: 1.0}
)");
        RenderStats stats;
        const Image image = RenderMeshJob(mesh, scene, stats);
        FieldAlongRays rig(mesh);
        const Camera camera(scene.camera);
        int hits = 0, compared = 0, ambiguous = 0;
        for (int j = 0; j < scene.camera.height; ++j)
            for (int i = 0; i < scene.camera.width; ++i) {
                const Ray ray = PixelRay(camera, i, j);
                double root = std::numeric_limits<double>::infinity(), nearest = 1e300;
                rig.ForEachSegment(ray, 0, [&](const Segment& seg) {
                    if (std::isfinite(root)) return;
                    const int n = 400;
                    double ta = seg.tEnter, fa = rig.sf(ta) - C;
                    nearest = std::min(nearest, std::abs(fa));
                    for (int k = 1; k <= n && !std::isfinite(root); ++k) {
                        const double tb = seg.tEnter + (seg.tExit - seg.tEnter) * k / n;
                        const double fb = rig.sf(tb) - C;
                        if ((fa < 0) != (fb < 0)) {
                            double lo = ta, hi = tb, flo = fa;
                            for (int it = 0; it < 80; ++it) {
                                const double mid = 0.5 * (lo + hi), fm = rig.sf(mid) - C;
                                if ((fm < 0) == (flo < 0)) {
                                    lo = mid;
                                    flo = fm;
                                } else {
                                    hi = mid;
                                }
                            }
                            root = 0.5 * (lo + hi);
                        } else {
                            nearest = std::min(nearest, std::abs(fb));
                        }
                        ta = tb;
                        fa = fb;
                    }
                });
                if (nearest < 1e-7) {
                    ++ambiguous;
                    continue;
                }
                const std::size_t p = std::size_t(j) * scene.camera.width + i;
                ++compared;
                EXPECT_EQ(std::isfinite(image.z[p]), std::isfinite(root))
                    << int(cut) << " pixel " << i << "," << j;
                if (!std::isfinite(root) || !std::isfinite(image.z[p])) continue;
                ++hits;
                EXPECT_NEAR(image.z[p], root, 1e-9)
                    << int(cut) << " pixel " << i << "," << j;
                EXPECT_LE(image.isoResidual[p], 1e-13 * 2.5) << int(cut);
            }
        EXPECT_GT(hits, 150) << int(cut);
        EXPECT_LT(ambiguous, 0.02 * compared) << int(cut);
        std::printf(
            "cut %d: %d hits of %d pixels (%d left out), %.0f projections, %.0f "
            "segments\n",
            int(cut), hits, compared, ambiguous, stats.counters.projections,
            stats.counters.segments);
        EXPECT_LT(stats.counters.projections, 0.002 * stats.counters.segments)
            << int(cut);
    }
}

// The volume over linear hexahedra, whose field (the closed form along each ray) is the
// trilinear interpolant of the grid values in each cube, written here independently,
// against the ODE reference: the error bar holds and the tolerance is met.
// Linear hexahedra, wedges and pyramids (the exact and rational series): their
// breakpoint crossings, found among the breakpoints counted in the short list, are those
// of the general scan of the whole list (the short list marked invalid): bitwise the same
// pixels, errors and counters.
TEST(VolumeLinearCells, ShortBreakpointListGivesTheGeneralScansCrossings) {
    using testing::CubeCut;
    for (const CubeCut cut : {CubeCut::Hex, CubeCut::Wedges, CubeCut::Pyramids}) {
        Mesh mesh = testing::GridMesh(4, 0.0, [cut](int, int, int) { return cut; });
        Field u{"u", Association::Point, 1, {}};
        for (std::int64_t i = 0; i < mesh.PointCount(); ++i) {
            const double* x = &mesh.points[3 * i];
            u.values.push_back(x[0] + 2 * x[1] + 3 * x[2] +
                               0.6 * std::sin(7 * x[0] * x[1]));
        }
        mesh.pointFields.push_back(std::move(u));
        const MeshGeometry geometry = MeshGeometry::Build(mesh);
        const BrickTraverser traverser(Brick::WholeMesh(mesh));
        Scene scene = MakeScene(kLinearScene);
        scene.volume->extinctionField = "u";
        // Seven breakpoints in all (a short list), most inside the field's range.
        scene.volume->extinctionTf = {{0.0, 0.3}, {2.2, 6.0}, {4.0, 2.0}};
        const BrickSetup setup = MakeBrickSetup(mesh, geometry, traverser, scene);
        ASSERT_TRUE(setup.volume.has_value());
        ASSERT_TRUE(setup.volume->sameField);
        ASSERT_TRUE(setup.volume->shortBreakpoints.valid);
        VolumeSetup scan = *setup.volume;
        scan.shortBreakpoints.valid = false;
        const Camera camera(scene.camera);
        VolumeRayMarcher counted, scanned;
        RenderCounters countersA, countersB;
        std::vector<Segment> segments;
        int rays = 0;
        for (int j = 0; j < 24; ++j)
            for (int i = 0; i < 28; ++i) {
                const Ray ray = PixelRay(camera, i, j);
                traverser.Trace(ray, 0, 1e30, segments);
                if (segments.empty()) continue;
                ++rays;
                double rgbaA[4] = {0, 0, 0, 0}, rgbaB[4] = {0, 0, 0, 0};
                RayComposite a, b;
                a.rgba = rgbaA;
                b.rgba = rgbaB;
                const double t0 = segments.front().tEnter, t1 = segments.back().tExit;
                counted.BeginRay(*setup.volume, ray, t0, t1);
                scanned.BeginRay(scan, ray, t0, t1);
                bool stopA = false, stopB = false;
                for (const Segment& seg : segments) {
                    if (!stopA && counted.BeginSegment(mesh, geometry, seg, countersA))
                        stopA = counted.Integrate(seg.tEnter, seg.tExit, a, countersA);
                    if (!stopB && scanned.BeginSegment(mesh, geometry, seg, countersB))
                        stopB = scanned.Integrate(seg.tEnter, seg.tExit, b, countersB);
                }
                EXPECT_EQ(stopA, stopB);
                counted.FinishRay(a);
                scanned.FinishRay(b);
                for (int c = 0; c < 4; ++c) EXPECT_EQ(rgbaA[c], rgbaB[c]);
                for (int c = 0; c < 3; ++c) EXPECT_EQ(a.error[c], b.error[c]);
            }
        EXPECT_GT(rays, 250);
        EXPECT_EQ(countersA.fieldEvaluations, countersB.fieldEvaluations);
        EXPECT_EQ(countersA.volumeNodes, countersB.volumeNodes);
    }
}

TEST(VolumeLinearCells, TrilinearFieldAgainstTheOdeReference) {
    const int n = 3;
    Mesh mesh =
        testing::GridMesh(n, 0.0, [](int, int, int) { return testing::CubeCut::Hex; });
    const auto g = [](double x, double y, double z) {
        return std::sin(3 * x) * std::cos(2 * y) + z * z;
    };
    Field u{"u", Association::Point, 1, {}};
    for (std::int64_t i = 0; i < mesh.PointCount(); ++i)
        u.values.push_back(
            g(mesh.points[3 * i], mesh.points[3 * i + 1], mesh.points[3 * i + 2]));
    mesh.pointFields.push_back(std::move(u));
    // The trilinear interpolant of g's (double) values at the corners of the cube
    // holding p.
    auto truth = [&](const std::array<LD, 3>& p) { return TrilinearGridTruth(n, g, p); };
    RenderCounters counters;
    const OdeCheck check = CheckAgainstTheOdeReference(
        mesh, 60, counters, [](int, testing::Vec3&) {}, truth,
        [&](const std::array<double, 3>& o, const std::array<double, 3>& d,
            std::vector<LD>& cuts) {
            for (int axis = 0; axis < 3; ++axis)  // the cube faces
                for (int k = 0; k <= n; ++k)
                    if (d[axis] != 0) cuts.push_back((LD(k) / n - o[axis]) / d[axis]);
        });
    EXPECT_EQ(check.checked, 60);
    EXPECT_GT(check.worst, 0);
    // The closed form evaluates no field sample: only the general path's would count.
    EXPECT_EQ(counters.fieldEvaluations, 0);
    EXPECT_GT(counters.segments, 60);
}

// Colour and extinction from two fields, each a polynomial (hexahedra) or rational
// (pyramids) along the rays, in closed form side by side (SeriesPieceOf with two
// PolyLines or PyramidLines): against the ODE reference of the two interpolants, written
// here independently; the error bar holds and the tolerance is met.
TEST(VolumeLinearCells, TwoFieldsInClosedFormAgainstTheOdeReference) {
    const char* scene = R"(
data: {mesh: "builtin:cube-tets-1"}
volume:
  color_field: u
  extinction_field: v
  color_tf: [[-0.5, 0.1, 0.2, 0.9], [0.2, 1.0, 0.6, 0.2], [1.0, 0.3, 1.0, 0.4]]
  extinction_tf: [[-0.2, 0.2], [0.4, 3.0], [0.9, 0.5], [1.6, 2.0]]
accuracy: {volume_tolerance: 1e-10}
)";
    const int n = 3;
    const auto gu = [](double x, double y, double z) {
        return std::sin(3 * x) * std::cos(2 * y) + z * z;
    };
    const auto gv = [](double x, double y, double z) {
        return std::cos(2 * x + y) + 0.8 * y * z;
    };
    for (const testing::CubeCut cut :
         {testing::CubeCut::Hex, testing::CubeCut::Pyramids}) {
        Mesh mesh = testing::GridMesh(n, 0.0, [&](int, int, int) { return cut; });
        Field u{"u", Association::Point, 1, {}}, v{"v", Association::Point, 1, {}};
        for (std::int64_t i = 0; i < mesh.PointCount(); ++i) {
            const double* x = &mesh.points[3 * i];
            u.values.push_back(gu(x[0], x[1], x[2]));
            v.values.push_back(gv(x[0], x[1], x[2]));
        }
        mesh.pointFields.push_back(std::move(u));
        mesh.pointFields.push_back(std::move(v));
        // The cells' interpolants of g's (double) values: trilinear in each cube, or the
        // pyramids' (PyramidGridTruth).
        auto interpolant = [&](auto g) {
            return [g, cut, n](const std::array<LD, 3>& p) -> LD {
                if (cut == testing::CubeCut::Pyramids)
                    return PyramidGridTruth{
                        n, [&](LD x, LD y, LD z) {
                            return LD(g(double(x), double(y), double(z)));
                        }}(p);
                return TrilinearGridTruth(n, g, p);
            };
        };
        RenderCounters counters;
        const OdeCheck check = CheckTwoFieldsAgainstTheOdeReference(
            mesh, scene, 40, counters, [](int, testing::Vec3&) {}, interpolant(gu),
            interpolant(gv),
            [&](const std::array<double, 3>& o, const std::array<double, 3>& d,
                std::vector<LD>& cuts) {
                GridCuts(n, cut == testing::CubeCut::Pyramids, o, d, cuts);
            });
        EXPECT_EQ(check.checked, 40) << int(cut);
        EXPECT_GT(check.worst, 0) << int(cut);
        // Closed forms sample nothing (nor do the hexahedra's series: only the pyramids
        // tell the paths apart); where either pyramid field needs its series, both take
        // one (5.2 samples a segment here, 17.6 with series only).
        if (cut == testing::CubeCut::Hex) {
            EXPECT_EQ(counters.fieldEvaluations, 0);
        } else {
            EXPECT_LT(counters.fieldEvaluations, 8 * counters.segments);
        }
    }
}

// ---------------------------------------------------------------------------------------
// Slices.

TEST(VolumeSlices, ColourIsTheTransferFunctionOfTheFieldOnThePlane) {
    const Mesh mesh = MakeBuiltin("builtin:cube-tets-4");
    const Scene scene = MakeScene(R"(
data: {mesh: "builtin:cube-tets-4"}
camera: {position: [2.3, 1.7, 2.9], look_at: [0.5, 0.45, 0.5], up: [0, 1, 0], fov_y: 32,
         width: 32, height: 32}
slices:
  - {point: [0.5, 0.4, 0.55], normal: [0.3, -0.5, 1.0], field: u,
     color_tf: [[0.5, 0.1, 0.2, 0.9], [2.0, 0.2, 0.9, 0.3], [4.5, 1.0, 0.9, 0.1]]}
)");
    RenderStats stats;
    const Image image = RenderMeshJob(mesh, scene, stats);
    const Camera camera(scene.camera);
    const RefTf tf = RefTf::Color(scene.slices[0].colorTf);
    const LD n[3] = {0.3L, -0.5L, 1.0L}, p[3] = {0.5L, 0.4L, 0.55L};
    int hits = 0;
    for (int j = 0; j < 32; ++j)
        for (int i = 0; i < 32; ++i) {
            const CameraRay r = camera.PixelRay(i, j);
            LD nd = 0, off = 0;
            for (int a = 0; a < 3; ++a) {
                nd += n[a] * LD(r.direction[a]);
                off += n[a] * (p[a] - LD(r.origin[a]));
            }
            const LD t = off / nd;
            LD x[3];
            for (int a = 0; a < 3; ++a) x[a] = LD(r.origin[a]) + t * LD(r.direction[a]);
            const LD inside = std::min({x[0], x[1], x[2], 1 - x[0], 1 - x[1], 1 - x[2]});
            const std::size_t q = std::size_t(j) * 32 + i;
            if (std::abs(inside) < 1e-9) continue;
            if (inside < 0) {
                EXPECT_EQ(image.a[q], 0.0) << i << "," << j;
                continue;
            }
            ++hits;
            const auto want = tf(x[0] + 2 * x[1] + 3 * x[2]);
            EXPECT_EQ(image.a[q], 1.0);
            EXPECT_NEAR(image.r[q], double(want[0]), 1e-13) << i << "," << j;
            EXPECT_NEAR(image.g[q], double(want[1]), 1e-13) << i << "," << j;
            EXPECT_NEAR(image.b[q], double(want[2]), 1e-13) << i << "," << j;
            EXPECT_EQ(image.isoId[q], -1);  // a slice is not an isosurface
        }
    EXPECT_GT(hits, 150);
}

// cube-tets-N (N even) without the corner octant [0, 1/2]^3: the plane z = 1/2 holds
// the notch's top boundary faces (x, y < 1/2) and interior faces elsewhere.
Mesh CubeTetsWithoutCorner(int n) {
    const Mesh cube = MakeBuiltin("builtin:cube-tets-" + std::to_string(n));
    Mesh mesh;
    mesh.points = cube.points;
    mesh.pointFields = cube.pointFields;
    for (std::int64_t c = 0; c < cube.CellCount(); ++c) {
        const std::int64_t* nodes = cube.CellNodes(c);
        const int count = cube.CellNodeCount(c);
        bool inCorner = true;
        for (int d = 0; d < 3; ++d) {
            double centre = 0;
            for (int k = 0; k < count; ++k) centre += cube.points[3 * nodes[k] + d];
            inCorner &= centre / count < 0.5;
        }
        if (!inCorner)
            mesh.AddCell(cube.cellShape[c], cube.cellOrder[c], cube.cellFamily[c], nodes,
                         count);
    }
    mesh.Validate("cube without a corner");
    return mesh;
}

// A slice in a plane that holds boundary faces (the notch's top, z = 1/2) is drawn
// exactly once on every ray that meets the plane in the closed domain: seen from above
// (the ray leaves the mesh there) and from below (it enters there), like the plane's
// interior faces (shared by two segments). Half opacity shows a hole (alpha 0) and a
// double draw (alpha 3/4) alike.
TEST(VolumeSlices, PlaneThroughBoundaryFacesIsDrawnOnceOnEveryRay) {
    const Mesh mesh = CubeTetsWithoutCorner(4);
    for (const char* position : {"[2.3, 1.7, 2.9]", "[-1.3, -0.8, -1.9]"}) {
        const Scene scene = MakeScene(std::string(R"(
data: {mesh: "builtin:cube-tets-4"}
camera: {position: )") + position + R"(, look_at: [0.5, 0.5, 0.5], up: [0, 1, 0],
         fov_y: 40, width: 96, height: 96}
slices:
  - {point: [0.5, 0.5, 0.5], normal: [0, 0, 1], field: u, opacity: 0.5,
     color_tf: [[0.0, 0.1, 0.2, 0.9], [6.0, 1.0, 0.9, 0.1]]}
)");
        RenderStats stats;
        const Image image = RenderMeshJob(mesh, scene, stats);
        const Camera camera(scene.camera);
        const RefTf tf = RefTf::Color(scene.slices[0].colorTf);
        int onPlane = 0, onBoundaryFaces = 0, bad = 0;
        for (int j = 0; j < image.height; ++j)
            for (int i = 0; i < image.width; ++i) {
                const CameraRay r = camera.PixelRay(i, j);
                const LD t = (0.5L - LD(r.origin[2])) / LD(r.direction[2]);
                const LD x = LD(r.origin[0]) + t * LD(r.direction[0]);
                const LD y = LD(r.origin[1]) + t * LD(r.direction[1]);
                const LD inside = std::min({x, y, 1 - x, 1 - y});
                if (std::abs(inside) < 1e-9) continue;  // grazes the outer edge
                const std::size_t q = std::size_t(j) * image.width + i;
                if (inside < 0) {
                    EXPECT_EQ(image.a[q], 0.0) << position << " " << i << "," << j;
                    continue;
                }
                ++onPlane;
                onBoundaryFaces += x < 0.5L && y < 0.5L;
                const auto want = tf(x + 2 * y + 1.5L);
                const bool ok = image.a[q] == 0.5 &&
                                std::abs(image.r[q] - 0.5 * double(want[0])) < 1e-12 &&
                                std::abs(image.b[q] - 0.5 * double(want[2])) < 1e-12;
                bad += !ok;
                if (!ok && bad <= 5)
                    ADD_FAILURE() << position << " " << i << "," << j << ": alpha "
                                  << image.a[q]
                                  << (x < 0.5L && y < 0.5L ? " (notch)" : "");
            }
        EXPECT_EQ(bad, 0) << position << ": pixels of " << onPlane;
        EXPECT_GT(onPlane, 1000) << position;
        EXPECT_GT(onBoundaryFaces, 200) << position;
    }
}

// A semi-transparent slice inside a volume is composited at its depth.
TEST(VolumeSlices, SemiTransparentSliceInsideTheVolumeAtItsDepth) {
    const Mesh mesh = CubeTetsTwoFields(4);
    Scene scene = MakeScene(kLinearScene);
    SceneSlice slice;
    slice.point = {0.5, 0.5, 0.5};
    slice.normal = {0.0, 0.0, 1.0};
    slice.field = "u";
    slice.colorTf = {{0.0, {1.0, 0.0, 0.0}}, {6.0, {0.0, 0.0, 1.0}}};
    slice.opacity = 0.4;
    scene.slices.push_back(slice);
    RenderStats stats;
    const Image image = RenderMeshJob(mesh, scene, stats);
    const Camera camera(scene.camera);
    const RefTf ctf = RefTf::Color(scene.volume->colorTf);
    const RefTf etf = RefTf::Extinction(scene.volume->extinctionTf);
    const RefTf stf = RefTf::Color(slice.colorTf);
    int checked = 0;
    for (int j = 0; j < image.height; ++j)
        for (int i = 0; i < image.width; ++i) {
            const CameraRay cr = camera.PixelRay(i, j);
            const LinearFieldRay ray{cr.origin, cr.direction};
            LD t0, t1;
            if (!testing::RefBoxChord(cr.origin, cr.direction, {0, 0, 0}, {1, 1, 1}, t0,
                                      t1) ||
                t1 - t0 < 1e-5)
                continue;
            const LD ts = (0.5L - cr.origin[2]) / LD(cr.direction[2]);
            std::vector<RefSurface> surfaces;
            if (ts > t0 + 1e-9 && ts < t1 - 1e-9) {
                const auto c = stf(ray.At(kU, ts));
                surfaces.push_back({ts, c, 0.4L});
            } else if (ts > t0 - 1e-9 && ts < t1 + 1e-9) {
                continue;  // the plane grazes the chord's end
            }
            std::vector<LD> kinks;
            ray.Crossings(kU, ctf.scalars, kinks);
            ray.Crossings(kV, etf.scalars, kinks);
            const RefPixel ref = testing::ReferenceRay(
                t0, t1, [&](LD t) { return ray.At(kU, t); },
                [&](LD t) { return ray.At(kV, t); }, ctf, etf, true, kinks, surfaces);
            const std::size_t p = std::size_t(j) * image.width + i;
            const double got[4] = {image.r[p], image.g[p], image.b[p], image.a[p]};
            const LD want[4] = {ref.rgb[0], ref.rgb[1], ref.rgb[2], ref.alpha};
            for (int c = 0; c < 4; ++c) {
                EXPECT_LE(std::abs(got[c] - want[c]), 1e-10 * want[c] + 1e-15)
                    << i << "," << j << " " << c;
            }
            checked += !surfaces.empty();
        }
    EXPECT_GT(checked, 100);
}

// ---------------------------------------------------------------------------------------
// Threads and errors.

bool SameBits(const std::vector<double>& a, const std::vector<double>& b) {
    return a.size() == b.size() &&
           std::memcmp(a.data(), b.data(), a.size() * sizeof(double)) == 0;
}

TEST(VolumeRender, OneAndTwoThreadsGiveBitIdenticalImages) {
    const Mesh mesh = MakeBuiltin("builtin:nk-sinc?order=4");
    Scene scene = MakeScene(R"(
data: {mesh: "builtin:nk-sinc"}
camera: {position: [2.2, 1.6, 2.6], look_at: [0.5, 0.5, 0.5], up: [0, 1, 0], fov_y: 30,
         width: 40, height: 32}
isosurfaces:
  - {field: u, value: 0.3, opacity: 0.6}
slices:
  - {point: [0.5, 0.5, 0.5], normal: [1, 0, 0], field: u,
     color_tf: [[-1, 0, 0, 1], [1, 1, 0, 0]], opacity: 0.3}
volume:
  color_field: u
  color_tf: [[-1.0, 0.1, 0.2, 0.9], [0.0, 0.9, 0.9, 0.9], [1.0, 1.0, 0.2, 0.1]]
  extinction_tf: [[-0.5, 0.0], [0.0, 4.0], [0.5, 0.5]]
accuracy: {volume_tolerance: 1e-8}
)");
    RenderStats s1, s2;
    scene.threads = 1;
    const Image one = RenderMeshJob(mesh, scene, s1);
    scene.threads = 2;
    const Image two = RenderMeshJob(mesh, scene, s2);
    const auto a = one.Channels();
    const auto b = two.Channels();
    for (std::size_t c = 0; c < a.size(); ++c)
        EXPECT_TRUE(SameBits(*a[c].second, *b[c].second)) << a[c].first;
    EXPECT_GT(s1.counters.volumePixels, 500);
    // Counters are summed per thread, so only up to the order of the sum.
    EXPECT_NEAR(s1.counters.volumeErrorSqSum, s2.counters.volumeErrorSqSum,
                1e-12 * s1.counters.volumeErrorSqSum);
    EXPECT_EQ(s1.counters.volumeErrorMax, s2.counters.volumeErrorMax);
}

TEST(VolumeRender, MissingVolumeOrSliceFieldIsAnInputError) {
    const Mesh mesh = MakeBuiltin("builtin:cube-tets-1");
    Scene scene = MakeScene(kLinearScene);
    scene.volume->extinctionField = "nope";
    try {
        RenderStats stats;
        RenderMeshJob(mesh, scene, stats);
        FAIL() << "expected InputError";
    } catch (const InputError& e) {
        EXPECT_EQ(e.where(), "volume.extinction_field");
    }
    scene = MakeScene(kLinearScene);
    scene.volume.reset();
    SceneSlice slice;
    slice.field = "w";
    slice.colorTf = {{0.0, {1, 1, 1}}};
    scene.slices.push_back(slice);
    try {
        RenderStats stats;
        RenderMeshJob(mesh, scene, stats);
        FAIL() << "expected InputError";
    } catch (const InputError& e) {
        EXPECT_EQ(e.where(), "slices.0.field");
    }
}

namespace {
// Legendre polynomial P_k(y) in long double by its recurrence.
long double LegendreP(int k, long double y) {
    long double prev = 1, cur = y;
    if (k == 0) return 1;
    for (int j = 2; j <= k; ++j) {
        const long double next = ((2 * j - 1) * y * cur - (j - 1) * prev) / j;
        prev = cur;
        cur = next;
    }
    return cur;
}

// Degree-p equispaced Lagrange interpolation on [0, 1] in long double: the hexahedron's
// field at reference point r from its nodal values (i fastest).
long double HexValue(int p, const double* u, const long double r[3]) {
    long double l[3][11];
    for (int d = 0; d < 3; ++d)
        for (int i = 0; i <= p; ++i) {
            long double w = 1;
            for (int m = 0; m <= p; ++m)
                if (m != i) w *= (r[d] - (long double)m / p) / ((long double)(i - m) / p);
            l[d][i] = w;
        }
    long double sum = 0;
    const int n = p + 1;
    for (int k = 0; k < n; ++k)
        for (int j = 0; j < n; ++j)
            for (int i = 0; i < n; ++i)
                sum += l[0][i] * l[1][j] * l[2][k] * u[i + n * (j + n * k)];
    return sum;
}

}  // namespace

TEST(VolumeDegreeTail, ProductsOfLegendrePolynomialsGiveTheirCoefficientsBack) {
    // u = 0.7 P2(y1) P1(y2) P3(y3) - 0.3 P4(y1) P4(y2) P4(y3) + 0.05 P0, y = 2 ref - 1:
    // total degrees 6 and 12, so tail[m] = 1.0 below 6, 0.3 from 6 to 11, 0 from 12.
    const int p = 4, n = p + 1;
    std::vector<double> u(n * n * n);
    for (int k = 0; k < n; ++k)
        for (int j = 0; j < n; ++j)
            for (int i = 0; i < n; ++i) {
                const long double y[3] = {2.0L * i / p - 1, 2.0L * j / p - 1,
                                          2.0L * k / p - 1};
                u[i + n * (j + n * k)] = double(
                    0.7L * LegendreP(2, y[0]) * LegendreP(1, y[1]) * LegendreP(3, y[2]) -
                    0.3L * LegendreP(4, y[0]) * LegendreP(4, y[1]) * LegendreP(4, y[2]) +
                    0.05L);
            }
    double tail[3 * p + 1];
    LagrangeHexDegreeTail(p, u.data(), tail);
    for (int m = 0; m <= 3 * p; ++m) {
        const double want = m < 6 ? 1.0 : m < 12 ? 0.3 : 0.0;
        EXPECT_NEAR(tail[m], want, 1e-14) << "m = " << m;
        // Every |coefficient| is rounded up (the node values carry rounding of 1e-16).
        if (m < 3 * p) {
            EXPECT_GE(tail[m], want - 1e-15) << "m = " << m;
        }
    }
    EXPECT_EQ(tail[3 * p], 0.0);
}

TEST(VolumeDegreeTail, BoundsTheInterpolationErrorAlongLinesOfNkSincCells) {
    // The volume samples an affine hexahedron's field along a segment at the
    // Legendre-Gauss-Lobatto nodes of a degree m below its exact 3p and counts
    // kLebesgueBound (4) times tail[m] as the field's error: check that bound on chords
    // through nk-sinc's order-8 cells, against the field interpolated in long double.
    const Mesh mesh = MakeBuiltin("builtin:nk-sinc");
    const Field* field = mesh.FindField("u");
    ASSERT_NE(field, nullptr);
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    int checked = 0, tight = 0;
    for (std::int64_t c = 0; c < mesh.CellCount(); c += 7) {
        const int p = mesh.cellOrder[c], n = p + 1;
        ASSERT_EQ(mesh.cellShape[c], CellShape::Hex);
        std::vector<double> u(n * n * n);
        for (int q = 0; q < n * n * n; ++q)
            u[q] = field->values[mesh.connectivity[mesh.cellOffsets[c] + q]];
        std::vector<double> tail(3 * p + 1);
        LagrangeHexDegreeTail(p, u.data(), tail.data());
        for (int line = 0; line < 4; ++line) {
            // A chord between points on two different faces of [0, 1]^3.
            long double a[3], b[3];
            for (int d = 0; d < 3; ++d) a[d] = unit(rng), b[d] = unit(rng);
            a[line % 3] = 0;
            b[(line + 1) % 3] = 1;
            for (int m : {3, 7, 11, 15}) {
                const LglRule& rule = LglNodes(m);
                std::vector<double> values(m + 1);
                for (int i = 0; i <= m; ++i) {
                    const long double s = 0.5L * (1 + rule.nodes[i]);
                    long double r[3];
                    for (int d = 0; d < 3; ++d) r[d] = a[d] + s * (b[d] - a[d]);
                    values[i] = double(HexValue(p, u.data(), r));
                }
                LegendreSeries series;
                InterpolateLgl(values.data(), m, 0.0, 1.0, series);
                double worst = 0;
                for (int k = 0; k <= 200; ++k) {
                    const long double s = k / 200.0L;
                    long double r[3];
                    for (int d = 0; d < 3; ++d) r[d] = a[d] + s * (b[d] - a[d]);
                    worst = std::max(worst, double(std::abs(HexValue(p, u.data(), r) -
                                                            series(double(s)))));
                }
                // Rounding of the samples and the transform aside (1e-14 of the values).
                EXPECT_LE(worst, 4 * tail[m] + 1e-14)
                    << "cell " << c << " line " << line << " degree " << m;
                ++checked;
                if (worst > 1e-3 * tail[m]) ++tight;
            }
        }
    }
    EXPECT_GT(checked, 200);
    // The bound is not vacuous: on many lines the error is within 1000x of it.
    EXPECT_GT(tight, checked / 4);
}

}  // namespace
}  // namespace hpray
