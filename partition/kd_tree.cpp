// BuildKdTree: level-synchronous weighted-median splits by histogram refinement and exact
// selection over streamed centroids; tree queries.
#include "kd_tree.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_group.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include "util/check.h"
#include "util/log.h"

namespace hpray::partition {
namespace {

constexpr int kBins = 1024;
constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr int kMaxRounds = 40;

/// The search for one node's split plane.
struct Search {
    int node = -1;
    int axis = 0;
    int lowLeaves = 0, leaves = 0;
    double total = 0;         ///< node cost (known after the first pass)
    double target = 0;        ///< wanted cost of the low side
    double a = 0, b = 0;      ///< current interval [a, b) of the axis coordinate
    double below = 0;         ///< cost of the node's cells with x < a
    bool collect = false;     ///< next pass collects the centroids in [a, b)
    double tieValue = 0;
    double tieBelow = 0;  ///< cost of the node's cells with x < tieValue
    double planeSplit = 0, planeError = 0;  ///< best plane, kept while trying a tie-break
    bool tieBreak = false;
    std::array<double, 2> tie{};
    std::vector<std::array<double, 3>> tieCollected;  ///< (y, z, cost) on the plane
    bool first = true;  ///< the first pass also measures the total
    bool done = false;
    double split = 0;
    int rounds = 0;
    std::vector<double> binCost;
    std::vector<std::int64_t> binCount;
    std::vector<double> binLo, binHi;  ///< least and greatest coordinate in each bin
    std::vector<double> edges;         ///< Edge(0..kBins) of the histogram's interval
    double scale = 0;                  ///< kBins / (b - a), for Bin's first guess
    /// (x, cost, y, z) of the centroids in [a, b), y and z for a tie-break
    std::vector<std::array<double, 4>> collected;

