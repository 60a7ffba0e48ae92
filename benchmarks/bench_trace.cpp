// Traversal benchmarks: segments per second, build time and bytes per cell of
// BrickTraverser on >= 1M cells and on curved quadratic tets and hexes (with the same
// quadratic tets straight for comparison), and the raw cost of the alternative Embree
// designs (a BVH over all faces collecting every hit, a BVH over cell boxes) that it was
// chosen against.
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

// Quadratic hexes on an n^3 grid of [0,1]^3 with nodes mapped by z -> z + x^2 + y^2:
// curved faces that the cells represent exactly (the paraboloid slab of tests/trace).
Mesh ParaboloidHexes(int n) {
    const int p = 2, g = n * p + 1;
    Mesh mesh;
    for (int k = 0; k < g; ++k)
        for (int j = 0; j < g; ++j)
            for (int i = 0; i < g; ++i) {
                const double x = double(i) / (g - 1), y = double(j) / (g - 1);
                const double z = double(k) / (g - 1);
                mesh.points.insert(mesh.points.end(), {x, y, z + x * x + y * y});
            }
    std::vector<std::int64_t> nodes;
    for (int c = 0; c < n; ++c)
        for (int b = 0; b < n; ++b)
            for (int a = 0; a < n; ++a) {
                nodes.clear();
                for (int k = 0; k <= p; ++k)
                    for (int j = 0; j <= p; ++j)
                        for (int i = 0; i <= p; ++i)
                            nodes.push_back((a * p + i) +
                                            g * ((b * p + j) + g * (c * p + k)));
                mesh.AddCell(hpray::CellShape::Hex, p, hpray::CellFamily::Lagrange,
                             nodes.data(), int(nodes.size()));
            }
    return mesh;
}

// Meshes by name: "paraboloid-tets" (builtin ball-p2?n=24, 69120 quadratic tets, nodes
// mapped by z -> (z - 1) / 2 + x^2 + y^2, every face curved but the vertical ones),
// "paraboloid-hexes" (ParaboloidHexes(40), 64000 cells), else a file or builtin spec.
const Mesh& GetMesh(const std::string& spec) {
    static std::map<std::string, std::unique_ptr<Mesh>> cache;
    auto& m = cache[spec];
    if (m) return *m;
    if (spec == "paraboloid-tets") {
        m = std::make_unique<Mesh>(hpray::MakeBuiltin("builtin:ball-p2?n=24"));
        for (std::int64_t i = 0; i < m->PointCount(); ++i) {
            double* x = &m->points[3 * i];
            x[2] = 0.5 * (x[2] - 1) + x[0] * x[0] + x[1] * x[1];
        }
    } else if (spec == "paraboloid-hexes") {
        m = std::make_unique<Mesh>(ParaboloidHexes(40));
    } else {
        m = std::make_unique<Mesh>(hpray::ReadMesh(spec));
    }
    return *m;
}

const hpray::BrickTraverser& GetTraverser(const std::string& spec) {
    static std::map<std::string, std::unique_ptr<hpray::BrickTraverser>> cache;
    auto& t = cache[spec];
    if (!t)
        t = std::make_unique<hpray::BrickTraverser>(
            hpray::Brick::WholeMesh(GetMesh(spec)));
    return *t;
}

// Rays of an orthographic view from a random direction, through the mesh bounds.
std::vector<hpray::Ray> ViewRays(const Mesh& mesh, int n, unsigned seed) {
    const auto b = mesh.Bounds();
    double c[3], r = 0;
    for (int d = 0; d < 3; ++d) {
        c[d] = 0.5 * (b.lo[d] + b.hi[d]);
        r += 0.25 * (b.hi[d] - b.lo[d]) * (b.hi[d] - b.lo[d]);
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

// 0, 1: straight tets (>= 1M cells); 2: the same quadratic tets as 3 but straight;
// 3, 4: curved quadratic tets and hexes.
std::string Spec(int index) {
    switch (index) {
        case 0:
            return "builtin:cube-tets-60";
        case 2:
            return "builtin:ball-p2?n=24";
        case 3:
            return "paraboloid-tets";
        case 4:
            return "paraboloid-hexes";
        default:
            return std::string(HPRAY_SHARED_DATA) + "/mfem_gmsh_t16_tets_1M.vtu";
    }
}

void BM_TraceSegments(benchmark::State& state) {
    const std::string spec = Spec(int(state.range(0)));
    if (state.range(0) == 1 && !std::filesystem::exists(spec)) {
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
    state.counters["segments/s"] =
        benchmark::Counter(double(segments), benchmark::Counter::kIsRate);
    state.counters["segments/ray"] = double(segments) / double(traced);
    state.SetLabel(spec);
}
BENCHMARK(BM_TraceSegments)->DenseRange(0, 4)->Unit(benchmark::kMicrosecond);

void BM_Build(benchmark::State& state) {
    const std::string spec = Spec(int(state.range(0)));
    if (state.range(0) == 1 && !std::filesystem::exists(spec)) {
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
    state.counters["curved_faces"] = double(stats.curvedFaces);
    state.SetLabel(spec);
}
BENCHMARK(BM_Build)->DenseRange(0, 4)->Iterations(1)->Unit(benchmark::kSecond);

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
            if (seen.emplace(k, 0).second)
                tris.push_back({unsigned(k[0]), unsigned(k[1]), unsigned(k[2])});
        }
    }
    float* v = static_cast<float*>(
        rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                3 * sizeof(float), mesh.PointCount()));
    for (std::int64_t i = 0; i < 3 * mesh.PointCount(); ++i) v[i] = float(mesh.points[i]);
    unsigned* idx = static_cast<unsigned*>(
        rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                3 * sizeof(unsigned), tris.size()));
    for (std::size_t i = 0; i < tris.size(); ++i)
        for (int k = 0; k < 3; ++k) idx[3 * i + k] = tris[i][k];
    rtcSetGeometryIntersectFilterFunction(
        geom, [](const RTCFilterFunctionNArguments* args) {
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
    state.counters["segments/s"] =
        benchmark::Counter(double(hits), benchmark::Counter::kIsRate);
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
            float lo[3] = {INFINITY, INFINITY, INFINITY},
                  hi[3] = {-INFINITY, -INFINITY, -INFINITY};
            for (int k = 0; k < m->CellNodeCount(args->primID); ++k)
                for (int d = 0; d < 3; ++d) {
                    const float x =
                        float(m->points[3 * m->CellNodes(args->primID)[k] + d]);
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
    state.counters["candidates/s"] =
        benchmark::Counter(double(hits), benchmark::Counter::kIsRate);
    state.counters["accel_bytes/cell"] = double(bytes) / double(mesh.CellCount());
    rtcReleaseScene(scene);
    rtcReleaseDevice(device);
}
BENCHMARK(BM_AltCellBoxBvh)->Unit(benchmark::kMicrosecond);

}  // namespace

BENCHMARK_MAIN();
