// Volume rendering of high-order data against independent truth: ball-p2 (u = r^2
// exactly) and nk-sinc (its order-8 tensor interpolant, evaluated here independently of
// the library's bases): the true error of every pixel against a long-double ODE reference
// is within the reported vol.error on at least 99% of the pixels; isosurfaces embedded in
// the volume at their analytic depth; slices of high-order and curved data show the true
// field on the plane.
#include <gtest/gtest.h>

#include <cmath>

#include "mesh/builtin.h"
#include "render/brick_renderer.h"
#include "render/render_job.h"
#include "render/test_volume_reference.h"
#include "scene/camera.h"
#include "scene/scene.h"
#include "trace/trace_test_meshes.h"

namespace hpray {
namespace {

using testing::LD;
using testing::SampledCrossings;
using testing::RefPixel;
using testing::RefSurface;
using testing::RefTf;

Scene MakeScene(const std::string& yaml) { return ParseScene(yaml, "test.yaml", {}, ""); }

struct ErrorSummary {
    int pixels = 0;
    int bounded = 0;     ///< true error <= vol.error (+ the reference's own 1e-15)
    double maxTrue = 0;  ///< largest true RGB error
    double maxEstimate = 0;
};

/// Compares image pixel p (RGB, A) with a reference: counts whether vol.error bounds the
/// true RGB error, and requires alpha to the same bound.
void Account(const Image& image, std::size_t p, const RefPixel& ref, ErrorSummary& s) {
    const double got[3] = {image.r[p], image.g[p], image.b[p]};
    double err = 0;
    for (int c = 0; c < 3; ++c)
        err = std::max(err, double(std::abs(got[c] - ref.rgb[c])));
    ++s.pixels;
    s.bounded += err <= image.volError[p] + 1e-15;
    s.maxTrue = std::max(s.maxTrue, err);
    s.maxEstimate = std::max(s.maxEstimate, image.volError[p]);
}

// ---------------------------------------------------------------------------------------
// ball-p2: straight quadratic tets on [-1, 1]^3 with u = x^2 + y^2 + z^2 (exact).

const char* kBallVolume = R"(
data: {mesh: "builtin:ball-p2"}
camera: {position: [2.1, 1.3, 2.9], look_at: [0.01, -0.02, 0.03], up: [0, 1, 0], fov_y: 44,
         width: 24, height: 24}
volume:
  color_field: u
  glow: williams-max
  color_tf: [[0.1, 0.9, 0.2, 0.1], [0.6, 0.2, 0.8, 0.3], [1.5, 0.1, 0.3, 1.0]]
  extinction_tf: [[0.2, 6.0], [0.5, 0.3], [1.2, 2.0], [2.5, 0.0]]
)";

struct BallRay {
    std::array<double, 3> o, d;
    LD U(LD t) const {
        LD s = 0;
        for (int a = 0; a < 3; ++a) {
            const LD x = LD(o[a]) + t * LD(d[a]);
            s += x * x;
        }
        return s;
    }
    // |o + t d|^2 = level (|d| = 1).
    void Crossings(LD level, std::vector<LD>& out) const {
        LD b = 0, c = -level;
        for (int a = 0; a < 3; ++a) {
            b += LD(o[a]) * LD(d[a]);
            c += LD(o[a]) * LD(o[a]);
        }
        const LD disc = b * b - c;
        if (disc <= 0) return;
        out.push_back(-b - std::sqrt(disc));
        out.push_back(-b + std::sqrt(disc));
    }
};

ErrorSummary BallErrors(const Scene& scene, const Image& image) {
    const Camera camera(scene.camera);
    const RefTf ctf = RefTf::Color(scene.volume->colorTf);
    const RefTf etf = RefTf::Extinction(scene.volume->extinctionTf);
    const bool wm = scene.volume->glow == GlowModel::WilliamsMax;
    ErrorSummary s;
    for (int j = 0; j < image.height; ++j)
        for (int i = 0; i < image.width; ++i) {
            const CameraRay cr = camera.PixelRay(i, j);
            const BallRay ray{cr.origin, cr.direction};
            LD t0, t1;
            if (!testing::RefBoxChord(cr.origin, cr.direction, {-1, -1, -1}, {1, 1, 1},
                                      t0, t1) ||
                t1 - t0 < 1e-6)
                continue;
            std::vector<LD> kinks;
            for (LD level : ctf.scalars) ray.Crossings(level, kinks);
            for (LD level : etf.scalars) ray.Crossings(level, kinks);
            const RefPixel ref = testing::ReferenceRay(
                t0, t1, [&](LD t) { return ray.U(t); }, [&](LD t) { return ray.U(t); },
                ctf, etf, wm, kinks);
            const std::size_t p = std::size_t(j) * image.width + i;
            EXPECT_NEAR(image.a[p], double(ref.alpha), 1e-7) << i << "," << j;
            Account(image, p, ref, s);
        }
    return s;
}

TEST(VolumeHighOrder, BallP2ErrorEstimateBoundsTheTrueError) {
    const Mesh mesh = MakeBuiltin("builtin:ball-p2");
    Scene scene = MakeScene(kBallVolume);
    for (GlowModel glow : {GlowModel::WilliamsMax, GlowModel::WilhelmsVanGelder})
        for (double tolerance : {1e-5, 1e-9}) {
            scene.volume->glow = glow;
            scene.accuracy.volumeTolerance = tolerance;
            RenderStats stats;
            const Image image = RenderMeshJob(mesh, scene, stats);
            const ErrorSummary s = BallErrors(scene, image);
            ASSERT_GT(s.pixels, 300);
            EXPECT_GE(s.bounded, 0.99 * s.pixels) << "tolerance " << tolerance;
            // The estimate honours the tolerance, and so does the true error.
            EXPECT_LE(s.maxEstimate, tolerance);
            EXPECT_LE(s.maxTrue, tolerance);
            EXPECT_NEAR(stats.counters.volumeErrorMax, s.maxEstimate, 1e-300);
            EXPECT_GT(stats.counters.volumePixels, 300);
            EXPECT_EQ(stats.counters.rootFailures, 0);
        }
}

// An isosurface inside the volume: composited at its analytic depth, the volume split
// there. u = 0.49 is the sphere r = 0.7.
TEST(VolumeHighOrder, EmbeddedIsosurfaceAtItsExactDepth) {
    const Mesh mesh = MakeBuiltin("builtin:ball-p2");
    Scene scene = MakeScene(std::string(kBallVolume) + R"(
isosurfaces:
  - {field: u, value: 0.49, color: [1.0, 0.9, 0.2], opacity: 0.55}
lighting: {ambient: 0.2, diffuse: 0.7, specular: 0.25, shininess: 16}
accuracy: {volume_tolerance: 1e-9}
)");
    RenderStats stats;
    const Image image = RenderMeshJob(mesh, scene, stats);
    const Camera camera(scene.camera);
    const RefTf ctf = RefTf::Color(scene.volume->colorTf);
    const RefTf etf = RefTf::Extinction(scene.volume->extinctionTf);
    ErrorSummary s;
    int hits = 0;
    for (int j = 0; j < image.height; ++j)
        for (int i = 0; i < image.width; ++i) {
            const CameraRay cr = camera.PixelRay(i, j);
            const BallRay ray{cr.origin, cr.direction};
            LD t0, t1;
            if (!testing::RefBoxChord(cr.origin, cr.direction, {-1, -1, -1}, {1, 1, 1},
                                      t0, t1) ||
                t1 - t0 < 1e-6)
                continue;
            std::vector<LD> hitsT;
            ray.Crossings(0.49L, hitsT);
            if (hitsT.size() == 2 && hitsT[1] - hitsT[0] < 1e-3) continue;  // grazing
            std::vector<RefSurface> surfaces;
            for (LD t : hitsT) {
                // Headlight Blinn-Phong with the sphere's normal facing the camera.
                LD nl = 0;
                for (int a = 0; a < 3; ++a)
                    nl += (LD(cr.origin[a]) + t * LD(cr.direction[a])) / 0.7L *
                          LD(cr.direction[a]);
                nl = std::abs(nl);
                const LD spec = 0.25L * std::pow(nl, 16.0L);
                RefSurface surface{t, {}, 0.55L};
                const LD color[3] = {1.0L, 0.9L, 0.2L};
                for (int c = 0; c < 3; ++c)
                    surface.color[c] =
                        std::min<LD>(1, color[c] * (0.2L + 0.7L * nl) + spec);
                surfaces.push_back(surface);
            }
            std::vector<LD> kinks;
            for (LD level : ctf.scalars) ray.Crossings(level, kinks);
            for (LD level : etf.scalars) ray.Crossings(level, kinks);
            const RefPixel ref = testing::ReferenceRay(
                t0, t1, [&](LD t) { return ray.U(t); }, [&](LD t) { return ray.U(t); },
                ctf, etf, true, kinks, surfaces);
            const std::size_t p = std::size_t(j) * image.width + i;
            if (!surfaces.empty()) {
                ++hits;
                EXPECT_NEAR(image.z[p], double(surfaces[0].t), 1e-10) << i << "," << j;
                EXPECT_EQ(image.isoId[p], 0);
            } else {
                EXPECT_EQ(image.isoId[p], -1);
            }
            // Shading uses the true-field normal (accurate to ~1e-12).
            for (int c = 0; c < 3; ++c) {
                const double got[3] = {image.r[p], image.g[p], image.b[p]};
                EXPECT_NEAR(got[c], double(ref.rgb[c]), image.volError[p] + 1e-10)
                    << i << "," << j << " " << c;
            }
            EXPECT_NEAR(image.a[p], double(ref.alpha), 1e-9) << i << "," << j;
            Account(image, p, ref, s);
        }
    EXPECT_GT(hits, 80);
    EXPECT_LE(s.maxEstimate, 1e-9);
}

// ---------------------------------------------------------------------------------------
// nk-sinc: 5^3 axis-aligned boxes of order 8; the truth is the tensor-product equispaced
// Lagrange interpolant of u = 2 (y - 0.3) - sinc(|(x, z) - (0.5, 0.5)|) on each box
// (testing::NkSincTruth).

using testing::NkSincTruth;

// Renders `scene` at each tolerance and checks every pixel against the reference along
// the same ray through nk-sinc's interpolant.
void CheckNkSinc(Scene scene, const std::vector<double>& tolerances,
                 LD referenceTolerance) {
    const Mesh mesh = MakeBuiltin("builtin:nk-sinc");
    NkSincTruth truth;
    const Camera camera(scene.camera);
    const RefTf ctf = RefTf::Color(scene.volume->colorTf);
    const RefTf etf = RefTf::Extinction(scene.volume->extinctionTf);
    const bool wm = scene.volume->glow == GlowModel::WilliamsMax;
    const std::size_t count = tolerances.size();
    std::vector<Image> images(count);
    std::vector<RenderStats> stats(count);
    for (std::size_t k = 0; k < count; ++k) {
        scene.accuracy.volumeTolerance = tolerances[k];
        images[k] = RenderMeshJob(mesh, scene, stats[k]);
    }
    std::vector<ErrorSummary> summary(count);
    for (int j = 0; j < scene.camera.height; ++j)
        for (int i = 0; i < scene.camera.width; ++i) {
            const CameraRay cr = camera.PixelRay(i, j);
            LD t0, t1;
            if (!testing::RefBoxChord(cr.origin, cr.direction, {0, 0, 0}, {1, 1, 1}, t0,
                                      t1) ||
                t1 - t0 < 1e-6)
                continue;
            // Box faces crossed, then the field's breakpoint crossings inside each box.
            std::vector<LD> cuts = {t0, t1};
            for (int a = 0; a < 3; ++a)
                for (double b : NkSincTruth::kBreaks)
                    if (cr.direction[a] != 0) {
                        const LD t = (LD(b) - cr.origin[a]) / LD(cr.direction[a]);
                        if (t > t0 && t < t1) cuts.push_back(t);
                    }
            std::sort(cuts.begin(), cuts.end());
            std::vector<std::array<int, 3>> boxes;
            for (std::size_t k = 0; k + 1 < cuts.size(); ++k) {
                const LD mid = (cuts[k] + cuts[k + 1]) / 2;
                std::array<int, 3> box;
                for (int a = 0; a < 3; ++a)
                    box[a] =
                        NkSincTruth::Box(double(cr.origin[a] + mid * cr.direction[a]));
                boxes.push_back(box);
            }
            auto field = [&](LD t) {
                // The box of the piece holding t.
                const auto it = std::upper_bound(cuts.begin(), cuts.end(), t);
                const std::size_t k = std::min<std::size_t>(
                    std::max<std::ptrdiff_t>(it - cuts.begin(), 1), cuts.size() - 1);
                LD x[3];
                for (int a = 0; a < 3; ++a) x[a] = cr.origin[a] + t * cr.direction[a];
                return truth.Eval(x, boxes[k - 1].data());
            };
            std::vector<LD> kinks(cuts.begin(), cuts.end());
            for (std::size_t k = 0; k + 1 < cuts.size(); ++k) {
                const LD a = cuts[k] + 1e-15L, b = cuts[k + 1] - 1e-15L;
                for (LD level : ctf.scalars)
                    SampledCrossings(field, a, b, level, 64, kinks);
                for (LD level : etf.scalars)
                    SampledCrossings(field, a, b, level, 64, kinks);
            }
            const RefPixel ref = testing::ReferenceRay(t0, t1, field, field, ctf, etf, wm,
                                                       kinks, {}, referenceTolerance);
            const std::size_t p = std::size_t(j) * scene.camera.width + i;
            for (std::size_t k = 0; k < count; ++k) {
                EXPECT_NEAR(images[k].a[p], double(ref.alpha),
                            std::max(1e-12, 2 * tolerances[k]));
                Account(images[k], p, ref, summary[k]);
            }
        }
    for (std::size_t k = 0; k < count; ++k) {
        const ErrorSummary& s = summary[k];
        ASSERT_GT(s.pixels, 80);
        EXPECT_GE(s.bounded, 0.99 * s.pixels) << "tolerance " << tolerances[k];
        EXPECT_LE(s.maxEstimate, tolerances[k]);
        EXPECT_LE(s.maxTrue, tolerances[k]);
        EXPECT_EQ(stats[k].counters.rootFailures, 0);
    }
}

TEST(VolumeHighOrder, NkSincErrorEstimateBoundsTheTrueError) {
    Scene scene = MakeScene(R"(
data: {mesh: "builtin:nk-sinc"}
camera: {position: [2.2, 1.6, 2.6], look_at: [0.5, 0.5, 0.5], up: [0, 1, 0], fov_y: 30,
         width: 12, height: 12}
volume:
  color_field: u
  glow: williams-max
  color_tf: [[-1.0, 0.1, 0.2, 0.9], [0.0, 0.9, 0.9, 0.9], [1.0, 1.0, 0.2, 0.1]]
  extinction_tf: [[-0.6, 0.0], [-0.1, 6.0], [0.1, 6.0], [0.6, 0.5]]
)");
    CheckNkSinc(scene, {1e-4, 1e-8}, 1e-18L);
    // A dense sheet (extinction 300 within 0.05 of u = 0, glow model): the attenuation
    // varies inside the cells, so the Kronrod pieces are subdivided to the tolerance.
    // With a transfer-function slope of 6000 per unit of u, the field's rounding bound
    // alone gives about 1e-9 (see VolumeRayMarcher::AddFieldError): tolerances above
    // that.
    scene.volume->glow = GlowModel::WilhelmsVanGelder;
    scene.volume->extinctionTf = {{-0.05, 0.0}, {0.0, 300.0}, {0.05, 0.0}};
    scene.volume->colorTf = {{-0.1, {0.0, 0.5, 2.0}}, {0.1, {3.0, 1.0, 0.0}}};
    CheckNkSinc(scene, {1e-3, 1e-6, 1e-8}, 1e-13L);
}

// Slices of high-order data: the colour is the transfer function of the true field at the
// plane point (nk-sinc's interpolant), composited at the plane's depth.
TEST(VolumeHighOrder, SliceOfNkSincShowsTheInterpolantOnThePlane) {
    const Mesh mesh = MakeBuiltin("builtin:nk-sinc");
    const Scene scene = MakeScene(R"(
data: {mesh: "builtin:nk-sinc"}
camera: {position: [2.2, 1.6, 2.6], look_at: [0.5, 0.5, 0.5], up: [0, 1, 0], fov_y: 30,
         width: 32, height: 32}
slices:
  - {point: [0.5, 0.5, 0.5], normal: [0.2, 1.0, -0.4], field: u,
     color_tf: [[-1.0, 0.0, 0.0, 1.0], [0.0, 1.0, 1.0, 1.0], [1.0, 1.0, 0.0, 0.0]]}
)");
    RenderStats stats;
    const Image image = RenderMeshJob(mesh, scene, stats);
    NkSincTruth truth;
    const Camera camera(scene.camera);
    const RefTf tf = RefTf::Color(scene.slices[0].colorTf);
    int hits = 0;
    for (int j = 0; j < 32; ++j)
        for (int i = 0; i < 32; ++i) {
            const CameraRay r = camera.PixelRay(i, j);
            const double n[3] = {0.2, 1.0, -0.4};
            double nd = 0, off = 0;
            for (int a = 0; a < 3; ++a) {
                nd += n[a] * r.direction[a];
                off += n[a] * (0.5 - r.origin[a]);
            }
            const double t = off / nd;
            LD x[3];
            int box[3];
            bool inside = true, nearFace = false;
            for (int a = 0; a < 3; ++a) {
                x[a] = r.origin[a] + t * r.direction[a];
                inside &= x[a] > 0 && x[a] < 1;
                box[a] = NkSincTruth::Box(double(x[a]));
                for (double b : NkSincTruth::kBreaks)
                    nearFace |= std::abs(x[a] - b) < 1e-9;
            }
            const std::size_t p = std::size_t(j) * 32 + i;
            if (nearFace) continue;
            if (!inside) {
                EXPECT_EQ(image.a[p], 0.0);
                continue;
            }
            ++hits;
            const auto want = tf(truth.Eval(x, box));
            EXPECT_NEAR(image.r[p], double(want[0]), 1e-12) << i << "," << j;
            EXPECT_NEAR(image.g[p], double(want[1]), 1e-12) << i << "," << j;
            EXPECT_NEAR(image.b[p], double(want[2]), 1e-12) << i << "," << j;
        }
    EXPECT_GT(hits, 80);
}

// Slices of curved cells: on isoparametric curved hexes the field u = x is exactly the
// world x coordinate, so the slice colour is the transfer function of x at the plane
// point (found through Newton inversion in the curved cell).
TEST(VolumeHighOrder, SliceOfCurvedCellsIsExact) {
    const Mesh mesh = testing::CurvedHexesWithFieldX(0.08);
    const Scene scene = MakeScene(R"(
data: {mesh: "builtin:nk-sinc"}
camera: {position: [2.2, 1.6, 2.6], look_at: [0.5, 0.5, 0.5], up: [0, 1, 0], fov_y: 30,
         width: 32, height: 32}
slices:
  - {point: [0.5, 0.45, 0.5], normal: [0.3, 1.0, 0.2], field: u,
     color_tf: [[0.0, 0.0, 0.0, 1.0], [1.0, 1.0, 0.5, 0.0]], opacity: 0.7}
)");
    RenderStats stats;
    const Image image = RenderMeshJob(mesh, scene, stats);
    const Camera camera(scene.camera);
    int hits = 0;
    for (int j = 0; j < 32; ++j)
        for (int i = 0; i < 32; ++i) {
            const CameraRay r = camera.PixelRay(i, j);
            const double n[3] = {0.3, 1.0, 0.2}, p0[3] = {0.5, 0.45, 0.5};
            double nd = 0, off = 0;
            for (int a = 0; a < 3; ++a) {
                nd += n[a] * r.direction[a];
                off += n[a] * (p0[a] - r.origin[a]);
            }
            const double t = off / nd;
            double x[3];
            double inside = 1;
            for (int a = 0; a < 3; ++a) {
                x[a] = r.origin[a] + t * r.direction[a];
                inside = std::min({inside, x[a], 1 - x[a]});
            }
            if (std::abs(inside) < 1e-9) continue;
            const std::size_t p = std::size_t(j) * 32 + i;
            if (inside < 0) {
                EXPECT_EQ(image.a[p], 0.0);
                continue;
            }
            ++hits;
            EXPECT_EQ(image.a[p], 0.7);
            EXPECT_NEAR(image.r[p], 0.7 * x[0], 1e-11) << i << "," << j;
            EXPECT_NEAR(image.g[p], 0.7 * 0.5 * x[0], 1e-11) << i << "," << j;
            EXPECT_NEAR(image.b[p], 0.7 * (1 - x[0]), 1e-11) << i << "," << j;
        }
    EXPECT_GT(hits, 300);
    EXPECT_GT(stats.counters.inversions, 0);
    EXPECT_EQ(stats.counters.inversionFailures, 0);
}

}  // namespace
}  // namespace hpray