    double Edge(int k) const {
        if (k == kBins) return b;
        return a + (b - a) * (static_cast<double>(k) / kBins);
    }
    /// The histogram bin of coordinate x in [a, b): Edge(k) <= x < Edge(k + 1), the
    /// greatest k with Edge(k) <= x whatever the first guess (edges do not decrease), so
    /// the guess may round differently from the edges. Needs the edges of ResetHistogram.
    int Bin(double x) const {
        double g = (x - a) * scale;
        if (!(g >= 0)) g = 0;
        if (g > kBins - 1) g = kBins - 1;
        int k = static_cast<int>(g);
        while (k > 0 && x < edges[k]) --k;
        while (k < kBins - 1 && x >= edges[k + 1]) ++k;
        return k;
    }
    /// Empties the histogram of the interval [a, b) and tabulates its edges.
    void ResetHistogram() {
        edges.resize(kBins + 1);
        for (int k = 0; k <= kBins; ++k) edges[k] = Edge(k);
        scale = kBins / (b - a);
        binCost.assign(kBins, 0.0);
        binCount.assign(kBins, 0);
        binLo.assign(kBins, std::numeric_limits<double>::infinity());
        binHi.assign(kBins, -std::numeric_limits<double>::infinity());
    }
};

/// What a pass does with one point: the index of its node's search (-1: none or done)
/// and the histogram bin (>= 0) or one of the actions below; and the point.
struct Routed {
    int search = -1;
    int action = 0;
    WeightedPoint point;
};
constexpr int kBelow = -3;    ///< x < a
constexpr int kAbove = -4;    ///< x >= b
constexpr int kCollect = -5;  ///< in [a, b), collected for the exact split

/// Adds routed points to their searches, in order.
void Sum(std::vector<Search>& searches, const Routed* routed, std::size_t count) {
    for (std::size_t i = 0; i < count; ++i) {
        const Routed& r = routed[i];
        if (r.search < 0) continue;
        const WeightedPoint& p = r.point;
        Search& s = searches[r.search];
        if (s.first) s.total += p.cost;
        if (r.action >= 0) {
            const double x = p.x[s.axis];
            s.binCost[r.action] += p.cost;
            ++s.binCount[r.action];
            s.binLo[r.action] = std::min(s.binLo[r.action], x);
            s.binHi[r.action] = std::max(s.binHi[r.action], x);
        } else if (r.action == kBelow) {
            if (s.first) s.below += p.cost;  // cannot happen: a is the box's lo
        } else if (r.action == kCollect) {
            s.collected.push_back(
                {p.x[s.axis], p.cost, p.x[(s.axis + 1) % 3], p.x[(s.axis + 2) % 3]});
        }
    }
}

/// Chooses the best split among candidates: low cost at s is `lowCost`.
struct Best {
    double split = 0;
    double error = std::numeric_limits<double>::infinity();
    void Offer(double s, double lowCost, double target) {
        const double e = std::abs(lowCost - target);
        if (e < error) {
            error = e;
            split = s;
        }
    }
};

}  // namespace

CentroidBlocks::CentroidBlocks(std::size_t maxBytes)
    : maxBlocks_(std::max<std::size_t>(
          2, maxBytes / sizeof(std::array<float, 6>) & ~std::size_t(1))) {
    current_ = Box::Empty();
}

void CentroidBlocks::Add(const double x[3]) {
    current_.Extend(x);
    ++count_;
    const std::int64_t mask = (std::int64_t(1) << shift_) - 1;
    if ((count_ & mask) != 0) return;
    if (boxes_.size() == maxBlocks_) {
        // Full: neighbours merge into blocks of twice the centroids, and the block just
        // completed becomes the first half of the next one.
        for (std::size_t i = 0; i < maxBlocks_ / 2; ++i)
            for (int d = 0; d < 3; ++d) {
                boxes_[i][d] = std::min(boxes_[2 * i][d], boxes_[2 * i + 1][d]);
                boxes_[i][3 + d] =
                    std::max(boxes_[2 * i][3 + d], boxes_[2 * i + 1][3 + d]);
            }
        boxes_.resize(maxBlocks_ / 2);
        ++shift_;
        return;
    }
    std::array<float, 6> rounded;
    for (int d = 0; d < 3; ++d) {
        constexpr float inf = std::numeric_limits<float>::infinity();
        float lo = static_cast<float>(current_.lo[d]),
              hi = static_cast<float>(current_.hi[d]);
        if (static_cast<double>(lo) > current_.lo[d]) lo = std::nextafter(lo, -inf);
        if (static_cast<double>(hi) < current_.hi[d]) hi = std::nextafter(hi, inf);
        rounded[d] = lo;
        rounded[3 + d] = hi;
    }
    boxes_.push_back(rounded);
    current_ = Box::Empty();
}

Box CentroidBlocks::BlockBox(std::size_t b) const {
    if (b == boxes_.size()) return current_;  // the block being filled
    const std::array<float, 6>& f = boxes_[b];
    return Box{{f[0], f[1], f[2]}, {f[3], f[4], f[5]}};
}

int OwnerBrick(const KdTree& tree, const double x[3]) {
    const std::vector<KdNode>& nodes = tree.nodes;
    int n = tree.root;
    while (nodes[n].axis >= 0) n = GoesLow(nodes[n], x) ? nodes[n].low : nodes[n].high;
    return nodes[n].leaf;
}

KdTree BuildKdTree(const Box& root, int leaves, const CentroidPass& pass,
                   std::size_t collectLimit) {
    HPRAY_CHECK_GE(leaves, 1);
    std::vector<KdNode> nodes(1);
    std::vector<Box> boxes{root};  // each node's region (closed; for the search only)
    // Each node's region without its faces on split planes, open to infinity at the root
    // box: a centroid strictly inside it descends to that node, however GoesLow breaks
    // ties on the planes.
    std::vector<Box> interiors{Box{{-kInf, -kInf, -kInf}, {kInf, kInf, kInf}}};
    std::vector<int> leafCount{leaves};
    // Exclusive upper ends of each node's region per axis: the root's region is closed,
    // so its end is the next double above the box.
    std::vector<std::array<double, 3>> ends(1);
    for (int d = 0; d < 3; ++d)
        ends[0][d] = std::nextafter(root.hi[d], std::numeric_limits<double>::infinity());

    std::vector<int> level{0};
    std::array<std::vector<std::pair<double, double>>, 3> slabs;
    std::vector<Routed> routed[2];  // the block being summed and the next one
    while (true) {
        std::vector<Search> searches;
        std::vector<int> searchOf(nodes.size(), -1);
        for (int n : level) {
            if (leafCount[n] < 2) continue;
            Search s;
            s.node = n;
            s.leaves = leafCount[n];
            s.lowLeaves = leafCount[n] / 2;
            const Box& box = boxes[n];
            int axis = 0;
            for (int d = 1; d < 3; ++d)
                if (box.hi[d] - box.lo[d] > box.hi[axis] - box.lo[axis]) axis = d;
            s.axis = axis;
            s.a = box.lo[axis];
            s.b = ends[n][axis];
            searchOf[n] = static_cast<int>(searches.size());
            searches.push_back(std::move(s));
        }
        if (searches.empty()) break;

        // Passes until every search of this level has its plane.
        for (int round = 0;; ++round) {
            bool pending = false;
            for (Search& s : searches) {
                if (s.done) continue;
                pending = true;
                if (!s.collect) {
                    s.ResetHistogram();
                } else {
                    s.collected.clear();
                }
            }
            if (!pending) {
                log::Debug("partition: tree level of " + std::to_string(searches.size()) +
                           " splits in " + std::to_string(round) + " passes");
                break;
            }
            HPRAY_CHECK_LT(round, kMaxRounds + 2);
            // After a search's first pass, only its centroids in [a, b) along its axis
            // matter (the others below and above are known): when every search of the
            // round is past its first pass, blocks of centroids outside all those slabs
            // may be left out.
            bool all = false;
            for (int d = 0; d < 3; ++d) slabs[d].clear();
            for (const Search& s : searches) {
                if (s.done) continue;
                if (s.first) all = true;
                slabs[s.axis].push_back({s.a, s.b});
            }
            BlockFilter wanted;
            if (!all) {
                for (auto& list : slabs) {
                    // Sorted and merged into disjoint slabs, so that their ends ascend
                    // too.
                    std::sort(list.begin(), list.end());
                    std::size_t m = 0;
                    for (std::size_t i = 0; i < list.size(); ++i) {
                        if (m > 0 && list[i].first <= list[m - 1].second) {
                            list[m - 1].second =
                                std::max(list[m - 1].second, list[i].second);
                        } else {
                            list[m++] = list[i];
                        }
                    }
                    list.resize(m);
                }
                wanted = [&slabs](const Box& box) {
                    for (int d = 0; d < 3; ++d) {
                        // The first slab ending after box.lo; [box.lo, box.hi] meets it
                        // unless it starts beyond box.hi.
                        const auto& list = slabs[d];
                        const auto it = std::upper_bound(
                            list.begin(), list.end(), box.lo[d],
                            [](double v, const std::pair<double, double>& slab) {
                                return v < slab.second;
                            });
                        if (it != list.end() && it->first <= box.hi[d]) return true;
                    }
                    return false;
                };
            }
            // Each block of points is routed in parallel (its search, or none, and what
            // the search does with it) into records that keep a copy of the point; the
            // sums then run in the points' order, one block after the other, while the
            // next block is read and routed. So the result does not depend on the number
            // of threads.
            tbb::task_group summing;
            struct WaitForSums {
                tbb::task_group& group;
                ~WaitForSums() {
                    try {
                        group.wait();
                    } catch (...) {
                        // Only on the way out of an exception: the first one propagates.
                    }
                }
            } waitForSums{summing};
            int buffer = 0;
            pass(wanted, [&](const WeightedPoint* pts, std::size_t count) {
                std::vector<Routed>& block = routed[buffer];
                buffer ^= 1;
                block.resize(count);
                tbb::parallel_for(
                    tbb::blocked_range<std::size_t>(0, count, 4096),
                    [&](const tbb::blocked_range<std::size_t>& range) {
                        // Neighbouring centroids tend to share a node: the last one found
                        // is tried first.
                        int last = -1;
                        Box in{};
                        for (std::size_t i = range.begin(); i < range.end(); ++i) {
                            const WeightedPoint& p = pts[i];
                            int n = last;
                            if (!(n >= 0 && p.x[0] > in.lo[0] && p.x[0] < in.hi[0] &&
                                  p.x[1] > in.lo[1] && p.x[1] < in.hi[1] &&
                                  p.x[2] > in.lo[2] && p.x[2] < in.hi[2])) {
                                n = 0;
                                while (nodes[n].axis >= 0)
                                    n = GoesLow(nodes[n], p.x) ? nodes[n].low
                                                               : nodes[n].high;
                                last = n;
                                in = interiors[n];
                            }
                            Routed& r = block[i];
                            r.search = -1;
                            const int si = searchOf[n];
                            if (si < 0) continue;
                            const Search& s = searches[si];
                            if (s.done) continue;
                            r.search = si;
                            r.point = p;
                            const double x = p.x[s.axis];
                            if (x < s.a) {
                                r.action = kBelow;
                            } else if (x >= s.b) {
                                r.action = kAbove;
                            } else if (s.collect) {
                                r.action = kCollect;
                            } else {
                                r.action = s.Bin(x);
                            }
                        }
                    });
                summing.wait();  // the block before
                summing.run(
                    [&searches, &block, count] { Sum(searches, block.data(), count); });
            });
            summing.wait();
            for (Search& s : searches) {
                if (s.done) continue;
                const double lo = boxes[s.node].lo[s.axis];
                const double hi = boxes[s.node].hi[s.axis];
                auto finish = [&](double split) {
                    s.split = std::clamp(split, lo, hi);
                    s.done = true;
                };
                // Divides the centroids on the plane x == tieValue by (y, z).
                auto decideTie = [&]() {
                    std::sort(s.tieCollected.begin(), s.tieCollected.end());
                    Best best;
                    double cum = s.tieBelow;
                    bool found = false;
                    std::array<double, 2> key{};
                    for (std::size_t i = 0; i < s.tieCollected.size(); ++i) {
                        const auto& t = s.tieCollected[i];
                        if (i == 0 || t[0] != s.tieCollected[i - 1][0] ||
                            t[1] != s.tieCollected[i - 1][1]) {
                            const double before = best.error;
                            best.Offer(0, cum, s.target);
                            if (best.error < before) {
                                key = {t[0], t[1]};
                                found = true;
                            }
                        }
                        cum += t[2];
                    }
                    if (found && best.error < s.planeError) {
                        s.tieBreak = true;
                        s.tie = key;
                        finish(s.tieValue);
                    } else {
                        finish(s.planeSplit);
                    }
                    std::vector<std::array<double, 3>>().swap(s.tieCollected);
                };
                if (s.first) {
                    s.first = false;
                    s.target = s.total * s.lowLeaves / s.leaves;
                    if (!(s.total > 0)) {  // no cells: halve the box
                        finish(lo + 0.5 * (hi - lo));
                        continue;
                    }
                }
                if (s.collect) {
                    // Exact: candidates between consecutive distinct coordinates.
                    // Sorted by (x, cost, y, z): the sums below see the costs in the order
                    // of sorted (x, cost) pairs.
                    std::sort(s.collected.begin(), s.collected.end());
                    Best best;
                    std::size_t groupBegin = 0, groupEnd = 0;
                    best.Offer(s.a, s.below, s.target);
                    double cum = s.below;
                    bool straddle = false;
                    std::int64_t groupCount = 0;
                    for (std::size_t i = 0; i < s.collected.size(); ++i) {
                        const double before = cum;
                        const double x = s.collected[i][0];
                        std::size_t j = i;
                        while (j < s.collected.size() && s.collected[j][0] == x)
                            cum += s.collected[j++][1];
                        // A group of equal coordinates straddling the target.
                        if (j - i > 1 && before < s.target && cum > s.target) {
                            straddle = true;
                            s.tieValue = x;
                            s.tieBelow = before;
                            groupCount = static_cast<std::int64_t>(j - i);
                            groupBegin = i;
                            groupEnd = j;
                        }
                        const double next =
                            j < s.collected.size() ? s.collected[j][0] : s.b;
                        double mid = x + 0.5 * (next - x);
                        if (!(mid > x && mid <= next)) mid = next;
                        best.Offer(mid, cum, s.target);
                        i = j - 1;
                    }
                    s.collect = false;
                    if (straddle && best.error > 1e-9 * s.total &&
                        groupCount <= static_cast<std::int64_t>(collectLimit)) {
                        s.planeSplit = best.split;
                        s.planeError = best.error;
                        // The centroids on the plane x == tieValue are the group just
                        // collected: (y, z, cost) of each.
                        s.tieCollected.clear();
                        for (std::size_t i = groupBegin; i < groupEnd; ++i)
                            s.tieCollected.push_back(
                                {s.collected[i][2], s.collected[i][3], s.collected[i][1]});
                        std::vector<std::array<double, 4>>().swap(s.collected);
                        decideTie();
                        continue;
                    }
                    std::vector<std::array<double, 4>>().swap(s.collected);
                    finish(best.split);
                    continue;
                }
                // Histogram: the bin where the cumulative cost crosses the target. When
                // that bin's centroids share one coordinate, every narrower interval
                // around it has the same histogram (one bin holding the same sum of the
                // same costs in the same order), so those rounds are decided here without
                // passes over the centroids.
                while (true) {
                    double cum = s.below;
                    int k = 0;
                    for (; k < kBins - 1; ++k) {
                        if (cum + s.binCost[k] >= s.target) break;
                        cum += s.binCost[k];
                    }
                    const double e0 = s.Edge(k), e1 = s.Edge(k + 1);
                    ++s.rounds;
                    if (s.binCount[k] <= static_cast<std::int64_t>(collectLimit)) {
                        s.a = e0;
                        s.b = e1;
                        s.below = cum;
                        s.collect = true;
                        break;
                    }
                    if ((e0 == s.a && e1 == s.b) || s.rounds >= kMaxRounds) {
                        // The interval no longer narrows (many equal coordinates): best
                        // edge.
                        Best best;
                        best.Offer(e0, cum, s.target);
                        best.Offer(e1, cum + s.binCost[k], s.target);
                        finish(best.split);
                        break;
                    }
                    s.a = e0;
                    s.b = e1;
                    s.below = cum;
                    if (!(s.binLo[k] == s.binHi[k])) break;  // the next pass tells
                    const double v = s.binLo[k], cost = s.binCost[k];
                    const std::int64_t count = s.binCount[k];
                    s.ResetHistogram();
                    const int kv = s.Bin(v);
                    s.binCost[kv] = cost;
                    s.binCount[kv] = count;
                    s.binLo[kv] = s.binHi[kv] = v;
                }
            }
        }

        // Create the children of this level.
        std::vector<int> next;
        for (const Search& s : searches) {
            const int n = s.node;
            const int low = static_cast<int>(nodes.size());
            const int high = low + 1;
            KdNode lowNode, highNode;
            Box lowBox = boxes[n], highBox = boxes[n];
            lowBox.hi[s.axis] = s.split;
            highBox.lo[s.axis] = s.split;
            std::array<double, 3> lowEnd = ends[n], highEnd = ends[n];
            // With a tie-break the low child also holds centroids on the plane.
            lowEnd[s.axis] =
                s.tieBreak
                    ? std::nextafter(s.split, std::numeric_limits<double>::infinity())
                    : s.split;
            nodes[n].axis = s.axis;
            nodes[n].split = s.split;
            nodes[n].tieBreak = s.tieBreak;
            nodes[n].tie = s.tie;
            nodes[n].low = low;
            nodes[n].high = high;
            nodes.push_back(lowNode);
            nodes.push_back(highNode);
            boxes.push_back(lowBox);
            boxes.push_back(highBox);
            Box lowInterior = interiors[n], highInterior = interiors[n];
            lowInterior.hi[s.axis] = s.split;
            highInterior.lo[s.axis] = s.split;
            interiors.push_back(lowInterior);
            interiors.push_back(highInterior);
            ends.push_back(lowEnd);
            ends.push_back(highEnd);
            leafCount.push_back(s.lowLeaves);
            leafCount.push_back(s.leaves - s.lowLeaves);
            next.push_back(low);
            next.push_back(high);
        }
        level = std::move(next);
    }
    // Brick numbers: leaves in depth-first order, low side first.
    int brick = 0;
    std::vector<int> stack{0};
    while (!stack.empty()) {
        const int n = stack.back();
        stack.pop_back();
        if (nodes[n].axis < 0) {
            nodes[n].leaf = brick++;
            continue;
        }
        stack.push_back(nodes[n].high);
        stack.push_back(nodes[n].low);
    }
    HPRAY_CHECK_EQ(brick, leaves);
    KdTree tree;
    tree.nodes = std::move(nodes);
    tree.box = root;
    return tree;
}

}  // namespace hpray::partition
