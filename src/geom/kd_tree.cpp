// k-d tree queries: regions under the ownership rule, point location, visibility order,
// validation.
#include "geom/kd_tree.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <utility>

namespace hpray {

ViewOrigin ViewOrigin::Perspective(const std::array<double, 3>& eye) {
    ViewOrigin view;
    view.orthographic = false;
    view.eye = eye;
    return view;
}

ViewOrigin ViewOrigin::Orthographic(const std::array<double, 3>& direction) {
    ViewOrigin view;
    view.orthographic = true;
    view.direction = direction;
    return view;
}

bool LowInFront(int axis, double split, const ViewOrigin& view) {
    if (view.orthographic) return view.direction[axis] > 0.0;
    return view.eye[axis] < split;
}

KdTree KdTree::SingleLeaf(const Box& box) {
    KdTree tree;
    KdNode leaf;
    leaf.leaf = 0;
    tree.nodes.push_back(leaf);
    tree.box = box;
    return tree;
}

std::vector<Box> KdTree::NodeBoxes() const {
    std::vector<Box> boxes(nodes.size());
    if (nodes.empty()) return boxes;
    Box rootBox = box;
    rootBox.inner = 0;
    std::vector<std::pair<int, Box>> stack{{root, rootBox}};
    while (!stack.empty()) {
        auto [id, b] = stack.back();
        stack.pop_back();
        boxes[id] = b;
        const KdNode& n = nodes[id];
        if (n.IsLeaf()) continue;
        Box low = b, high = b;
        low.hi[n.axis] = n.split;
        low.inner |= std::uint8_t(1u << (3 + n.axis));
        high.lo[n.axis] = n.split;
        high.inner |= std::uint8_t(1u << n.axis);
        stack.push_back({n.low, low});
        stack.push_back({n.high, high});
    }
    return boxes;
}

std::vector<Box> KdTree::LeafBoxes() const {
    const std::vector<Box> all = NodeBoxes();
    int count = 0;
    for (const KdNode& n : nodes)
        if (n.IsLeaf()) count = std::max(count, n.leaf + 1);
    std::vector<Box> boxes(count);
    for (std::size_t i = 0; i < nodes.size(); ++i)
        if (nodes[i].IsLeaf() && nodes[i].leaf >= 0) boxes[nodes[i].leaf] = all[i];
    return boxes;
}

int KdTree::LeafAt(const double x[3]) const {
    int id = root;
    while (!nodes[id].IsLeaf())
        id = x[nodes[id].axis] < nodes[id].split ? nodes[id].low : nodes[id].high;
    return nodes[id].leaf;
}

void KdTree::TouchedLeaves(const Box& b, std::vector<int>& leaves) const {
    std::vector<int> stack;
    TouchedLeaves(b, leaves, stack);
}

void KdTree::TouchedLeaves(const Box& b, std::vector<int>& leaves,
                           std::vector<int>& stack) const {
    stack.assign(1, root);
    while (!stack.empty()) {
        const KdNode& n = nodes[stack.back()];
        stack.pop_back();
        if (n.IsLeaf()) {
            leaves.push_back(n.leaf);
            continue;
        }
        if (b.hi[n.axis] >= n.split) stack.push_back(n.high);
        if (b.lo[n.axis] <= n.split) stack.push_back(n.low);
    }
}

std::vector<int> KdTree::FrontToBack(const ViewOrigin& view) const {
    std::vector<int> order;
    // Explicit stack: push the back child first so the front child is visited first.
    std::vector<int> stack{root};
    while (!stack.empty()) {
        const KdNode& n = nodes[stack.back()];
        stack.pop_back();
        if (n.IsLeaf()) {
            order.push_back(n.leaf);
            continue;
        }
        const bool lowFront = LowInFront(n.axis, n.split, view);
        stack.push_back(lowFront ? n.high : n.low);
        stack.push_back(lowFront ? n.low : n.high);
    }
    return order;
}

int KdTree::Height() const {
    int height = 0;
    std::vector<std::pair<int, int>> stack{{root, 0}};
    while (!stack.empty()) {
        const auto [id, depth] = stack.back();
        stack.pop_back();
        const KdNode& n = nodes[id];
        if (n.IsLeaf()) {
            height = std::max(height, depth);
            continue;
        }
        stack.push_back({n.low, depth + 1});
        stack.push_back({n.high, depth + 1});
    }
    return height;
}

std::string KdTree::Problem(int leaves) const {
    std::ostringstream os;
    const int n = static_cast<int>(nodes.size());
    if (leaves < 1) return "the leaf count must be at least 1";
    if (n < 1) return "the tree has no node";
    if (root < 0 || root >= n) return "root index out of range";
    std::vector<int> reached(n, 0), leafSeen(leaves, 0);
    std::vector<int> stack{root};
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
        const KdNode& node = nodes[id];
        if (node.IsLeaf()) {
            if (node.axis != -1 || node.leaf < 0 || node.leaf >= leaves) {
                os << "leaf node " << id << " has number " << node.leaf << " outside [0, "
                   << leaves << ")";
                return os.str();
            }
            if (++leafSeen[node.leaf] > 1) {
                os << "leaf number " << node.leaf << " appears more than once";
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
    for (int r = 0; r < leaves; ++r)
        if (leafSeen[r] == 0) {
            os << "leaf number " << r << " is missing";
            return os.str();
        }
    return {};
}

namespace {

int EmitRegular(KdTree& tree, int first, int count, const Box& box) {
    if (count == 1) {
        KdNode leaf;
        leaf.leaf = first;
        tree.nodes.push_back(leaf);
        return static_cast<int>(tree.nodes.size()) - 1;
    }
    int axis = 0;
    for (int d = 1; d < 3; ++d)
        if (box.hi[d] - box.lo[d] > box.hi[axis] - box.lo[axis]) axis = d;
    const int lowCount = count / 2;
    KdNode node;
    node.axis = axis;
    node.split = box.lo[axis] + (box.hi[axis] - box.lo[axis]) * lowCount / count;
    tree.nodes.push_back(node);
    const int self = static_cast<int>(tree.nodes.size()) - 1;
    Box low = box, high = box;
    low.hi[axis] = node.split;
    high.lo[axis] = node.split;
    const int lowId = EmitRegular(tree, first, lowCount, low);
    const int highId = EmitRegular(tree, first + lowCount, count - lowCount, high);
    tree.nodes[self].low = lowId;
    tree.nodes[self].high = highId;
    return self;
}

}  // namespace

KdTree RegularKdTree(int count, const Box& box) {
    KdTree tree;
    tree.box = box;
    tree.root = EmitRegular(tree, 0, std::max(count, 1), box);
    return tree;
}

}  // namespace hpray
