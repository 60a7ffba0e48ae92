// The register-blocked sampler of affine Lagrange hexahedra along a line
// (render/hex_line_sampler.h) against the library's generic evaluator, and its kernels
// (AVX-512 where the processor has it, AVX2) and blockings against each other.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>
#include <vector>

#include "elements/tensor_eval.h"
#include "render/hex_line_sampler.h"

namespace hpray {
namespace {

bool SameBits(double a, double b) { return std::memcmp(&a, &b, sizeof a) == 0; }

struct Line {
    std::vector<double> u;
    double ref0[3], dref[3];
    std::vector<double> t;
};

/// Random nodal values in [-1, 1] and a random line whose points t in [0, 1] stay in the
/// reference cube [0, 1]^3.
Line RandomLine(int p, int count, std::mt19937_64& rng) {
    std::uniform_real_distribution<double> unit(0, 1), sym(-1, 1);
    Line line;
    line.u.resize(std::size_t(p + 1) * (p + 1) * (p + 1));
    for (double& v : line.u) v = sym(rng);
    for (int d = 0; d < 3; ++d) {
        const double a = unit(rng), b = unit(rng);
        line.ref0[d] = a;
        line.dref[d] = b - a;
    }
    line.t.resize(count);
    for (double& v : line.t) v = unit(rng);
    return line;
}

/// sum_ijk |u_ijk l_i(x) l_j(y) l_k(z)|: what the rounding of any evaluation order scales
/// with.
double AbsTerms(int p, const double* u, const double ref[3]) {
    std::vector<double> l[3];
    for (int d = 0; d < 3; ++d) {
        l[d].resize(p + 1);
        LagrangeEquispaced1D(p, ref[d], l[d].data(), nullptr);
    }
    long double sum = 0;
    for (int k = 0; k <= p; ++k)
        for (int j = 0; j <= p; ++j)
            for (int i = 0; i <= p; ++i)
                sum += std::abs(u[i + (p + 1) * (j + (p + 1) * k)] * l[0][i] * l[1][j] *
                                l[2][k]);
    return double(sum);
}

TEST(HexLineSampler, EqualsTheGenericEvaluatorToRounding) {
    std::mt19937_64 rng(11);
    int compared = 0;
    for (int p = 1; p <= 10; ++p) {
        for (int count : {1, 3, 4, 7, 12, 16, 24, 25, 31, 48, 49, kMaxHexLineSamples}) {
            const Line line = RandomLine(p, count, rng);
            std::vector<double> out(count, 7);
            if (!SampleAffineHexLine(p, line.u.data(), line.ref0, line.dref,
                                     line.t.data(), count, out.data()))
                GTEST_SKIP()
                    << "this build has no line-sampling kernel (needs AVX2 and FMA)";
            for (int s = 0; s < count; ++s) {
                double ref[3];
                for (int d = 0; d < 3; ++d)
                    ref[d] = line.ref0[d] + line.t[s] * line.dref[d];
                const double want = HexFieldValue(p, line.u.data(), ref);
                const double bound = 64 * 2.220446049250313e-16 * (p + 1) *
                                     AbsTerms(p, line.u.data(), ref);
                ASSERT_LE(std::abs(out[s] - want), bound)
                    << "p " << p << " count " << count << " sample " << s;
                ++compared;
            }
        }
    }
    EXPECT_GT(compared, 2000);
}

TEST(HexLineSampler, EveryKernelAndBlockingGivesTheSameBits) {
    // One call of `count` samples with the processor's widest kernels (AVX-512 blocks of
    // 24, 16 and 8 samples where it has them; else AVX2 blocks of 12 and 4), the last
    // count % 4 one by one, against the AVX2 kernels alone, and against calls of four
    // samples at a time: the kernels run the same fused multiply-adds per sample, so the
    // bits must agree.
    std::mt19937_64 rng(5);
    int compared = 0;
    for (int p = 1; p <= 10; ++p) {
        for (int count : {4, 5, 8, 12, 16, 17, 20, 24, 25, 28, 32, 40, 44, 48, 51,
                          kMaxHexLineSamples}) {
            const Line line = RandomLine(p, count, rng);
            std::vector<double> whole(count), narrow(count), pieces(count);
            if (!SampleAffineHexLine(p, line.u.data(), line.ref0, line.dref,
                                     line.t.data(), count, whole.data()))
                GTEST_SKIP()
                    << "this build has no line-sampling kernel (needs AVX2 and FMA)";
            ASSERT_TRUE(SampleAffineHexLine(p, line.u.data(), line.ref0, line.dref,
                                            line.t.data(), count, narrow.data(), false));
            for (int s = 0; s < count; s += 4) {
                const int n = std::min(4, count - s);
                ASSERT_TRUE(SampleAffineHexLine(p, line.u.data(), line.ref0, line.dref,
                                                line.t.data() + s, n, pieces.data() + s));
            }
            for (int s = 0; s < count; ++s) {
                ASSERT_TRUE(SameBits(whole[s], narrow[s]))
                    << "p " << p << " count " << count << " sample " << s << ": "
                    << whole[s] << " against the AVX2 kernels' " << narrow[s];
                ASSERT_TRUE(SameBits(whole[s], pieces[s]))
                    << "p " << p << " count " << count << " sample " << s << ": "
                    << whole[s] << " against " << pieces[s] << " four at a time";
                ++compared;
            }
        }
    }
    EXPECT_GT(compared, 2000);
}

}  // namespace
}  // namespace hpray
