// Isosurface rendering against analytic ray-surface intersections: spheres of ball-p2,
// planes of linear fields on p = 10 tets, planes of isoparametric fields on highly curved
// hexes, offset and near-constant fields, tangent rays, compositing and thread invariance.
#include <gtest/gtest.h>

#include <cmath>
#include <algorithm>
#include <cstring>
#include <optional>
#include <random>

#include "mesh/builtin.h"
#include "render/brick_renderer.h"
#include "render/render_job.h"
#include "scene/camera.h"
#include "scene/scene.h"
#include "trace/trace_test_meshes.h"

namespace hpray {
namespace {

Scene MakeScene(const std::string& yaml) { return ParseScene(yaml, "test.yaml", {}, ""); }

struct Hit {
    double t;
    std::array<double, 3> normal;  // unit, facing the camera
};

// Nearest intersection of a ray with the sphere |x| = R, if the ray is not within `tangent`
// (relative) of grazing it; `grazing` reports rays too close to call.
std::optional<Hit> RaySphere(const CameraRay& ray, double R, bool& grazing) {
    const auto& o = ray.origin;
    const auto& d = ray.direction;
    const double b = o[0] * d[0] + o[1] * d[1] + o[2] * d[2];
    const double c = o[0] * o[0] + o[1] * o[1] + o[2] * o[2] - R * R;
    const double disc = b * b - c;
    grazing = std::abs(disc) <= 1e-9 * R * R;
    if (disc < 0) return std::nullopt;
    const double t = -b - std::sqrt(disc);
    if (t < 0) return std::nullopt;
    Hit h;
    h.t = t;
    for (int i = 0; i < 3; ++i) h.normal[i] = (o[i] + t * d[i]) / R;
    return h;
}

// zTol is the bound for well-conditioned pixels; `dataError` (the absolute error of the
// field data) adds its conditioning dataError / |df/dt|, with df/dt = 2 R (n . d).
void ExpectSphereImage(const Scene& scene, const Mesh& mesh, double R, double zTol,
                       double nTol, double dataError = 0) {
    RenderStats stats;
    const Image image = RenderMeshJob(mesh, scene, stats);
    const Camera camera(scene.camera);
    int hits = 0, graze = 0;
    for (int j = 0; j < image.height; ++j)
        for (int i = 0; i < image.width; ++i) {
            const std::size_t p = std::size_t(j) * image.width + i;
            bool grazing = false;
            const auto expect = RaySphere(camera.PixelRay(i, j), R, grazing);
            if (grazing) {
                ++graze;
                continue;
            }
            ASSERT_EQ(expect.has_value(), std::isfinite(image.z[p])) << i << "," << j;
            if (!expect) {
                EXPECT_EQ(image.isoId[p], -1);
                EXPECT_EQ(image.a[p], 0.0);
                continue;
            }
            ++hits;
            const CameraRay ray = camera.PixelRay(i, j);
            double nd = 0;
            for (int a = 0; a < 3; ++a) nd += expect->normal[a] * ray.direction[a];
            const double conditioning = 4 * dataError / (2 * R * std::abs(nd));
            EXPECT_NEAR(image.z[p], expect->t, zTol + conditioning) << i << "," << j;
            EXPECT_NEAR(image.nx[p], expect->normal[0], nTol) << i << "," << j;
            EXPECT_NEAR(image.ny[p], expect->normal[1], nTol) << i << "," << j;
            EXPECT_NEAR(image.nz[p], expect->normal[2], nTol) << i << "," << j;
            EXPECT_EQ(image.isoId[p], 0);
            EXPECT_EQ(image.a[p], 1.0);
        }
    EXPECT_GT(hits, image.width * image.height / 20);
    EXPECT_LT(graze, image.width);
    EXPECT_EQ(stats.counters.rootFailures, 0);
    EXPECT_EQ(stats.counters.inversionFailures, 0);
}

const char* kBallScene = R"(
data: {mesh: "builtin:ball-p2"}
camera: {position: [2.1, 1.3, 2.9], look_at: [0.01, -0.02, 0.03], up: [0, 1, 0], fov_y: 40,
         width: 72, height: 64}
isosurfaces:
  - {field: u, value: 0.49}
)";

TEST(IsoRender, BallP2SpheresMatchAnalyticIntersection) {
    const Mesh mesh = MakeBuiltin("builtin:ball-p2");
    // Scene size ~ 2 (the cube [-1,1]^3): Z within 1e-10 of it, normals within 1e-9.
    ExpectSphereImage(MakeScene(kBallScene), mesh, 0.7, 2e-10, 1e-9);
    // R = 0.5 passes through mesh nodes, edges and faces: isovalue equal to nodal values.
    Scene scene = MakeScene(kBallScene);
    scene.isosurfaces[0].value = 0.25;
    ExpectSphereImage(scene, mesh, 0.5, 2e-10, 1e-9);
}

TEST(IsoRender, OffsetAndNearConstantFields) {
    Mesh offset = MakeBuiltin("builtin:ball-p2");
    for (double& u : offset.pointFields[0].values) u += 1e6;
    Scene scene = MakeScene(kBallScene);
    scene.isosurfaces[0].value = 1e6 + 0.49;
    // The data carries half an ulp of 1e6 (5.8e-11) of rounding, times the Lebesgue
    // constant of the P2 interpolant (< 2): t is known to that over |df/dt|.
    ExpectSphereImage(scene, offset, 0.7, 2e-10, 1e-5, 1.2e-10);

    Mesh tiny = MakeBuiltin("builtin:ball-p2");
    for (double& u : tiny.pointFields[0].values) u *= 1e-12;  // |grad u| ~ 1e-12
    scene.isosurfaces[0].value = 0.49e-12;
    ExpectSphereImage(scene, tiny, 0.7, 2e-10, 1e-9);
}

// The plane x + 2y + 3z = C through the unit cube, on order-10 tets (line degree 10).
TEST(IsoRender, OrderTenTetsGiveTheExactPlane) {
    const Mesh mesh = MakeBuiltin("builtin:cube-tets-2?order=10");
    Scene scene = MakeScene(R"(
data: {mesh: "builtin:cube-tets-2?order=10"}
camera: {position: [2.5, 1.9, 3.1], look_at: [0.5, 0.5, 0.5], up: [0, 1, 0], fov_y: 35,
         width: 48, height: 48}
isosurfaces:
  - {field: u, value: 2.5, opacity: 0.5}
)");
    RenderStats stats;
    const Image image = RenderMeshJob(mesh, scene, stats);
    const Camera camera(scene.camera);
    const double n[3] = {1 / std::sqrt(14.0), 2 / std::sqrt(14.0), 3 / std::sqrt(14.0)};
    int hits = 0;
    for (int j = 0; j < 48; ++j)
        for (int i = 0; i < 48; ++i) {
            const CameraRay r = camera.PixelRay(i, j);
            const double dn = r.direction[0] + 2 * r.direction[1] + 3 * r.direction[2];
            const double t = (2.5 - r.origin[0] - 2 * r.origin[1] - 3 * r.origin[2]) / dn;
            std::array<double, 3> x;
            for (int d = 0; d < 3; ++d) x[d] = r.origin[d] + t * r.direction[d];
            const double inside = std::min({x[0], x[1], x[2], 1 - x[0], 1 - x[1], 1 - x[2]});
            const std::size_t p = std::size_t(j) * 48 + i;
            if (std::abs(inside) < 1e-9) continue;  // grazing the cube's boundary
            ASSERT_EQ(inside > 0, std::isfinite(image.z[p])) << i << "," << j;
            if (inside < 0) continue;
            ++hits;
            EXPECT_NEAR(image.z[p], t, 1e-10);
            // Facing the camera: the normal points against the ray.
            const double s = dn > 0 ? -1 : 1;
            EXPECT_NEAR(image.nx[p], s * n[0], 1e-9);
            EXPECT_NEAR(image.ny[p], s * n[1], 1e-9);
            EXPECT_NEAR(image.nz[p], s * n[2], 1e-9);
            // Exactly one hit: opacity 0.5 composited once, never twice.
            EXPECT_EQ(image.a[p], 0.5) << i << "," << j;
        }
    EXPECT_GT(hits, 300);
}

// The isosurface u = 1 of u = x + 2y + 3z on cube-tets-3 passes through mesh vertices
// ((1,0,0), (1/3,1/3,0), ...), edges and faces: no holes and no double hits.
TEST(IsoRender, PlaneThroughVerticesEdgesAndFacesHasNoHolesOrDoubleHits) {
    const Mesh mesh = MakeBuiltin("builtin:cube-tets-3");
    Scene scene = MakeScene(R"(
data: {mesh: "builtin:cube-tets-3"}
camera: {position: [0.1, 0.2, 3.0], look_at: [0.3, 0.2, 0.1], up: [0, 1, 0],
         ortho_height: 1.3, width: 64, height: 64}
isosurfaces:
  - {field: u, value: 1.0, opacity: 0.5}
)");
    RenderStats stats;
    const Image image = RenderMeshJob(mesh, scene, stats);
    const Camera camera(scene.camera);
    int hits = 0;
    for (int j = 0; j < 64; ++j)
        for (int i = 0; i < 64; ++i) {
            const CameraRay r = camera.PixelRay(i, j);
            const double dn = r.direction[0] + 2 * r.direction[1] + 3 * r.direction[2];
            const double t = (1.0 - r.origin[0] - 2 * r.origin[1] - 3 * r.origin[2]) / dn;
            std::array<double, 3> x;
            for (int d = 0; d < 3; ++d) x[d] = r.origin[d] + t * r.direction[d];
            const double inside = std::min({x[0], x[1], x[2], 1 - x[0], 1 - x[1], 1 - x[2]});
            if (std::abs(inside) < 1e-12) continue;
            const std::size_t p = std::size_t(j) * 64 + i;
            ASSERT_EQ(inside > 0, std::isfinite(image.z[p])) << i << "," << j;
            if (inside > 0) {
                ++hits;
                EXPECT_NEAR(image.z[p], t, 1e-12);
                EXPECT_EQ(image.a[p], 0.5) << i << "," << j;
            }
        }
    EXPECT_GT(hits, 500);
}

// A field that is the world x coordinate of an isoparametric, strongly curved hex mesh is
// exactly x, whatever the curvature: its isosurface is the plane x = C.
TEST(IsoRender, HighlyCurvedHexesGiveTheExactPlaneOfAnIsoparametricField) {
    const Mesh mesh = testing::CurvedHexesWithFieldX(0.08, 4);
    Scene scene = MakeScene(R"(
data: {mesh: "builtin:nk-sinc"}
camera: {position: [2.6, 1.7, 2.2], look_at: [0.5, 0.5, 0.5], up: [0, 1, 0], fov_y: 32,
         width: 40, height: 40}
isosurfaces:
  - {field: u, value: 0.37}
)");
    RenderStats stats;
    const Image image = RenderMeshJob(mesh, scene, stats);
    const Camera camera(scene.camera);
    int hits = 0;
    for (int j = 0; j < 40; ++j)
        for (int i = 0; i < 40; ++i) {
            const CameraRay r = camera.PixelRay(i, j);
            const double t = (0.37 - r.origin[0]) / r.direction[0];
            std::array<double, 3> x;
            for (int d = 0; d < 3; ++d) x[d] = r.origin[d] + t * r.direction[d];
            // The domain stays the unit cube: the displacement vanishes on its boundary.
            const double inside = std::min({x[1], x[2], 1 - x[1], 1 - x[2]});
            if (std::abs(inside) < 1e-9) continue;
            const std::size_t p = std::size_t(j) * 40 + i;
            ASSERT_EQ(inside > 0, std::isfinite(image.z[p])) << i << "," << j;
            if (inside < 0) continue;
            ++hits;
            EXPECT_NEAR(image.z[p], t, 1e-10) << i << "," << j;
            EXPECT_NEAR(std::abs(image.nx[p]), 1.0, 1e-9) << i << "," << j;
            EXPECT_LE(image.isoResidual[p], 1e-12);
        }
    EXPECT_GT(hits, 200);
    EXPECT_EQ(stats.counters.inversionFailures, 0);
    EXPECT_GT(stats.counters.inversions, 0);  // the cells really are curved
}

TEST(IsoRender, TangentAndNearTangentRays) {
    const Mesh mesh = MakeBuiltin("builtin:ball-p2");
    const Scene scene = MakeScene(kBallScene);
    const MeshGeometry geometry = MeshGeometry::Build(mesh);
    const BrickTraverser traverser(Brick::WholeMesh(mesh));
    Scene s = scene;
    s.isosurfaces[0].value = 0.25;  // R = 0.5
    const BrickSetup setup = MakeBrickSetup(mesh, geometry, traverser, s);
    RenderCounters counters;
    Pixel sample;
    // Tangent to the sphere at (0, 0.5, 0), a mesh vertex: a double root at t = 2.
    Ray ray;
    ray.origin[0] = -2;
    ray.origin[1] = 0.5;
    ray.dir[0] = 1;
    ray.dir[2] = 0;
    IntegrateRay(setup, ray, sample, counters);
    EXPECT_NEAR(sample.z, 2.0, 1e-6);  // a double root is determined to ~sqrt(eps)
    EXPECT_LE(sample.isoResidual, 1e-14);
    // Tangent inside a face of the grid (z = 0.25 is not a grid plane): at (0.1, 0.4, 0.25)?
    // Use y offset: passing 1e-6 outside misses, 1e-6 inside hits at the analytic chord.
    ray.origin[1] = 0.5 + 1e-6;
    IntegrateRay(setup, ray, sample, counters);
    EXPECT_EQ(sample.isoId, -1);
    ray.origin[1] = 0.5 - 1e-6;
    IntegrateRay(setup, ray, sample, counters);
    ASSERT_EQ(sample.isoId, 0);
    const double y = 0.5 - 1e-6;
    EXPECT_NEAR(sample.z, 2.0 - std::sqrt(0.25 - y * y), 1e-10);
}

TEST(IsoRender, NestedTransparentSpheresCompositeInDepthOrder) {
    const Mesh mesh = MakeBuiltin("builtin:ball-p2");
    Scene scene = MakeScene(R"(
data: {mesh: "builtin:ball-p2"}
camera: {position: [0.05, 0.03, 3.0], look_at: [0, 0, 0], up: [0, 1, 0], fov_y: 40,
         width: 40, height: 40}
isosurfaces:
  - {field: u, value: 0.25, color: [1, 0, 0], opacity: 0.5}
  - {field: u, value: 0.64, color: [0, 0, 1], opacity: 0.4}
lighting: {ambient: 0.2, diffuse: 0.7, specular: 0.0, shininess: 8}
)");
    RenderStats stats;
    const Image image = RenderMeshJob(mesh, scene, stats);
    const Camera camera(scene.camera);
    for (int j = 0; j < 40; ++j)
        for (int i = 0; i < 40; ++i) {
            const CameraRay r = camera.PixelRay(i, j);
            // Every crossing of the two spheres along the ray, in depth order.
            struct Crossing {
                double t;
                int id;
                double nl;
            };
            std::vector<Crossing> xs;
            bool grazing = false;
            for (int k = 0; k < 2; ++k) {
                const double R = k == 0 ? 0.5 : 0.8;
                const auto& o = r.origin;
                const auto& d = r.direction;
                const double b = o[0] * d[0] + o[1] * d[1] + o[2] * d[2];
                const double c = o[0] * o[0] + o[1] * o[1] + o[2] * o[2] - R * R;
                const double disc = b * b - c;
                grazing |= std::abs(disc) < 1e-6;
                if (disc <= 0) continue;
                for (double t : {-b - std::sqrt(disc), -b + std::sqrt(disc)}) {
                    double nd = 0;
                    for (int a = 0; a < 3; ++a) nd += (o[a] + t * d[a]) / R * d[a];
                    xs.push_back({t, k, std::abs(nd)});
                }
            }
            if (grazing) continue;
            std::sort(xs.begin(), xs.end(), [](auto& a, auto& b) { return a.t < b.t; });
            double T = 1, rgb[3] = {0, 0, 0};
            for (const auto& x : xs) {
                const double alpha = x.id == 0 ? 0.5 : 0.4;
                const double color[3] = {x.id == 0 ? 1.0 : 0.0, 0.0, x.id == 0 ? 0.0 : 1.0};
                for (int c = 0; c < 3; ++c) rgb[c] += T * alpha * std::min(1.0, color[c] * (0.2 + 0.7 * x.nl));
                T *= 1 - alpha;
            }
            const std::size_t p = std::size_t(j) * 40 + i;
            EXPECT_NEAR(image.a[p], 1 - T, 1e-14) << i << "," << j;
            EXPECT_NEAR(image.r[p], rgb[0], 1e-9) << i << "," << j;
            EXPECT_NEAR(image.b[p], rgb[2], 1e-9) << i << "," << j;
            if (!xs.empty()) {
                EXPECT_EQ(image.isoId[p], xs.front().id);
            }
        }
}

bool SameBits(const std::vector<double>& a, const std::vector<double>& b) {
    return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(double)) == 0;
}

