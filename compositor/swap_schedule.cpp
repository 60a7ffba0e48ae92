// Tree-aware swap and direct-send schedules: piece assignment per merge step.
#include "swap_schedule.h"

#include <algorithm>

#include "util/check.h"

namespace hpray::compositor {
namespace {

/// Range k of `count` equal cuts of [0, pixels) (sizes differ by at most one pixel).
PixelRange EqualCut(std::size_t pixels, std::size_t count, std::size_t k) {
    // k * pixels fits easily in 64 bits for any image and rank count in use.
    return {k * pixels / count, (k + 1) * pixels / count};
}

/// Ranks of every subtree in "swap order": a node's order interleaves its children's
/// orders evenly (the k-th of g ranks of a child sits at fraction (k + 1/2) / g; ties put
/// the low child first), so that every subtree's ranks are spread across the image.
/// Filled bottom-up; `orders[id]` for every node below and at `id`.
void SwapOrders(const KdTree& tree, int id,
                std::vector<std::vector<int>>& orders) {
    const KdNode& node = tree.nodes[id];
    if (node.IsLeaf()) {
        orders[id] = {node.leaf};
        return;
    }
    SwapOrders(tree, node.low, orders);
    SwapOrders(tree, node.high, orders);
    const std::vector<int>& a = orders[node.low];
    const std::vector<int>& b = orders[node.high];
    std::vector<int>& out = orders[id];
    out.reserve(a.size() + b.size());
    std::size_t i = 0, j = 0;
    while (i < a.size() || j < b.size()) {
        // Compare (2i + 1) / (2 |a|) with (2j + 1) / (2 |b|) exactly, in integers.
        const bool takeLow =
            j == b.size() ||
            (i < a.size() && (2 * i + 1) * b.size() <= (2 * j + 1) * a.size());
        out.push_back(takeLow ? a[i++] : b[j++]);
    }
}

/// The tiling of a child given its parent's tiling `parent` (pieces in the parent's swap
/// order, increasing ranges; `inChild` marks the child's ranks): each of the child's
/// ranks keeps its parent piece and grows over the gaps left by the other child's ranks.
/// The boundary between two consecutive child pieces is the equal cut of the image among
/// the child's ranks, clamped into the gap, so pieces stay as equal as the parent allows
/// (exact halves for classic binary swap). Every parent piece lies inside the child
/// piece of the same rank.
std::vector<Piece> ChildTiling(const std::vector<Piece>& parent,
                               const std::vector<char>& inChild, std::size_t pixels) {
    std::vector<Piece> out;
    std::size_t count = 0;
    for (const Piece& piece : parent) count += inChild[piece.rank] ? 1 : 0;
    std::size_t gapStart = 0;  // end of the previous child piece's parent range
    for (const Piece& piece : parent) {
        if (!inChild[piece.rank]) continue;
        std::size_t begin = 0;
        if (!out.empty()) {
            const std::size_t target = EqualCut(pixels, count, out.size()).begin;
            begin = std::clamp(target, gapStart, piece.range.begin);
            out.back().range.end = begin;
        }
        out.push_back({piece.rank, PixelRange{begin, pixels}});
        gapStart = piece.range.end;
    }
    return out;
}

/// Top-down: records the step of node `id`, whose ranks hold `tiling` after it, and
/// recurses into its children. Steps are stored in post-order afterwards.
void PlanNode(const KdTree& tree, int id, int depth, std::size_t pixels,
              const std::vector<Piece>& tiling, std::vector<char>& inChild,
              const std::vector<std::vector<int>>& orders, CompositePlan& plan) {
    const KdNode& node = tree.nodes[id];
    if (node.IsLeaf()) return;
    MergeStep step;
    step.node = id;
    step.tag = depth;
    step.result = tiling;
    for (int child : {node.low, node.high}) {
        for (int r : orders[child]) inChild[r] = 1;
        step.children.push_back(ChildTiling(tiling, inChild, pixels));
        for (int r : orders[child]) inChild[r] = 0;
    }
    const std::vector<Piece> low = step.children[0], high = step.children[1];
    PlanNode(tree, node.low, depth + 1, pixels, low, inChild, orders, plan);
    PlanNode(tree, node.high, depth + 1, pixels, high, inChild, orders, plan);
    plan.steps.push_back(std::move(step));
}

}  // namespace

CompositePlan PlanTreeSwap(const KdTree& tree, int ranks, std::size_t pixels) {
    ValidateTree(tree, ranks);
    CompositePlan plan;
    plan.pixels = pixels;
    plan.ranks = ranks;
    std::vector<std::vector<int>> orders(tree.nodes.size());
    SwapOrders(tree, tree.root, orders);
    // The final pieces: equal cuts of the image in the root's swap order.
    std::vector<Piece> last;
    plan.finalRange.assign(ranks, PixelRange{});
    const std::vector<int>& rootOrder = orders[tree.root];
    for (std::size_t k = 0; k < rootOrder.size(); ++k) {
        last.push_back({rootOrder[k], EqualCut(pixels, rootOrder.size(), k)});
        plan.finalRange[rootOrder[k]] = last.back().range;
    }
    std::vector<char> inChild(ranks, 0);
    PlanNode(tree, tree.root, 0, pixels, last, inChild, orders, plan);
    plan.rounds = tree.Height();
    return plan;
}

CompositePlan PlanDirectSend(int ranks, std::size_t pixels) {
    HPRAY_CHECK_GE(ranks, 1);
    CompositePlan plan;
    plan.pixels = pixels;
    plan.ranks = ranks;
    plan.finalRange.assign(ranks, PixelRange{0, pixels});
    if (ranks == 1) return plan;
    MergeStep step;
    for (int r = 0; r < ranks; ++r) {
        step.children.push_back({Piece{r, PixelRange{0, pixels}}});
        const PixelRange cut = EqualCut(pixels, ranks, r);
        step.result.push_back({r, cut});
        plan.finalRange[r] = cut;
    }
    plan.steps.push_back(std::move(step));
    plan.rounds = 1;
    return plan;
}

std::vector<std::size_t> DensePixelsSent(const CompositePlan& plan) {
    std::vector<std::size_t> sent(plan.ranks, 0);
    for (const MergeStep& step : plan.steps)
        for (const auto& child : step.children)
            for (const Piece& mine : child)
                for (const Piece& other : step.result)
                    if (other.rank != mine.rank)
                        sent[mine.rank] += Intersect(mine.range, other.range).Size();
    return sent;
}

}  // namespace hpray::compositor
