// Tests of the swap schedules: tilings, the S (1 - 1/P) bound for any tree, rounds.
#include <gtest/gtest.h>

#include <random>

#include "composite_test_util.h"
#include "swap_schedule.h"

namespace hpray::compositor {
namespace {

/// Every listed piece set must tile [0, pixels) with one piece per rank.
void ExpectTiling(const std::vector<Piece>& pieces, std::size_t pixels,
                  const std::string& what) {
    std::size_t at = 0;
    for (const Piece& piece : pieces) {
        ASSERT_EQ(piece.range.begin, at) << what;
        ASSERT_LE(piece.range.begin, piece.range.end) << what;
        at = piece.range.end;
    }
    EXPECT_EQ(at, pixels) << what;
}

void CheckPlan(const CompositePlan& plan, const std::string& what) {
    const int ranks = plan.ranks;
    const std::size_t n = plan.pixels;
    std::vector<int> owners(ranks, 0);
    for (const MergeStep& step : plan.steps) {
        std::size_t groupSize = 0;
        for (const auto& child : step.children) {
            ExpectTiling(child, n, what + " child");
            groupSize += child.size();
        }
        ExpectTiling(step.result, n, what + " result");
        EXPECT_EQ(step.result.size(), groupSize) << what;
        // A rank's new piece lies inside its old one: it never sends what it must keep.
        for (const Piece& now : step.result)
            for (const auto& child : step.children)
                for (const Piece& before : child)
                    if (before.rank == now.rank && !now.range.Empty()) {
                        EXPECT_LE(before.range.begin, now.range.begin) << what;
                        EXPECT_GE(before.range.end, now.range.end) << what;
                    }
    }
    // Final ranges tile the image.
    std::vector<Piece> last;
    for (int r = 0; r < ranks; ++r) last.push_back({r, plan.finalRange[r]});
    std::sort(last.begin(), last.end(), [](const Piece& x, const Piece& y) {
        return x.range.begin != y.range.begin ? x.range.begin < y.range.begin
                                              : x.range.end < y.range.end;
    });
    ExpectTiling(last, n, what + " final");
    // Each rank's final range is an equal cut: n / P rounded.
    for (int r = 0; r < ranks; ++r) {
        EXPECT_LE(plan.finalRange[r].Size(), n / ranks + 1) << what;
        EXPECT_GE(plan.finalRange[r].Size() + 1, n / ranks) << what;
    }
    // The binary-swap bound, per rank, with every pixel active: S (1 - 1/P), up to a
    // pixel of rounding; and exactly everything but the final piece.
    const std::vector<std::size_t> sent = DensePixelsSent(plan);
    const double bound = n * (1.0 - 1.0 / ranks) + 1.0;
    for (int r = 0; r < ranks; ++r) {
        EXPECT_LE(sent[r], bound) << what << " rank " << r;
        if (!plan.steps.empty()) {
            EXPECT_EQ(sent[r], n - plan.finalRange[r].Size()) << what;
        }
    }
}

TEST(SwapSchedule, RegularTreesMeetTheBoundForAnyP) {
    for (int ranks = 1; ranks <= 64; ++ranks)
        for (std::size_t pixels :
             {std::size_t{5}, std::size_t{640 * 480}, std::size_t{1} << 20}) {
            const KdTree tree = RegularKdTree(ranks, hpray::Box{{0, 0, 0}, {1, 1, 1}});
            const CompositePlan plan = PlanTreeSwap(tree, ranks, pixels);
            EXPECT_EQ(plan.rounds, tree.Height());
            CheckPlan(plan,
                      "P=" + std::to_string(ranks) + " N=" + std::to_string(pixels));
        }
}

TEST(SwapSchedule, RandomTreeShapesMeetTheBound) {
    for (int seed = 0; seed < 200; ++seed) {
        std::mt19937 rng(seed);
        const int ranks = 2 + seed % 40;
        const KdTree tree =
            testutil::RandomRankTree(ranks, rng, testutil::Box{}, seed % 2 == 0);
        const std::size_t pixels = 1000 + 7919 * static_cast<std::size_t>(seed);
        CheckPlan(PlanTreeSwap(tree, ranks, pixels), "seed " + std::to_string(seed));
    }
}

TEST(SwapSchedule, BalancedPowerOfTwoIsClassicBinarySwap) {
    // Round k halves every rank's piece: rank sends N/2 + N/4 + ... + N/P exactly.
    for (int log2p = 1; log2p <= 6; ++log2p) {
        const int ranks = 1 << log2p;
        const std::size_t pixels = std::size_t{1} << 16;
        const CompositePlan plan =
            PlanTreeSwap(RegularKdTree(ranks, hpray::Box{{0, 0, 0}, {1, 1, 1}}), ranks, pixels);
        EXPECT_EQ(plan.rounds, log2p);
        const std::vector<std::size_t> sent = DensePixelsSent(plan);
        for (int r = 0; r < ranks; ++r) EXPECT_EQ(sent[r], pixels - pixels / ranks);
        for (const MergeStep& step : plan.steps)
            for (const Piece& piece : step.result)
                EXPECT_EQ(piece.range.Size(), pixels / step.result.size());
    }
}

TEST(SwapSchedule, DirectSendIsOneRound) {
    for (int ranks = 1; ranks <= 9; ++ranks) {
        const CompositePlan plan = PlanDirectSend(ranks, 12345);
        EXPECT_EQ(plan.rounds, ranks > 1 ? 1 : 0);
        CheckPlan(plan, "direct P=" + std::to_string(ranks));
    }
}

TEST(SwapSchedule, TinyImagesWithFewerPixelsThanRanks) {
    for (int ranks = 2; ranks <= 9; ++ranks)
        for (std::size_t pixels = 0; pixels < 4; ++pixels)
            CheckPlan(
                PlanTreeSwap(RegularKdTree(ranks, hpray::Box{{0, 0, 0}, {1, 1, 1}}), ranks, pixels),
                "tiny");
}

}  // namespace
}  // namespace hpray::compositor