TEST(IsoRender, OneAndTwoThreadsGiveBitIdenticalImages) {
    const Mesh mesh = MakeBuiltin("builtin:nk-sinc");
    Scene scene = MakeScene(R"(
data: {mesh: "builtin:nk-sinc"}
camera: {position: [2.2, 1.6, 2.6], look_at: [0.5, 0.5, 0.5], up: [0, 1, 0], fov_y: 30,
         width: 48, height: 40}
isosurfaces:
  - {field: u, value: 0.0, opacity: 0.7}
  - {field: u, value: 0.3, opacity: 0.6}
)");
    RenderStats s1, s2;
    scene.threads = 1;
    const Image one = RenderMeshJob(mesh, scene, s1);
    scene.threads = 2;
    const Image two = RenderMeshJob(mesh, scene, s2);
    const auto a = one.Channels();
    const auto b = two.Channels();
    ASSERT_EQ(a.size(), b.size());
    for (std::size_t c = 0; c < a.size(); ++c) EXPECT_TRUE(SameBits(*a[c].second, *b[c].second)) << a[c].first;
    EXPECT_EQ(s1.counters.isoHits, s2.counters.isoHits);
}

// Splitting the pixels between ranks: tiles rendered in chunks of any size and in any
// order (here random chunks, last first) fill the same image bit for bit as one render,
// touch no pixel outside their tiles, and their counters add up to the whole render's.
TEST(IsoRender, TilesInAnyGroupingGiveTheSameImage) {
    const Mesh mesh = MakeBuiltin("builtin:nk-sinc?order=4");
    Scene scene = MakeScene(R"(
data: {mesh: "builtin:nk-sinc?order=4"}
camera: {position: [2.2, 1.6, 2.6], look_at: [0.5, 0.5, 0.5], up: [0, 1, 0], fov_y: 30,
         width: 70, height: 45}
isosurfaces:
  - {field: u, value: 0.0, opacity: 0.7}
volume: {color_field: u, extinction_field: u, color_tf: [[-1.6, 0, 0, 1], [1.1, 1, 0, 0]],
         extinction_tf: [[-1.6, 0.5], [1.1, 2]]}
)");
    scene.threads = 2;
    RenderStats wholeStats = StartStats(scene), tileStats = StartStats(scene);
    PreparedBrick brick(mesh, std::nullopt, scene, wholeStats);
    const Camera camera(scene.camera);
    Image whole;
    brick.Render(scene, camera, std::nullopt, whole, wholeStats);
    const int tiles = RenderTileCount(camera);
    ASSERT_EQ(tiles, 5 * 3);  // 16-pixel tiles, partial ones at the right and bottom edges
    std::mt19937 rng(7);
    std::vector<std::pair<int, int>> chunks;
    for (int t = 0; t < tiles;) {
        const int n = 1 + static_cast<int>(rng() % 4);
        chunks.push_back({t, std::min(tiles, t + n)});
        t += n;
    }
    std::reverse(chunks.begin(), chunks.end());
    Image tiled;
    tiled.Resize(camera.Width(), camera.Height());
    for (std::size_t k = 0; k < chunks.size(); ++k) {
        brick.RenderTiles(scene, camera, chunks[k].first, chunks[k].second, tiled, tileStats);
        if (k == 0) {
            // Only the chunk's own pixels are written: the first pixel of the image (tile 0)
            // is still empty after the last chunk.
            EXPECT_EQ(tiled.a[0], 0.0);
            EXPECT_TRUE(std::isinf(tiled.z[0]));
        }
    }
    const auto a = whole.Channels();
    const auto b = tiled.Channels();
    ASSERT_EQ(a.size(), b.size());
    for (std::size_t c = 0; c < a.size(); ++c)
        EXPECT_TRUE(SameBits(*a[c].second, *b[c].second)) << a[c].first;
    EXPECT_GT(wholeStats.counters.isoHits, 100);
    EXPECT_EQ(wholeStats.counters.rays, tileStats.counters.rays);
    EXPECT_EQ(wholeStats.counters.rays, 70.0 * 45.0);
    EXPECT_EQ(wholeStats.counters.isoHits, tileStats.counters.isoHits);
    EXPECT_EQ(wholeStats.counters.segments, tileStats.counters.segments);
}

