// The tree over ranks: validation, visibility order, construction from the brick tree.
#include "composite_tree.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "util/check.h"
#include "util/error.h"

namespace hpray::compositor {

CompositeTree CompositeTree::SingleRank() {
    CompositeTree tree;
    CompositeNode leaf;
    leaf.rank = 0;
    tree.nodes.push_back(leaf);
    tree.root = 0;
    return tree;
}

CompositeView CompositeView::Perspective(const std::array<double, 3>& eye) {
    CompositeView view;
    view.orthographic = false;
    view.eye = eye;
    return view;
}

CompositeView CompositeView::Orthographic(const std::array<double, 3>& direction) {
    CompositeView view;
    view.orthographic = true;
    view.direction = direction;
    return view;
}

CompositeView ViewFromCamera(const SceneCamera& camera) {
    if (!camera.orthographic) return CompositeView::Perspective(camera.position);
    // Only the sign of each component matters, so no normalisation is needed.
    return CompositeView::Orthographic({camera.lookAt[0] - camera.position[0],
                                        camera.lookAt[1] - camera.position[1],
                                        camera.lookAt[2] - camera.position[2]});
}

bool LowInFront(int axis, double split, const CompositeView& view) {
    HPRAY_CHECK(axis >= 0 && axis < 3);
    if (view.orthographic) return !(view.direction[axis] < 0.0);
    return !(view.eye[axis] > split);
}

std::string TreeProblem(const CompositeTree& tree, int ranks) {
    std::ostringstream os;
    const int n = static_cast<int>(tree.nodes.size());
    if (ranks < 1) return "rank count must be at least 1";
    if (n < 1) return "the tree has no node";
    if (tree.root < 0 || tree.root >= n) return "root index out of range";
    std::vector<int> reached(n, 0), rankLeaves(ranks, 0);
    std::vector<int> stack{tree.root};
    while (!stack.empty()) {
        const int id = stack.back();
        stack.pop_back();
        if (id < 0 || id >= n) {
            os << "child index " << id << " out of range [0, " << n << ")";
            return os.str();
        }
        if (++reached[id] > 1) {
            os << "node " << id << " is reached twice (a cycle or shared child)";
            return os.str();
        }
        const CompositeNode& node = tree.nodes[id];
        if (node.IsLeaf()) {
            if (node.axis != -1 || node.rank < 0 || node.rank >= ranks) {
                os << "leaf node " << id << " has rank " << node.rank << " outside [0, "
                   << ranks << ")";
                return os.str();
            }
            if (++rankLeaves[node.rank] > 1) {
                os << "rank " << node.rank << " owns more than one leaf";
                return os.str();
            }
            continue;
        }
        if (node.axis > 2 || !std::isfinite(node.split)) {
            os << "node " << id << " has axis " << node.axis << " and split "
               << node.split;
            return os.str();
        }
        stack.push_back(node.low);
        stack.push_back(node.high);
    }
    for (int r = 0; r < ranks; ++r) {
        if (rankLeaves[r] == 0) {
            os << "rank " << r << " owns no leaf";
            return os.str();
        }
    }
    return {};
}

void ValidateTree(const CompositeTree& tree, int ranks) {
    const std::string problem = TreeProblem(tree, ranks);
    if (!problem.empty()) throw InternalError("invalid compositing tree: " + problem);
}

std::vector<int> VisibilityOrder(const CompositeTree& tree, const CompositeView& view) {
    std::vector<int> order;
    // Explicit stack: push the back child first so the front child is visited first.
    std::vector<int> stack{tree.root};
    while (!stack.empty()) {
        const CompositeNode& node = tree.nodes[stack.back()];
        stack.pop_back();
        if (node.IsLeaf()) {
            order.push_back(node.rank);
            continue;
        }
        const bool lowFront = LowInFront(node.axis, node.split, view);
        stack.push_back(lowFront ? node.high : node.low);
        stack.push_back(lowFront ? node.low : node.high);
    }
    return order;
}

int TreeHeight(const CompositeTree& tree) {
    int height = 0;
    std::vector<std::pair<int, int>> stack{{tree.root, 0}};
    while (!stack.empty()) {
        const auto [id, depth] = stack.back();
        stack.pop_back();
        const CompositeNode& node = tree.nodes[id];
        if (node.IsLeaf()) {
            height = std::max(height, depth);
            continue;
        }
        stack.push_back({node.low, depth + 1});
        stack.push_back({node.high, depth + 1});
    }
    return height;
}

namespace {

/// Recursion state of BuildRankTree.
struct RankTreeBuilder {
    const std::vector<BrickTreeNode>& bricks;
    const std::vector<int>& brickRank;
    std::vector<int> visits;  ///< per brick-tree node, to detect shared children
    std::vector<int> owner;   ///< per brick-tree node: its single owning rank, or -1
    CompositeTree out;
    std::vector<int> rankLeaf;  ///< node index of each rank's leaf, -1 while none

