// Traversal benchmarks: segments per second, build time and bytes per cell of
// BrickTraverser on >= 1M cells, and the raw cost of the alternative Embree designs
// (a BVH over all faces collecting every hit, a BVH over cell boxes) that it was chosen
// against.
#include <benchmark/benchmark.h>
#include <embree3/rtcore.h>

#include <array>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <map>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "io/mesh_io.h"
#include "mesh/builtin.h"
#include "trace/brick_traverser.h"

namespace {

using hpray::Mesh;

const Mesh& GetMesh(const std::string& spec) {
    static std::map<std::string, std::unique_ptr<Mesh>> cache;
    auto& m = cache[spec];
    if (!m) m = std::make_unique<Mesh>(hpray::ReadMesh(spec));
    return *m;
}

const hpray::BrickTraverser& GetTraverser(const std::string& spec) {
    static std::map<std::string, std::unique_ptr<hpray::BrickTraverser>> cache;
    auto& t = cache[spec];
    if (!t) t = std::make_unique<hpray::BrickTraverser>(hpray::Brick::WholeMesh(GetMesh(spec)));
    return *t;
}

// Rays of an orthographic view from a random direction, through the mesh bounds.
std::vector<hpray::Ray> ViewRays(const Mesh& mesh, int n, unsigned seed) {
    const auto b = mesh.Bounds();
    double c[3], r = 0;
    for (int d = 0; d < 3; ++d) {
        c[d] = 0.5 * (b[0][d] + b[1][d]);
        r += 0.25 * (b[1][d] - b[0][d]) * (b[1][d] - b[0][d]);
    }
    r = std::sqrt(r);
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> uni(-1, 1);
    std::vector<hpray::Ray> rays(n);
    for (auto& ray : rays) {
        double dir[3] = {uni(rng), uni(rng), uni(rng)}, len = 0;
        for (double x : dir) len += x * x;
        len = std::sqrt(len);
        for (int d = 0; d < 3; ++d) {
            ray.dir[d] = dir[d] / len;
            ray.origin[d] = c[d] + 0.9 * r * uni(rng) - 3 * r * ray.dir[d];
        }
    }
    return rays;
}

std::string Spec(int index) {
    if (index == 0) return "builtin:cube-tets-60";
    return std::string(HPRAY_SHARED_DATA) + "/mfem_gmsh_t16_tets_1M.vtu";
}

void BM_TraceSegments(benchmark::State& state) {
    const std::string spec = Spec(int(state.range(0)));
    if (state.range(0) != 0 && !std::filesystem::exists(spec)) {
        state.SkipWithError("data file missing");
        return;
    }
    const auto& tr = GetTraverser(spec);
    const auto rays = ViewRays(GetMesh(spec), 4096, 1);
    std::vector<hpray::Segment> segs;
    std::int64_t segments = 0, traced = 0;
    std::size_t i = 0;
    for (auto _ : state) {
        tr.Trace(rays[i++ % rays.size()], 0, INFINITY, segs);
        segments += static_cast<std::int64_t>(segs.size());
        ++traced;
    }
    state.counters["segments/s"] = benchmark::Counter(double(segments), benchmark::Counter::kIsRate);
    state.counters["segments/ray"] = double(segments) / double(traced);
    state.SetLabel(spec);
}
BENCHMARK(BM_TraceSegments)->Arg(0)->Arg(1)->Unit(benchmark::kMicrosecond);

void BM_Build(benchmark::State& state) {
    const std::string spec = Spec(int(state.range(0)));
    if (state.range(0) != 0 && !std::filesystem::exists(spec)) {
        state.SkipWithError("data file missing");
        return;
    }
    const Mesh& mesh = GetMesh(spec);
    hpray::TraverserStats stats;
    for (auto _ : state) {
        hpray::BrickTraverser tr(hpray::Brick::WholeMesh(mesh));
        stats = tr.Stats();
    }
    state.counters["cells"] = double(stats.cells);
    state.counters["build_s"] = stats.buildSeconds;
    state.counters["accel_s"] = stats.accelSeconds;
    state.counters["bytes/cell"] = stats.BytesPerCell();
    state.counters["accel_bytes/cell"] = double(stats.accelBytes) / double(stats.cells);
    state.counters["boundary_faces"] = double(stats.boundaryFaces);
    state.SetLabel(spec);
}
BENCHMARK(BM_Build)->Arg(0)->Arg(1)->Iterations(1)->Unit(benchmark::kSecond);

// ---- Alternatives, measured as lower bounds of their cost (no exact intersection). ----

struct CountContext {
    RTCIntersectContext base;
    std::int64_t hits = 0;
};

// (a) Every face of the tets as an Embree float triangle; a filter collects every hit
// (rejecting it so traversal goes on), i.e. the segments' endpoints without sorting.
void BM_AltAllFacesBvh(benchmark::State& state) {
    const Mesh& mesh = GetMesh(Spec(0));
    RTCDevice device = rtcNewDevice(nullptr);
    std::int64_t bytes = 0;
    rtcSetDeviceMemoryMonitorFunction(
        device,
        [](void* p, ssize_t b, bool) {
            *static_cast<std::int64_t*>(p) += b;
            return true;
        },
        &bytes);
    RTCScene scene = rtcNewScene(device);
    RTCGeometry geom = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
    std::map<std::array<std::int64_t, 3>, int> seen;
    std::vector<std::array<unsigned, 3>> tris;
    for (std::int64_t c = 0; c < mesh.CellCount(); ++c) {
        const std::int64_t* n = mesh.CellNodes(c);
        const int f[4][3] = {{0, 1, 2}, {0, 1, 3}, {0, 2, 3}, {1, 2, 3}};
        for (const auto& t : f) {
            std::array<std::int64_t, 3> k = {n[t[0]], n[t[1]], n[t[2]]};
            std::sort(k.begin(), k.end());
            if (seen.emplace(k, 0).second) tris.push_back({unsigned(k[0]), unsigned(k[1]), unsigned(k[2])});
        }
    }
    float* v = static_cast<float*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0,
                                                           RTC_FORMAT_FLOAT3, 3 * sizeof(float),
                                                           mesh.PointCount()));
    for (std::int64_t i = 0; i < 3 * mesh.PointCount(); ++i) v[i] = float(mesh.points[i]);
    unsigned* idx = static_cast<unsigned*>(rtcSetNewGeometryBuffer(
        geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(unsigned), tris.size()));
    for (std::size_t i = 0; i < tris.size(); ++i)
        for (int k = 0; k < 3; ++k) idx[3 * i + k] = tris[i][k];
    rtcSetGeometryIntersectFilterFunction(geom, [](const RTCFilterFunctionNArguments* args) {
        reinterpret_cast<CountContext*>(args->context)->hits++;
        args->valid[0] = 0;
    });
    rtcCommitGeometry(geom);
    rtcAttachGeometry(scene, geom);
    rtcReleaseGeometry(geom);
    rtcCommitScene(scene);
    const auto rays = ViewRays(mesh, 4096, 1);
    std::int64_t hits = 0;
    std::size_t i = 0;
    for (auto _ : state) {
        const auto& r = rays[i++ % rays.size()];
        CountContext ctx;
        rtcInitIntersectContext(&ctx.base);
        RTCRayHit rh{};
        rh.ray.org_x = float(r.origin[0]);
        rh.ray.org_y = float(r.origin[1]);
        rh.ray.org_z = float(r.origin[2]);
        rh.ray.dir_x = float(r.dir[0]);
        rh.ray.dir_y = float(r.dir[1]);
        rh.ray.dir_z = float(r.dir[2]);
        rh.ray.tfar = INFINITY;
        rh.ray.mask = ~0u;
        rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
        rtcIntersect1(scene, &ctx.base, &rh);
        hits += ctx.hits;
    }
    state.counters["segments/s"] = benchmark::Counter(double(hits), benchmark::Counter::kIsRate);
    state.counters["accel_bytes/cell"] = double(bytes) / double(mesh.CellCount());
    rtcReleaseScene(scene);
    rtcReleaseDevice(device);
}
BENCHMARK(BM_AltAllFacesBvh)->Unit(benchmark::kMicrosecond);