// Nelson & Kirby's examples at default accuracy: the residual on the true field at every
// hit is at the rounding level of the data (done-when: RMS <= 1e-12, max <= 1e-10 of the
// field range).
TEST(IsoRender, NelsonKirbyExamplesResidualBudget) {
    for (const char* name : {"builtin:nk-sinc", "builtin:nk-quartic"}) {
        const Mesh mesh = MakeBuiltin(name);
        Scene scene = MakeScene(std::string("data: {mesh: \"") + name + R"("}
camera: {position: [2.2, 1.6, 2.6], look_at: [0.5, 0.5, 0.5], up: [0, 1, 0], fov_y: 30,
         width: 40, height: 40}
isosurfaces:
  - {field: u, value: 0.0}
)");
        if (std::string(name) == "builtin:nk-quartic") scene.isosurfaces[0].value = -0.00716511;
        RenderStats stats;
        RenderMeshJob(mesh, scene, stats);
        const double range = stats.isoFieldRange[1] - stats.isoFieldRange[0];
        ASSERT_GT(stats.counters.isoHits, 200) << name;
        const double rms = std::sqrt(stats.counters.isoResidualSqSum / stats.counters.isoHits);
        EXPECT_LE(rms / range, 1e-12) << name;
        EXPECT_LE(stats.counters.isoResidualMax / range, 1e-10) << name;
        EXPECT_EQ(stats.counters.rootFailures, 0) << name;
    }
}

}  // namespace
}  // namespace hpray

