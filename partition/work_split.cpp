// SplitWork (see work_split.h).
#include "work_split.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <utility>

#include "util/check.h"

namespace hpray::partition {

WorkSplit SplitWork(const std::vector<WorkExtent>& items, int count, const Box& root,
                    const std::array<std::vector<double>, 3>& bounds) {
    HPRAY_CHECK_GE(count, 1);
    WorkSplit plan;
    const double inf = std::numeric_limits<double>::infinity();
    std::function<int(Box, std::vector<std::size_t>, int)> build =
        [&](Box box, std::vector<std::size_t> index, int leaves) -> int {
        const int node = static_cast<int>(plan.tree.nodes.size());
        plan.tree.nodes.emplace_back();
        // Whether each extent's stop lies in this box (it is then hidden here).
        std::vector<char> hidden(index.size(), 0);
        double visible = 0;
        for (std::size_t k = 0; k < index.size(); ++k) {
            const WorkExtent& x = items[index[k]];
            bool inside = x.occluded;
            for (int d = 0; d < 3 && inside; ++d)
                inside = x.occluder[d] >= box.lo[d] && x.occluder[d] <= box.hi[d];
            hidden[k] = inside;
            if (!inside) visible += x.weight;
        }
        if (leaves == 1) {
            plan.tree.nodes[node].leaf = static_cast<int>(plan.cost.size());
            plan.cost.push_back(visible);
            return node;
        }
        const int lowLeaves = leaves / 2, highLeaves = leaves - lowLeaves;
        // The best plane of each axis; the axes are tried longest first and a shorter one
        // wins only if it balances strictly better.
        std::array<int, 3> axes{0, 1, 2};
        std::stable_sort(axes.begin(), axes.end(), [&](int p, int q) {
            return box.hi[p] - box.lo[p] > box.hi[q] - box.lo[q];
        });
        int axis = axes[0];
        double split = 0.5 * (box.lo[axis] + box.hi[axis]);
        double best = inf;
        for (int d : axes) {
            if (index.empty()) break;
            const double a = box.lo[d], b = box.hi[d];
            // low(x) = sum of [lo < x] - [qLow < x]; high(x) = [qHigh <= x] - [hi <= x].
            std::vector<std::pair<double, double>> lowOn, lowOff, highOn, highOff;
            std::vector<double> candidates;
            for (std::size_t k = 0; k < index.size(); ++k) {
                const WorkExtent& x = items[index[k]];
                const double qLow = hidden[k] ? x.occluder[d] : inf;
                const double qHigh = hidden[k] ? x.occluder[d] : -inf;
                if (qLow > x.lo[d]) {
                    lowOn.emplace_back(x.lo[d], x.weight);
                    lowOff.emplace_back(qLow, x.weight);
                }
                // An extent flat along the axis (a ray in a plane x = const) lying on the
                // plane goes to the high side.
                const double hiKey =
                    x.lo[d] == x.hi[d] ? std::nextafter(x.hi[d], inf) : x.hi[d];
                if (qHigh < hiKey) {
                    highOn.emplace_back(qHigh, x.weight);
                    highOff.emplace_back(hiKey, x.weight);
                }
                candidates.push_back(x.lo[d]);
                candidates.push_back(x.hi[d]);
                if (hidden[k]) candidates.push_back(x.occluder[d]);
            }
            for (auto* v : {&lowOn, &lowOff, &highOn, &highOff})
                std::sort(v->begin(), v->end());
            // Planes strictly inside the box, and its middle (inside wide pieces).
            candidates.erase(std::remove_if(candidates.begin(), candidates.end(),
                                            [&](double v) { return !(v > a && v < b); }),
                             candidates.end());
            candidates.push_back(0.5 * (a + b));
            std::sort(candidates.begin(), candidates.end());
            candidates.erase(std::unique(candidates.begin(), candidates.end()),
                             candidates.end());
            double low = 0, high = 0;
            std::size_t i0 = 0, i1 = 0, i2 = 0, i3 = 0;
            for (double x : candidates) {
                for (; i0 < lowOn.size() && lowOn[i0].first < x; ++i0)
                    low += lowOn[i0].second;
                for (; i1 < lowOff.size() && lowOff[i1].first < x; ++i1)
                    low -= lowOff[i1].second;
                for (; i2 < highOn.size() && highOn[i2].first <= x; ++i2)
                    high += highOn[i2].second;
                for (; i3 < highOff.size() && highOff[i3].first <= x; ++i3)
                    high -= highOff[i3].second;
                const double objective = std::max(low / lowLeaves, high / highLeaves);
                if (objective < best * (1 - 1e-9)) {
                    best = objective;
                    split = x;
                    axis = d;
                }
            }
        }
        const double a = box.lo[axis], b = box.hi[axis];
        const std::vector<double>& faces = bounds[axis];
        const double tolerance = 1e-9 * (b - a);
        auto near = std::lower_bound(faces.begin(), faces.end(), split - tolerance);
        if (near != faces.end() && *near <= split + tolerance && *near > a && *near < b)
            split = *near;
        std::vector<std::size_t> lowIndex, highIndex;
        for (std::size_t i : index) {
            if (items[i].lo[axis] < split) lowIndex.push_back(i);
            if (items[i].hi[axis] > split ||
                (items[i].hi[axis] == split && items[i].lo[axis] == split))
                highIndex.push_back(i);
        }
        index.clear();
        index.shrink_to_fit();
        Box lowBox = box, highBox = box;
        lowBox.hi[axis] = split;
        highBox.lo[axis] = split;
        plan.tree.nodes[node].axis = axis;
        plan.tree.nodes[node].split = split;
        const int lo = build(lowBox, std::move(lowIndex), lowLeaves);
        const int hi = build(highBox, std::move(highIndex), highLeaves);
        plan.tree.nodes[node].low = lo;
        plan.tree.nodes[node].high = hi;
        return node;
    };
    std::vector<std::size_t> all(items.size());
    for (std::size_t i = 0; i < all.size(); ++i) all[i] = i;
    plan.tree.box = root;
    plan.tree.root = build(root, std::move(all), count);
    plan.boxes = plan.tree.LeafBoxes();
    return plan;
}

}  // namespace hpray::partition
