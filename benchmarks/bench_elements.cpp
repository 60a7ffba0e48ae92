// Element kernels: basis evaluation, field value + world gradient, and inversion rates by
// shape, order and family on curved cells.
#include <benchmark/benchmark.h>

#include <array>
#include <memory>
#include <cmath>
#include <random>
#include <vector>

#include "elements/basis.h"
#include "elements/field.h"
#include "elements/geometry.h"

namespace hpray {
namespace {

// A smoothly curved cell: an affine image of the reference cell plus sines at the nodes.
struct BenchCell {
    const BasisTable* basis = nullptr;
    std::vector<double> nodes;
    std::vector<double> field;
    CellGeometry geometry;
    std::vector<std::array<double, 3>> refs;    // random interior reference points
    std::vector<std::array<double, 3>> worlds;  // their images
};

std::array<double, 3> RandomRef(CellShape shape, std::mt19937_64& rng) {
    std::uniform_real_distribution<double> u(0.0, 1.0);
    for (;;) {
        std::array<double, 3> x{u(rng), u(rng), u(rng)};
        if (RefOutsideDistance(shape, x.data()) <= 0.0) return x;
    }
}

BenchCell MakeCell(CellShape shape, int order, CellFamily family) {
    BenchCell c;
    c.basis = &GetBasis(shape, order, family);
    for (const auto& r : c.basis->refNodes) {
        const double x = 1.3 * r[0] + 0.2 * r[1] + 0.05 * std::sin(2 * r[2] + 1);
        const double y = -0.1 * r[0] + 1.1 * r[1] + 0.05 * std::cos(1.5 * r[0]);
        const double z = 0.1 * r[0] + 0.9 * r[2] + 0.05 * std::sin(2.5 * r[1]);
        c.nodes.insert(c.nodes.end(), {x, y, z});
        c.field.push_back(std::sin(3 * x) * std::cos(2 * y) + 0.5 * std::sin(4 * z + x * y));
    }
    c.geometry = MakeCellGeometry(*c.basis, c.nodes.data());
    std::mt19937_64 rng(1);
    EvalWorkspace ws;
    for (int i = 0; i < 256; ++i) {
        c.refs.push_back(RandomRef(shape, rng));
        std::array<double, 3> w;
        WorldFromRef(c.geometry, c.refs.back().data(), ws, w.data(), nullptr);
        c.worlds.push_back(w);
    }
    return c;
}

void SetLabel(benchmark::State& state, const BasisTable& b) {
    state.SetLabel(std::string(ShapeName(b.shape)) + (b.family == CellFamily::Serendipity
                                                          ? " serendipity"
                                                          : "") +
                   " p" + std::to_string(b.order) + " n=" + std::to_string(b.nodeCount));
}

BenchCell& Cell(const benchmark::State& state) {
    static std::vector<std::unique_ptr<BenchCell>> cache;
    const auto shape = static_cast<CellShape>(state.range(0));
    const int order = static_cast<int>(state.range(1));
    const auto family = static_cast<CellFamily>(state.range(2));
    for (auto& c : cache)
        if (c->basis->shape == shape && c->basis->order == order && c->basis->family == family)
            return *c;
    cache.push_back(std::make_unique<BenchCell>(MakeCell(shape, order, family)));
    return *cache.back();
}

// All basis values and reference gradients at one point.
void BM_EvalBasis(benchmark::State& state) {
    BenchCell& c = Cell(state);
    EvalWorkspace ws;
    std::size_t i = 0;
    for (auto _ : state) {
        EvalBasis(*c.basis, c.refs[i++ & 255].data(), ws.values.data(), ws.dRef.data());
        benchmark::DoNotOptimize(ws.values.data());
        benchmark::ClobberMemory();
    }
    state.SetItemsProcessed(state.iterations());
    SetLabel(state, *c.basis);
}

// Field value and world gradient (basis, contraction, Jacobian, J^-T) at a reference point.
void BM_FieldValueGradient(benchmark::State& state) {
    BenchCell& c = Cell(state);
    EvalWorkspace ws;
    const CellScalar field{c.field.data(), 0.0};
    std::size_t i = 0;
    for (auto _ : state) {
        double v, g[3];
        FieldValueGradient(c.geometry, field, c.refs[i++ & 255].data(), ws, v, g);
        benchmark::DoNotOptimize(v);
        benchmark::DoNotOptimize(g[0]);
    }
    state.SetItemsProcessed(state.iterations());
    SetLabel(state, *c.basis);
}

// World -> reference by damped Newton from the affine guess (curved cells).
void BM_RefFromWorld(benchmark::State& state) {
    BenchCell& c = Cell(state);
    EvalWorkspace ws;
    std::size_t i = 0;
    long iterations = 0;
    for (auto _ : state) {
        const InversionResult r = RefFromWorld(c.geometry, c.worlds[i++ & 255].data(), ws);
        iterations += r.iterations;
        benchmark::DoNotOptimize(r.ref[0]);
    }
    state.SetItemsProcessed(state.iterations());
    state.counters["newton_iters"] =
        static_cast<double>(iterations) / static_cast<double>(state.iterations());
    SetLabel(state, *c.basis);
}

void Sweep(benchmark::internal::Benchmark* b) {
    for (int shape = 0; shape < kNumCellShapes; ++shape)
        for (int p = 1; p <= kMaxOrder; ++p) b->Args({shape, p, 0});
    for (int shape = 1; shape < kNumCellShapes; ++shape) b->Args({shape, 2, 1});
    b->ArgNames({"shape", "p", "family"});
}

BENCHMARK(BM_EvalBasis)->Apply(Sweep);
BENCHMARK(BM_FieldValueGradient)->Apply(Sweep);
BENCHMARK(BM_RefFromWorld)->Apply(Sweep);

}  // namespace
}  // namespace hpray

BENCHMARK_MAIN();