namespace hpray {
namespace {

// Rays aimed exactly at points of the isosurface that lie on mesh faces, edges and
// vertices: each must composite the semi-transparent surface exactly once.
TEST(IsoRender, RaysThroughVerticesEdgesAndFacesOnTheSurfaceHitOnce) {
    const Mesh mesh = MakeBuiltin("builtin:cube-tets-3");
    Scene scene = MakeScene(R"(
data: {mesh: "builtin:cube-tets-3"}
isosurfaces:
  - {field: u, value: 1.0, opacity: 0.5}
)");
    const MeshGeometry geometry = MeshGeometry::Build(mesh);
    const BrickTraverser traverser(Brick::WholeMesh(mesh));
    const BrickSetup setup = MakeBrickSetup(mesh, geometry, traverser, scene);
    // Points with x + 2y + 3z = 1 on grid planes (cube faces), grid lines (edges) and
    // grid points (vertices) of the 3^3 cube grid.
    std::vector<std::array<double, 3>> targets = {
        {1.0 / 3, 1.0 / 3, 0.0}, {1.0, 0.0, 0.0}, {0.0, 1.0 / 3, 1.0 / 9},  // vertex, vertex, face
        {1.0 / 3, 0.1, (2.0 / 3 - 0.2) / 3},                               // on x = 1/3
        {0.2, 1.0 / 3, (0.8 - 2.0 / 3) / 3},                               // on y = 1/3
        {1.0 / 3, 1.0 / 3, 0.0},                                           // edge and vertex
        {2.0 / 3, 0.0, 1.0 / 9},                                           // on y = 0 edge
        {0.1, 0.0, 0.3},                                                    // boundary face
    };
    RenderCounters counters;
    Pixel sample;
    int checked = 0;
    for (std::size_t k = 0; k < targets.size(); ++k)
        for (int trial = 0; trial < 200; ++trial) {
            std::mt19937 rng(1000 * k + trial);
            std::normal_distribution<double> g;
            double d[3] = {g(rng), g(rng), g(rng)};
            const double n = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
            Ray ray;
            for (int a = 0; a < 3; ++a) {
                ray.dir[a] = d[a] / n;
                ray.origin[a] = targets[k][a] - 3.0 * ray.dir[a];
            }
            // Targets on the boundary: keep the rays that pass through the inside of the
            // cube next to the target (the others touch the domain at one point only).
            auto inside = [&](double s) {
                for (int a = 0; a < 3; ++a) {
                    const double x = targets[k][a] + s * ray.dir[a];
                    if (x <= 0 || x >= 1) return false;
                }
                return true;
            };
            if (!inside(1e-3) && !inside(-1e-3)) continue;
            IntegrateRay(setup, ray, sample, counters);
            ASSERT_EQ(sample.isoId, 0) << k << " " << trial;
            EXPECT_NEAR(sample.z, 3.0, 1e-12) << k << " " << trial;
            EXPECT_EQ(sample.rgba[3], 0.5) << k << " " << trial;
            ++checked;
        }
    EXPECT_GT(checked, 1000);
}


// Cost measuring (the pre-pass of in-memory splits): one sample per traversed segment;
// rays do not stop at the opaque sphere, and every segment behind it names the hit point
// (on the analytic sphere) as its occluder, every segment before it none.
TEST(IsoRender, CostSamplesCoverEverySegmentAndRecordOpaqueStops) {
    const Mesh mesh = MakeBuiltin("builtin:ball-p2");
    const Scene scene = MakeScene(kBallScene);
    RenderStats stats = StartStats(scene);
    PreparedBrick brick(mesh, std::nullopt, scene, stats);
    std::vector<SegmentCostSample> samples;
    Image image;
    brick.Render(scene, Camera(scene.camera), std::nullopt, image, stats, &samples);
    ASSERT_EQ(static_cast<double>(samples.size()), stats.counters.segments);
    const double R = 0.7;
    int occluded = 0, visible = 0;
    for (const SegmentCostSample& s : samples) {
        EXPECT_GE(s.seconds, 0.0f);
        double enter = 0, exit = 0;
        for (int d = 0; d < 3; ++d) {
            enter += s.enter[d] * s.enter[d];
            exit += s.exit[d] * s.exit[d];
        }
        if (s.occluded) {
            ++occluded;
            const double r = std::sqrt(s.occluder[0] * s.occluder[0] +
                                       s.occluder[1] * s.occluder[1] +
                                       s.occluder[2] * s.occluder[2]);
            EXPECT_NEAR(r, R, 1e-9);
        } else {
            ++visible;
            // Not behind the sphere: the segment starts outside it (up to rounding).
            EXPECT_GT(std::sqrt(enter), R - 1e-9);
        }
    }
    EXPECT_GT(occluded, 1000);
    EXPECT_GT(visible, 1000);
    // Measuring does not stop rays: hits behind the first one are found and counted.
    // A plain render stops each ray's walk at its opaque hit: it walks exactly the
    // segments not behind one.
    RenderStats plain;
    RenderMeshJob(mesh, scene, plain);
    EXPECT_GT(stats.counters.isoHits, plain.counters.isoHits);
    EXPECT_EQ(plain.counters.segments, visible);
}

}  // namespace
}  // namespace hpray

