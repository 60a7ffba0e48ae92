// The tree over ranks: validation and construction from the brick tree.
#include "composite_tree.h"

#include <algorithm>
#include <cmath>

#include "util/check.h"
#include "util/error.h"

namespace hpray::compositor {

void ValidateTree(const KdTree& tree, int ranks) {
    const std::string problem = tree.Problem(ranks);
    if (!problem.empty()) throw InternalError("invalid compositing tree: " + problem);
}

namespace {

/// Recursion state of BuildRankTree.
struct RankTreeBuilder {
    const std::vector<KdNode>& bricks;
    const std::vector<int>& brickRank;
    std::vector<int> visits;  ///< per brick-tree node, to detect shared children
    std::vector<int> owner;   ///< per brick-tree node: its single owning rank, or -1
    KdTree out;
    std::vector<int> rankLeaf;  ///< node index of each rank's leaf, -1 while none

    /// Fills owner[] below `id` (the single rank owning every brick there, or -1 if
    /// several do) and checks the brick tree's structure. Returns owner[id].
    int FindOwners(int id, int depth) {
        const int n = static_cast<int>(bricks.size());
        HPRAY_CHECK_MSG(id >= 0 && id < n, "brick tree child index " << id);
        HPRAY_CHECK_MSG(++visits[id] == 1, "brick tree node " << id << " reached twice");
        HPRAY_CHECK_MSG(depth <= n, "brick tree deeper than its node count");
        const KdNode& node = bricks[id];
        if (node.axis < 0) {
            HPRAY_CHECK_MSG(
                node.leaf >= 0 && node.leaf < static_cast<int>(brickRank.size()),
                "brick tree leaf " << id << " names brick " << node.leaf);
            return owner[id] = brickRank[node.leaf];
        }
        HPRAY_CHECK_MSG(node.axis <= 2 && std::isfinite(node.split),
                        "brick tree node " << id << " has axis " << node.axis);
        const int lowOwner = FindOwners(node.low, depth + 1);
        const int highOwner = FindOwners(node.high, depth + 1);
        return owner[id] = lowOwner >= 0 && lowOwner == highOwner ? lowOwner : -1;
    }

    /// Appends the rank-tree node of brick node `id`; returns its index.
    int Emit(int id) {
        const KdNode& node = bricks[id];
        if (owner[id] >= 0) {
            const int rank = owner[id];
            HPRAY_CHECK_MSG(rankLeaf[rank] < 0,
                            "rank "
                                << rank
                                << " owns bricks in two separate subtrees; ranks must "
                                   "own whole k-d subtrees");
            KdNode leaf;
            leaf.leaf = rank;
            out.nodes.push_back(leaf);
            rankLeaf[rank] = static_cast<int>(out.nodes.size()) - 1;
            return rankLeaf[rank];
        }
        KdNode split;
        split.axis = node.axis;
        split.split = node.split;
        out.nodes.push_back(split);
        const int self = static_cast<int>(out.nodes.size()) - 1;
        const int low = Emit(node.low);
        const int high = Emit(node.high);
        out.nodes[self].low = low;
        out.nodes[self].high = high;
        return self;
    }
};

}  // namespace

KdTree BuildRankTree(const KdTree& brickTree, const std::vector<int>& brickRank, int ranks) {
    HPRAY_CHECK_GE(ranks, 1);
    const int root = brickTree.root;
    HPRAY_CHECK_MSG(root >= 0 && root < static_cast<int>(brickTree.nodes.size()),
                    "brick tree root " << root);
    for (std::size_t b = 0; b < brickRank.size(); ++b)
        HPRAY_CHECK_MSG(brickRank[b] >= 0 && brickRank[b] < ranks,
                        "brick " << b << " assigned to rank " << brickRank[b]);
    RankTreeBuilder builder{brickTree.nodes,
                            brickRank,
                            std::vector<int>(brickTree.nodes.size(), 0),
                            std::vector<int>(brickTree.nodes.size(), -1),
                            KdTree{},
                            std::vector<int>(ranks, -1)};
    builder.FindOwners(root, 0);
    builder.out.root = builder.Emit(root);
    builder.out.box = brickTree.box;
    for (int r = 0; r < ranks; ++r)
        HPRAY_CHECK_MSG(builder.rankLeaf[r] >= 0, "rank " << r << " owns no brick");
    ValidateTree(builder.out, ranks);
    return builder.out;
}

}  // namespace hpray::compositor