// (b) Cell bounding boxes as Embree user geometry; the callback only counts candidates
// (a real design would intersect every candidate cell exactly and sort).
void BM_AltCellBoxBvh(benchmark::State& state) {
    const Mesh& mesh = GetMesh(Spec(0));
    RTCDevice device = rtcNewDevice(nullptr);
    std::int64_t bytes = 0;
    rtcSetDeviceMemoryMonitorFunction(
        device,
        [](void* p, ssize_t b, bool) {
            *static_cast<std::int64_t*>(p) += b;
            return true;
        },
        &bytes);
    RTCScene scene = rtcNewScene(device);
    RTCGeometry geom = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_USER);
    rtcSetGeometryUserPrimitiveCount(geom, unsigned(mesh.CellCount()));
    rtcSetGeometryUserData(geom, const_cast<Mesh*>(&mesh));
    rtcSetGeometryBoundsFunction(
        geom,
        [](const RTCBoundsFunctionArguments* args) {
            const auto* m = static_cast<const Mesh*>(args->geometryUserPtr);
            float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
            for (int k = 0; k < m->CellNodeCount(args->primID); ++k)
                for (int d = 0; d < 3; ++d) {
                    const float x = float(m->points[3 * m->CellNodes(args->primID)[k] + d]);
                    lo[d] = std::min(lo[d], x);
                    hi[d] = std::max(hi[d], x);
                }
            *args->bounds_o = {lo[0], lo[1], lo[2], 0, hi[0], hi[1], hi[2], 0};
        },
        nullptr);
    rtcSetGeometryIntersectFunction(geom, [](const RTCIntersectFunctionNArguments* args) {
        reinterpret_cast<CountContext*>(args->context)->hits++;
    });
    rtcCommitGeometry(geom);
    rtcAttachGeometry(scene, geom);
    rtcReleaseGeometry(geom);
    rtcCommitScene(scene);
    const auto rays = ViewRays(mesh, 4096, 1);
    std::int64_t hits = 0;
    std::size_t i = 0;
    for (auto _ : state) {
        const auto& r = rays[i++ % rays.size()];
        CountContext ctx;
        rtcInitIntersectContext(&ctx.base);
        RTCRayHit rh{};
        rh.ray.org_x = float(r.origin[0]);
        rh.ray.org_y = float(r.origin[1]);
        rh.ray.org_z = float(r.origin[2]);
        rh.ray.dir_x = float(r.dir[0]);
        rh.ray.dir_y = float(r.dir[1]);
        rh.ray.dir_z = float(r.dir[2]);
        rh.ray.tfar = INFINITY;
        rh.ray.mask = ~0u;
        rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
        rtcIntersect1(scene, &ctx.base, &rh);
        hits += ctx.hits;
    }
    state.counters["candidates/s"] = benchmark::Counter(double(hits), benchmark::Counter::kIsRate);
    state.counters["accel_bytes/cell"] = double(bytes) / double(mesh.CellCount());
    rtcReleaseScene(scene);
    rtcReleaseDevice(device);
}
BENCHMARK(BM_AltCellBoxBvh)->Unit(benchmark::kMicrosecond);

}  // namespace

BENCHMARK_MAIN();