namespace hpray {
namespace {

// Per-field data is computed once per mesh: setups for scenes that change isovalues or
// transfer functions share it (the service's frames), and the ranges are those the field
// has (every nodal value lies in its cell's range; u = x^2 + y^2 + z^2 >= 0).
TEST(FieldCache, SetupsOfChangedValuesReuseTheFieldsData) {
    const Mesh mesh = MakeBuiltin("builtin:ball-p2");
    const MeshGeometry geometry = MeshGeometry::Build(mesh);
    const BrickTraverser traverser(Brick::WholeMesh(mesh));
    FieldCache cache(mesh, geometry);
    Scene scene = MakeScene(kBallScene);
    const BrickSetup first = MakeBrickSetup(mesh, geometry, traverser, scene, &cache);
    ASSERT_TRUE(first.subBounds[0]);
    const std::int64_t builtFirst = first.subBounds[0]->subCells;
    EXPECT_EQ(cache.DataBuilt(), 1);
    EXPECT_EQ(cache.RangesBuilt(), 1);
    scene.isosurfaces[0].value = 0.25;
    scene.volume.emplace();
    scene.volume->colorField = "u";
    scene.volume->colorTf = {{0.0, {0.1, 0.2, 0.9}}, {3.0, {1.0, 0.4, 0.1}}};
    scene.volume->extinctionTf = {{0.0, 0.5}, {3.0, 2.0}};
    const BrickSetup second = MakeBrickSetup(mesh, geometry, traverser, scene, &cache);
    EXPECT_EQ(cache.DataBuilt(), 1);
    EXPECT_EQ(cache.RangesBuilt(), 1);
    ASSERT_EQ(second.cellRanges.size(), 1u);
    EXPECT_EQ(first.cellRanges[0].get(), second.cellRanges[0].get());
    EXPECT_EQ(first.fieldData[0].get(), second.fieldData[0].get());
    // The sub-cell bounds too (ball-p2's quadratic tetrahedra have them): built for the
    // cells whose range holds the first isovalue, extended to those of the second.
    std::int64_t firstCells = 0;
    for (const Interval& r : *first.cellRanges[0])
        firstCells += 0.49 >= r.lo && 0.49 <= r.hi;
    EXPECT_EQ(builtFirst, firstCells);
    EXPECT_EQ(first.subBounds[0].get(), second.subBounds[0].get());
    EXPECT_GT(second.subBounds[0]->subCells, firstCells);
    ASSERT_TRUE(second.volume);
    EXPECT_EQ(second.volume->ranges[0].get(), second.cellRanges[0].get());
    // Gradient bounds (for linear tetrahedra; this mesh has none, so they are empty) are
    // built once too.
    EXPECT_EQ(cache.GradientBoundsBuilt(), 1);
    scene.volume->extinctionTf = {{0.0, 1.5}, {3.0, 0.5}};
    const BrickSetup third = MakeBrickSetup(mesh, geometry, traverser, scene, &cache);
    EXPECT_EQ(cache.GradientBoundsBuilt(), 1);
    ASSERT_TRUE(third.volume);
    EXPECT_EQ(third.volume->gradientBound[0].get(),
              second.volume->gradientBound[0].get());
    const auto sel = SelectScalar(mesh, "u");
    ASSERT_TRUE(sel);
    const std::vector<Interval>& ranges = *cache.Ranges(*sel);
    ASSERT_EQ(static_cast<std::int64_t>(ranges.size()), mesh.CellCount());
    for (std::int64_t c = 0; c < mesh.CellCount(); ++c) {
        const std::int64_t* nodes = mesh.CellNodes(c);
        EXPECT_GE(ranges[c].hi, ranges[c].lo);
        EXPECT_GE(ranges[c].hi, -1e-12);
        for (int m = 0; m < mesh.CellNodeCount(c); ++m) {
            const double v = ScalarValue(*sel, nodes[m]);
            EXPECT_LE(ranges[c].lo, v + 1e-15) << c;
            EXPECT_GE(ranges[c].hi, v - 1e-15) << c;
        }
    }
    // A setup without a cache computes its own.
    const BrickSetup own = MakeBrickSetup(mesh, geometry, traverser, scene);
    EXPECT_NE(own.cellRanges[0].get(), first.cellRanges[0].get());
}

}  // namespace
}  // namespace hpray