    /// Fills owner[] below `id` (the single rank owning every brick there, or -1 if
    /// several do) and checks the brick tree's structure. Returns owner[id].
    int FindOwners(int id, int depth) {
        const int n = static_cast<int>(bricks.size());
        HPRAY_CHECK_MSG(id >= 0 && id < n, "brick tree child index " << id);
        HPRAY_CHECK_MSG(++visits[id] == 1, "brick tree node " << id << " reached twice");
        HPRAY_CHECK_MSG(depth <= n, "brick tree deeper than its node count");
        const BrickTreeNode& node = bricks[id];
        if (node.axis < 0) {
            HPRAY_CHECK_MSG(
                node.brick >= 0 && node.brick < static_cast<int>(brickRank.size()),
                "brick tree leaf " << id << " names brick " << node.brick);
            return owner[id] = brickRank[node.brick];
        }
        HPRAY_CHECK_MSG(node.axis <= 2 && std::isfinite(node.split),
                        "brick tree node " << id << " has axis " << node.axis);
        const int lowOwner = FindOwners(node.low, depth + 1);
        const int highOwner = FindOwners(node.high, depth + 1);
        return owner[id] = lowOwner >= 0 && lowOwner == highOwner ? lowOwner : -1;
    }

    /// Appends the rank-tree node of brick node `id`; returns its index.
    int Emit(int id) {
        const BrickTreeNode& node = bricks[id];
        if (owner[id] >= 0) {
            const int rank = owner[id];
            HPRAY_CHECK_MSG(rankLeaf[rank] < 0,
                            "rank "
                                << rank
                                << " owns bricks in two separate subtrees; ranks must "
                                   "own whole k-d subtrees");
            CompositeNode leaf;
            leaf.rank = rank;
            out.nodes.push_back(leaf);
            rankLeaf[rank] = static_cast<int>(out.nodes.size()) - 1;
            return rankLeaf[rank];
        }
        CompositeNode split;
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

/// Appends the subtree of ranks [first, first + count) over box [lo, hi]; returns its
/// index.
int EmitRegular(CompositeTree& tree, int first, int count, std::array<double, 3> lo,
                std::array<double, 3> hi) {
    if (count == 1) {
        CompositeNode leaf;
        leaf.rank = first;
        tree.nodes.push_back(leaf);
        return static_cast<int>(tree.nodes.size()) - 1;
    }
    int axis = 0;
    for (int d = 1; d < 3; ++d)
        if (hi[d] - lo[d] > hi[axis] - lo[axis]) axis = d;
    const int lowCount = count / 2;
    CompositeNode node;
    node.axis = axis;
    node.split = lo[axis] + (hi[axis] - lo[axis]) * lowCount / count;
    tree.nodes.push_back(node);
    const int self = static_cast<int>(tree.nodes.size()) - 1;
    std::array<double, 3> lowHi = hi, highLo = lo;
    lowHi[axis] = node.split;
    highLo[axis] = node.split;
    const int low = EmitRegular(tree, first, lowCount, lo, lowHi);
    const int high = EmitRegular(tree, first + lowCount, count - lowCount, highLo, hi);
    tree.nodes[self].low = low;
    tree.nodes[self].high = high;
    return self;
}

}  // namespace

CompositeTree BuildRankTree(const std::vector<BrickTreeNode>& brickTree, int root,
                            const std::vector<int>& brickRank, int ranks) {
    HPRAY_CHECK_GE(ranks, 1);
    HPRAY_CHECK_MSG(root >= 0 && root < static_cast<int>(brickTree.size()),
                    "brick tree root " << root);
    for (std::size_t b = 0; b < brickRank.size(); ++b)
        HPRAY_CHECK_MSG(brickRank[b] >= 0 && brickRank[b] < ranks,
                        "brick " << b << " assigned to rank " << brickRank[b]);
    RankTreeBuilder builder{brickTree,
                            brickRank,
                            std::vector<int>(brickTree.size(), 0),
                            std::vector<int>(brickTree.size(), -1),
                            CompositeTree{},
                            std::vector<int>(ranks, -1)};
    builder.FindOwners(root, 0);
    builder.out.root = builder.Emit(root);
    for (int r = 0; r < ranks; ++r)
        HPRAY_CHECK_MSG(builder.rankLeaf[r] >= 0, "rank " << r << " owns no brick");
    ValidateTree(builder.out, ranks);
    return builder.out;
}

CompositeTree RegularRankTree(int ranks, const std::array<double, 3>& lo,
                              const std::array<double, 3>& hi) {
    HPRAY_CHECK_GE(ranks, 1);
    CompositeTree tree;
    tree.root = EmitRegular(tree, 0, ranks, lo, hi);
    return tree;
}

}  // namespace hpray::compositor
