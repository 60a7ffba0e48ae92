// The cost of render progress (scripts/bench_progress.sh): what RenderTiles
// (src/render/brick_renderer.cpp) does after every tile, and one progress line through
// log::Progress. Run with stderr where a render's goes: a pipe (a line per call) or a
// terminal (the line rewritten in place); the script runs both.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>

#include "util/log.h"

namespace hpray {
namespace {

using Clock = std::chrono::steady_clock;

// After each tile, with no line due (every tile but the few that print): the tile
// counter, the clock, the due time. The same operations as RenderTiles' `report`.
void BM_TileReportNoLineDue(benchmark::State& state) {
    const auto started = Clock::now();
    std::atomic<int> tilesDone{0};
    std::atomic<double> nextReport{1e9};
    const double interval = 5.0;
    int printed = 0;
    for (auto _ : state) {
        const int done = ++tilesDone;
        const double elapsed = std::chrono::duration<double>(Clock::now() - started).count();
        double due = nextReport.load();
        if (elapsed < due || !nextReport.compare_exchange_strong(due, elapsed + interval))
            continue;
        printed += done;  // never reached: no line is due
    }
    benchmark::DoNotOptimize(printed);
}
BENCHMARK(BM_TileReportNoLineDue);

// One progress line as RenderTiles prints it: the text formatted, then log::Progress
// (a whole line on a pipe; on a terminal the line rewritten in place).
void BM_ProgressLine(benchmark::State& state) {
    const auto started = Clock::now();
    int done = 0;
    for (auto _ : state) {
        ++done;
        const double elapsed =
            std::max(1e-3, std::chrono::duration<double>(Clock::now() - started).count());
        const double share = 0.5;
        char text[200];
        std::snprintf(text, sizeof text,
                      "rendering %dx%d: %.0f%% of the tiles after %.1f s (%.0f tiles/s), "
                      "about %.0f s left",
                      1024, 1024, 100 * share, elapsed, done / elapsed,
                      elapsed * (1 - share) / share);
        log::Progress(text);
    }
    log::EndProgress();
    state.counters["terminal"] = log::ProgressOnTerminal() ? 1 : 0;
}
BENCHMARK(BM_ProgressLine);

}  // namespace
}  // namespace hpray

BENCHMARK_MAIN();