namespace hpray {
namespace {

// A long render says how far it is: with a progress interval, lines with the share of
// tiles done and the time left go to the log; without one, nothing.
TEST(RenderProgress, LinesWithShareAndTimeLeft) {
    const Mesh mesh = MakeBuiltin("builtin:ball-p2");
    const MeshGeometry geometry = MeshGeometry::Build(mesh);
    const BrickTraverser traverser(Brick::WholeMesh(mesh));
    const Scene scene = MakeScene(kBallScene);
    BrickSetup setup = MakeBrickSetup(mesh, geometry, traverser, scene);
    Image image;
    RenderCounters counters;
    ::testing::internal::CaptureStderr();
    RenderBrick(setup, Camera(scene.camera), 1, image, counters);
    EXPECT_EQ(::testing::internal::GetCapturedStderr().find("of the tiles"), std::string::npos);
    setup.progressSeconds = 1e-9;  // every tile
    ::testing::internal::CaptureStderr();
    RenderBrick(setup, Camera(scene.camera), 1, image, counters);
    const std::string log = ::testing::internal::GetCapturedStderr();
    EXPECT_NE(log.find("rendering 72x64: "), std::string::npos) << log;
    EXPECT_NE(log.find("% of the tiles after "), std::string::npos) << log;
    EXPECT_NE(log.find("100% of the tiles"), std::string::npos) << log;
    EXPECT_NE(log.find("s left"), std::string::npos) << log;
}

}  // namespace
}  // namespace hpray

namespace hpray {
namespace {

// An isosurface coloured by another field: the sphere u = 0.25 of ball-p2 coloured by
// v = x through a grey ramp over [-1, 1], unlit (ambient 1), so each hit pixel's colour is
// (x + 1) / 2 at the true hit point, found from the ray and the hit's t.
TEST(IsoRender, ColouredByAnotherFieldAtTheHit) {
    const Mesh mesh = MakeBuiltin("builtin:ball-p2");
    const Scene scene = MakeScene(R"(
data: {mesh: "builtin:ball-p2"}
camera: {position: [0.3, 0.4, 4], look_at: [0, 0, 0], up: [0, 1, 0], fov_y: 20,
         width: 48, height: 40}
isosurfaces:
  - {field: u, value: 0.25, color_field: v, color_tf: [[-1, 0, 0, 0], [1, 1, 1, 1]]}
lighting: {ambient: 1, diffuse: 0, specular: 0}
)");
    Image image;
    RenderStats stats;
    RenderOneBrick(mesh, std::nullopt, scene, image, stats);
    const Camera camera(scene.camera);
    int hits = 0;
    for (int j = 0; j < camera.Height(); ++j)
        for (int i = 0; i < camera.Width(); ++i) {
            const std::size_t p = std::size_t(j) * camera.Width() + i;
            if (!std::isfinite(image.z[p])) continue;
            ++hits;
            const CameraRay ray = camera.PixelRay(i, j);
            const double x = ray.origin[0] + image.z[p] * ray.direction[0];
            for (double c : {image.r[p], image.g[p], image.b[p]})
                EXPECT_NEAR(c, 0.5 * (x + 1), 1e-9) << i << "," << j;
        }
    EXPECT_GT(hits, 200);
    // The colour varies over the sphere (x spans about [-0.5, 0.5] on it).
    double lo = 1, hi = 0;
    for (std::size_t p = 0; p < image.PixelCount(); ++p)
        if (std::isfinite(image.z[p])) lo = std::min(lo, image.r[p]), hi = std::max(hi, image.r[p]);
    EXPECT_GT(hi - lo, 0.35);
}

}  // namespace
}  // namespace hpray

namespace hpray {
namespace {

// accuracy.target_residual: every hit's true residual (measured independently here at the
// reported point, through the exact field of the builtin) is within the target, the same
// pixels are hit as at full accuracy, and a looser target does less work.
TEST(IsoRender, TargetResidualIsMetAtEveryHitAndBuysWork) {
    const Mesh mesh = MakeBuiltin("builtin:nk-quartic");
    auto quartic = [](const double x[3]) {
        double u = 0;
        for (int d = 0; d < 3; ++d) {
            const double d2 = (0.5 - x[d]) * (0.5 - x[d]);
            u += d2 * (d2 - 0.169);
        }
        return u;
    };
    const double C = -0.00716511;
    auto render = [&](double target, RenderStats& stats) {
        Scene scene = MakeScene(R"(data: {mesh: "builtin:nk-quartic"}
camera: {position: [2.2, 1.6, 2.6], look_at: [0.5, 0.5, 0.5], up: [0, 1, 0], fov_y: 30,
         width: 48, height: 48}
isosurfaces:
  - {field: u, value: -0.00716511}
)");
        scene.accuracy.targetResidual = target;
        if (target > 0) scene.accuracy.projectionTolerance = target / 4;
        return RenderMeshJob(mesh, scene, stats);
    };
    RenderStats exactStats;
    const Image exact = render(0, exactStats);
    const double range = exactStats.isoFieldRange[1] - exactStats.isoFieldRange[0];
    ASSERT_GT(exactStats.counters.isoHits, 500);
    const Camera camera(MakeScene(R"(data: {mesh: "builtin:nk-quartic"}
camera: {position: [2.2, 1.6, 2.6],
  look_at: [0.5, 0.5, 0.5], up: [0, 1, 0], fov_y: 30, width: 48, height: 48})").camera);
    for (double target : {1e-4, 1e-6, 1e-8}) {
        RenderStats stats;
        const Image image = render(target, stats);
        EXPECT_EQ(stats.counters.rootFailures, 0);
        EXPECT_LE(stats.counters.isoResidualMax, target * range) << target;
        // A quarter of the samples or more saved: the projection's checks (four of
        // about twelve samples a segment) are skipped where its tail is 1e-3 of the
        // loosened tolerance.
        EXPECT_LT(stats.counters.fieldEvaluations,
                  0.75 * exactStats.counters.fieldEvaluations)
            << target;
        for (int y = 0; y < 48; ++y)
            for (int x = 0; x < 48; ++x) {
                const Pixel a = LoadPixel(image, std::size_t(y) * 48 + x);
                const Pixel b = LoadPixel(exact, std::size_t(y) * 48 + x);
                ASSERT_EQ(std::isfinite(a.z), std::isfinite(b.z)) << x << " " << y;
                if (!std::isfinite(a.z)) continue;
                // The field is exactly this quartic (the order-8 hexes interpolate it
                // without error), so the residual is checked against it at the hit.
                const CameraRay ray = camera.PixelRay(x, y);
                double p[3];
                for (int d = 0; d < 3; ++d) p[d] = ray.origin[d] + a.z * ray.direction[d];
                EXPECT_LE(std::abs(quartic(p) - C), target * range * (1 + 1e-6) + 1e-15)
                    << target << " at " << x << " " << y;
                EXPECT_NEAR(a.isoResidual, std::abs(quartic(p) - C), 1e-14);
            }
    }
}

}  // namespace
}  // namespace hpray

namespace hpray {
namespace {

// A scene rendered with the sub-cell bounds and without them (one thread).
struct WithAndWithout {
    Image with, without;
    RenderCounters cWith, cWithout;
    /// Segments ruled out, by the cell filter (never traced) or in the cell.
    double RuledOut() const {
        return cWithout.segments - cWith.segments + cWith.isoSubcellCulled;
    }
};
WithAndWithout RenderWithAndWithoutSubCellBounds(const Mesh& mesh, const Scene& scene) {
    const MeshGeometry geometry = MeshGeometry::Build(mesh);
    const BrickTraverser traverser(Brick::WholeMesh(mesh));
    const BrickSetup on = MakeBrickSetup(mesh, geometry, traverser, scene);
    const BrickSetup off =
        MakeBrickSetup(mesh, geometry, traverser, scene, nullptr, false);
    const Camera camera(scene.camera);
    WithAndWithout r;
    RenderBrick(on, camera, 1, r.with, r.cWith);
    RenderBrick(off, camera, 1, r.without, r.cWithout);
    return r;
}

// Over every pixel (i, j) of r's two images, p its index: the same pixels hit (fatal
// otherwise), pixel(i, j, p); then on each hit the same depth to 1e-12 and hit(i, j, p).
// `hits` counts the hits.
template <class Pixel, class Hit>
void ExpectSameHits(const WithAndWithout& r, int& hits, Pixel&& pixel, Hit&& hit) {
    const Image &with = r.with, &without = r.without;
    hits = 0;
    for (int j = 0; j < with.height; ++j)
        for (int i = 0; i < with.width; ++i) {
            const std::size_t p = std::size_t(j) * with.width + i;
            ASSERT_EQ(std::isfinite(with.z[p]), std::isfinite(without.z[p]))
                << i << "," << j;
            pixel(i, j, p);
            if (!std::isfinite(with.z[p])) continue;
            ++hits;
            EXPECT_NEAR(with.z[p], without.z[p], 1e-12);
            hit(i, j, p);
        }
}

// The sub-cell bounds rule out or shorten segments without changing what is found: the
// plane x = C of the isoparametric field on strongly curved hexes, with the bounds and
// without, gives the same hits to rounding, both on the analytic plane, while the bounds
// cull segments and save field samples.
TEST(IsoRender, SubCellBoundsCullSegmentsAndKeepEveryHit) {
    const Mesh mesh = testing::CurvedHexesWithFieldX(0.08, 4);
    const Scene scene = MakeScene(R"(
data: {mesh: "builtin:nk-sinc"}
camera: {position: [2.6, 1.7, 2.2], look_at: [0.5, 0.5, 0.5], up: [0, 1, 0], fov_y: 32,
         width: 48, height: 48}
isosurfaces:
  - {field: u, value: 0.37, opacity: 0.5}
  - {field: u, value: 0.81}
)");
    const WithAndWithout r = RenderWithAndWithoutSubCellBounds(mesh, scene);
    const Camera camera(scene.camera);
    const Image &with = r.with, &without = r.without;
    const RenderCounters &cWith = r.cWith, &cWithout = r.cWithout;
    const double ruledOut = r.RuledOut();
    EXPECT_GT(ruledOut, 0.1 * cWithout.segments);
    EXPECT_EQ(cWithout.isoSubcellCulled, 0);
    EXPECT_LT(cWith.fieldEvaluations, 0.9 * cWithout.fieldEvaluations);
    EXPECT_EQ(cWith.isoHits, cWithout.isoHits);
    EXPECT_EQ(cWith.rootFailures, 0);
    int hits = 0;
    ASSERT_NO_FATAL_FAILURE(ExpectSameHits(
        r, hits,
        [&](int, int, std::size_t p) { EXPECT_EQ(with.isoId[p], without.isoId[p]); },
        [&](int i, int j, std::size_t p) {
            EXPECT_NEAR(with.r[p], without.r[p], 1e-12);
            // The first surface met is one of the two planes.
            const CameraRay ray = camera.PixelRay(i, j);
            const double x = ray.origin[0] + with.z[p] * ray.direction[0];
            EXPECT_NEAR(std::min(std::abs(x - 0.37), std::abs(x - 0.81)), 0, 1e-10);
        }));
    EXPECT_GT(hits, 300);
}

}  // namespace
}  // namespace hpray

namespace hpray {
namespace {

// The same on quadratic tetrahedra (sub-tetrahedra): ball-p2's sphere, with and without
// the bounds, the same hits, both on the analytic sphere (ExpectSphereImage's scene).
TEST(IsoRender, SubTetrahedronBoundsCullSegmentsAndKeepEveryHit) {
    const Mesh mesh = MakeBuiltin("builtin:ball-p2");
    Scene scene = MakeScene(kBallScene);
    scene.isosurfaces[0].value = 0.25;  // R = 0.5
    const WithAndWithout r = RenderWithAndWithoutSubCellBounds(mesh, scene);
    const Camera camera(scene.camera);
    const Image& with = r.with;
    const RenderCounters &cWith = r.cWith, &cWithout = r.cWithout;
    const double ruledOut = r.RuledOut();
    EXPECT_GT(ruledOut, 0.1 * cWithout.segments);
    EXPECT_LT(cWith.fieldEvaluations, cWithout.fieldEvaluations);
    EXPECT_EQ(cWith.isoHits, cWithout.isoHits);
    int hits = 0;
    ASSERT_NO_FATAL_FAILURE(ExpectSameHits(
        r, hits, [](int, int, std::size_t) {},
        [&](int i, int j, std::size_t p) {
            bool grazing = false;
            const auto expect = RaySphere(camera.PixelRay(i, j), 0.5, grazing);
            if (!grazing && expect) {
                EXPECT_NEAR(with.z[p], expect->t, 1e-9);
            }
        }));
    EXPECT_GT(hits, 300);
}

}  // namespace
}  // namespace hpray

namespace hpray {
namespace {

// Rays parallel to two axes (an orthographic camera looking down -x): the sub-cell
// bounds' slab test takes its zero-direction branch for y and z. Every ray inside the
// domain meets the plane x = 0.81 at t = 3 - 0.81, with and without the bounds.
TEST(IsoRender, SubCellBoundsWithRaysAlongAnAxis) {
    const Mesh mesh = testing::CurvedHexesWithFieldX(0.08, 4);
    const Scene scene = MakeScene(R"(
data: {mesh: "builtin:nk-sinc"}
camera: {position: [3, 0.52, 0.47], look_at: [0.5, 0.52, 0.47], up: [0, 1, 0],
         ortho_height: 1.2, width: 40, height: 40}
isosurfaces:
  - {field: u, value: 0.81}
)");
    const WithAndWithout r = RenderWithAndWithoutSubCellBounds(mesh, scene);
    const Camera camera(scene.camera);
    const Image &with = r.with, &without = r.without;
    const RenderCounters &cWith = r.cWith, &cWithout = r.cWithout;
    EXPECT_LT(cWith.fieldEvaluations, cWithout.fieldEvaluations);
    int hits = 0;
    for (int j = 0; j < 40; ++j)
        for (int i = 0; i < 40; ++i) {
            const std::size_t p = std::size_t(j) * 40 + i;
            const CameraRay r = camera.PixelRay(i, j);
            ASSERT_EQ(r.direction[1], 0.0);
            ASSERT_EQ(r.direction[2], 0.0);
            const double y = r.origin[1], z = r.origin[2];
            if (std::min({y, z, 1 - y, 1 - z}) < 1e-9)
                continue;  // outside or on the edge
            ASSERT_TRUE(std::isfinite(with.z[p])) << i << "," << j;
            ASSERT_TRUE(std::isfinite(without.z[p])) << i << "," << j;
            ++hits;
            EXPECT_NEAR(with.z[p], 3 - 0.81, 1e-10);
            EXPECT_NEAR(with.z[p], without.z[p], 1e-12);
        }
    EXPECT_GT(hits, 600);
}

}  // namespace
}  // namespace hpray

namespace hpray {
namespace {

// Every sub-box's world box holds the map's image of points spread over the box, and its
// interval the field there (the values the rays evaluate): on the curved hexahedra, with
// the default budget (4 x 4 x 4 boxes) and with one that only fits 2 x 2 x 2.
TEST(SubCellBounds, BoxesHoldTheMappedPointsAndTheirValues) {
    const Mesh mesh = testing::CurvedHexesWithFieldX(0.08, 4);
    const MeshGeometry geometry = MeshGeometry::Build(mesh);
    const auto sel = SelectScalar(mesh, "u");
    ASSERT_TRUE(sel);
    const FieldCellData data = FieldCellData::Build(mesh, geometry, *sel);
    const std::int64_t cells = mesh.CellCount();
    std::mt19937_64 rng(3);
    std::uniform_real_distribution<double> unit(0, 1);
    for (const std::int64_t budget : {std::int64_t(256) << 20, cells * 8 * 32}) {
        const SubCellBounds b =
            SubCellBounds::Build(mesh, geometry, data, nullptr, budget);
        const int n = budget == cells * 8 * 32 ? 2 : 4;
        ASSERT_EQ(b.subN, n);
        ASSERT_EQ(b.subCells, cells);
        CellScratch scratch;
        EvalWorkspace ws;
        std::vector<double> nodal;
        for (std::int64_t c = 0; c < cells; ++c) {
            ASSERT_EQ(b.subStart[c + 1] - b.subStart[c], n * n * n);
            const CellGeometry& g = geometry.Cell(c, scratch);
            CellScalar field;
            field.nodal = data.CellValues(c, nodal);
            for (int box = 0; box < n * n * n; ++box) {
                const SubCellBounds::SubBox x = b.SubBoxOf(c, box);
                const int k[3] = {box % n, (box / n) % n, box / (n * n)};
                for (int s = 0; s < 20; ++s) {
                    double ref[3], world[3], jac[9];
                    for (int d = 0; d < 3; ++d) ref[d] = (k[d] + unit(rng)) / n;
                    WorldFromRef(g, ref, ws, world, jac);
                    for (int d = 0; d < 3; ++d) {
                        EXPECT_LE(x.lo[d], world[d]) << c << " " << box;
                        EXPECT_GE(x.hi[d], world[d]) << c << " " << box;
                    }
                    const double v = FieldValue(g, field, ref, ws);
                    EXPECT_LE(x.fieldLo, v) << c << " " << box;
                    EXPECT_GE(x.fieldHi, v) << c << " " << box;
                }
            }
        }
    }
    // Nothing fits a budget below 8 boxes per cell.
    EXPECT_EQ(
        SubCellBounds::Build(mesh, geometry, data, nullptr, cells * 8 * 32 - 1).subCells,
        0);
    // Built for some cells only: the others hold everything until Extend computes them,
    // and then they are what a full build gives.
    const SubCellBounds all = SubCellBounds::Build(mesh, geometry, data);
    std::vector<std::uint8_t> half(cells, 0);
    for (std::int64_t c = 0; c < cells; c += 2) half[c] = 1;
    SubCellBounds some = SubCellBounds::Build(mesh, geometry, data, &half);
    EXPECT_EQ(some.subCells, (cells + 1) / 2);
    const double value = 0.37;
    for (std::int64_t c = 0; c < cells; ++c) {
        if (half[c]) {
            EXPECT_EQ(some.Holding(c, &value, 1), all.Holding(c, &value, 1));
        } else {
            EXPECT_EQ(some.Holding(c, &value, 1), ~std::uint64_t(0));
        }
    }
    some.Extend(mesh, geometry, data, nullptr);
    EXPECT_EQ(some.subCells, cells);
    const std::size_t floats = 8 * static_cast<std::size_t>(all.subStart.back());
    EXPECT_TRUE(
        std::equal(some.subData.get(), some.subData.get() + floats, all.subData.get()));
}

}  // namespace
}  // namespace hpray
