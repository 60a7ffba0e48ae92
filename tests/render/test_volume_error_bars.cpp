// vol.error as an error bar, on the scene of configs/volume_nk_sinc.yaml (nk-sinc, order-8
// hexahedra, a thin dense sheet about u = 0) at 48^2 and volume_tolerance 1e-4, 1e-6 and
// 1e-8. The truth is the pixel of the exact field (the interpolant of the mesh's nodal
// values, evaluated in long double) by testing::NkSincSeriesReference: the field's exact
// series along each cell segment, the optical depth in closed form, the emission by
// bisected 48- and 64-node Gauss-Legendre quadrature agreeing to 1e-18 relative; it is
// checked here against the ODE reference (testing::ReferenceRay, Bulirsch-Stoer in long
// double, which the other volume tests check against closed forms) on a few pixels.
// Required: vol.error bounds the true RGB error on every pixel; it is within 100x of the
// true error (or of 1e-14, whichever is larger) on 99% of the pixels the volume touches;
// and a looser tolerance does measurably less work (quadrature nodes in the stats).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "mesh/builtin.h"
#include "render/render_job.h"
#include "render/test_volume_reference.h"
#include "scene/camera.h"
#include "scene/scene.h"

namespace hpray {
namespace {

using testing::LD;
using testing::NkSincTruth;
using testing::RefPixel;
using testing::RefTf;

const char* kScene = R"(
data: {mesh: "builtin:nk-sinc"}
camera: {position: [2.2, 1.6, 2.6], look_at: [0.5, 0.5, 0.5], up: [0, 1, 0], fov_y: 30,
         width: 48, height: 48}
volume:
  color_field: u
  glow: williams-max
  color_tf: [[-1.0, 0.1, 0.2, 0.9], [-0.2, 0.2, 0.7, 1.0], [0.0, 1.0, 1.0, 1.0],
             [0.3, 1.0, 0.7, 0.1], [1.0, 0.9, 0.1, 0.1]]
  extinction_tf: [[-0.8, 0.0], [-0.3, 1.5], [-0.05, 0.3], [0.0, 25.0], [0.05, 0.3],
                  [0.6, 4.0]]
)";

struct Reference {
    std::vector<RefPixel> pixels;
    std::vector<char> inside;  ///< the ray crosses the data
};

Reference MakeReference(const Scene& scene) {
    NkSincTruth truth;
    const Camera camera(scene.camera);
    const RefTf ctf = RefTf::Color(scene.volume->colorTf);
    const RefTf etf = RefTf::Extinction(scene.volume->extinctionTf);
    const bool wm = scene.volume->glow == GlowModel::WilliamsMax;
    Reference r;
    const int w = scene.camera.width, h = scene.camera.height;
    r.pixels.resize(std::size_t(w) * h);
    r.inside.assign(std::size_t(w) * h, 0);
    for (int j = 0; j < h; ++j)
        for (int i = 0; i < w; ++i) {
            const CameraRay cr = camera.PixelRay(i, j);
            LD t0, t1;
            const std::size_t p = std::size_t(j) * w + i;
            if (!testing::RefBoxChord(cr.origin, cr.direction, {0, 0, 0}, {1, 1, 1}, t0, t1))
                continue;
            r.inside[p] = 1;
            r.pixels[p] = testing::NkSincSeriesReference(truth, cr.origin, cr.direction, ctf,
                                                         etf, wm);
        }
    return r;
}

double TrueError(const Image& image, std::size_t p, const RefPixel& ref) {
    const double got[3] = {image.r[p], image.g[p], image.b[p]};
    double err = 0;
    for (int c = 0; c < 3; ++c) err = std::max(err, double(std::abs(got[c] - ref.rgb[c])));
    return err;
}

TEST(VolumeErrorBars, SeriesReferenceAgreesWithTheOdeReference) {
    const Scene scene = ParseScene(kScene, "test.yaml", {}, "");
    NkSincTruth truth;
    const Camera camera(scene.camera);
    const RefTf ctf = RefTf::Color(scene.volume->colorTf);
    const RefTf etf = RefTf::Extinction(scene.volume->extinctionTf);
    int checked = 0;
    for (const auto& [i, j] : std::vector<std::pair<int, int>>{
             {24, 24}, {10, 30}, {30, 12}, {20, 38}, {36, 26}}) {
        const CameraRay cr = camera.PixelRay(i, j);
        LD t0, t1;
        ASSERT_TRUE(testing::RefBoxChord(cr.origin, cr.direction, {0, 0, 0}, {1, 1, 1}, t0,
                                         t1));
        // The ODE reference with the cuts at the box faces and the breakpoint crossings.
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
            std::array<int, 3> box;
            for (int a = 0; a < 3; ++a)
                box[a] = NkSincTruth::Box(
                    double(cr.origin[a] + (cuts[k] + cuts[k + 1]) / 2 * cr.direction[a]));
            boxes.push_back(box);
        }
        auto field = [&](LD t) {
            const auto it = std::upper_bound(cuts.begin(), cuts.end(), t);
            const std::size_t k = std::min<std::size_t>(
                std::max<std::ptrdiff_t>(it - cuts.begin(), 1), cuts.size() - 1);
            LD x[3];
            for (int a = 0; a < 3; ++a) x[a] = cr.origin[a] + t * cr.direction[a];
            return truth.Eval(x, boxes[k - 1].data());
        };
        std::vector<LD> kinks(cuts.begin(), cuts.end());
        for (std::size_t k = 0; k + 1 < cuts.size(); ++k)
            for (const RefTf* tf : {&ctf, &etf})
                for (LD level : tf->scalars)
                    testing::SampledCrossings(field, cuts[k] + 1e-15L, cuts[k + 1] - 1e-15L,
                                              level, 64, kinks);
        const RefPixel ode = testing::ReferenceRay(t0, t1, field, field, ctf, etf, true,
                                                   kinks, {}, 1e-18L);
        const RefPixel series =
            testing::NkSincSeriesReference(truth, cr.origin, cr.direction, ctf, etf, true);
        for (int c = 0; c < 3; ++c)
            EXPECT_NEAR(double(series.rgb[c]), double(ode.rgb[c]), 1e-16) << i << "," << j;
        EXPECT_NEAR(double(series.alpha), double(ode.alpha), 1e-16) << i << "," << j;
        EXPECT_GT(double(series.alpha), 0.01);
        ++checked;
    }
    EXPECT_EQ(checked, 5);
}

TEST(VolumeErrorBars, BoundOnEveryPixelAndWithin100xOfTheTrueError) {
    const Mesh mesh = MakeBuiltin("builtin:nk-sinc");
    Scene scene = ParseScene(kScene, "test.yaml", {}, "");
    const Reference ref = MakeReference(scene);
    double nodes[3] = {0, 0, 0};
    const double tolerances[3] = {1e-4, 1e-6, 1e-8};
    for (int k = 0; k < 3; ++k) {
        const double tolerance = tolerances[k];
        scene.accuracy.volumeTolerance = tolerance;
        RenderStats stats;
        const Image image = RenderMeshJob(mesh, scene, stats);
        nodes[k] = stats.counters.volumeNodes;
        int touched = 0, bounded = 0, sharp = 0;
        double minRatio = 1e300;
        std::vector<double> ratios;
        double maxTrue = 0, maxClaim = 0;
        for (std::size_t p = 0; p < image.volError.size(); ++p) {
            if (!ref.inside[p] || image.volError[p] == 0) continue;
            ++touched;
            const double err = TrueError(image, p, ref.pixels[p]);
            const double claim = image.volError[p];
            // The reference carries about 1e-19 of its own.
            const bool ok = err <= claim + 1e-18;
            bounded += ok;
            EXPECT_TRUE(ok) << "pixel " << p << " true " << err << " claimed " << claim
                            << " at tolerance " << tolerance;
            sharp += claim <= 100 * std::max(err, 1e-14);
            if (err > 0) minRatio = std::min(minRatio, claim / err);
            ratios.push_back(claim / std::max(err, 1e-14));
            maxTrue = std::max(maxTrue, err);
            maxClaim = std::max(maxClaim, claim);
        }
        ASSERT_GT(touched, 1000);
        EXPECT_EQ(bounded, touched) << "tolerance " << tolerance;
        EXPECT_GE(sharp, 0.99 * touched) << "tolerance " << tolerance;
        EXPECT_LE(maxClaim, tolerance);
        EXPECT_LE(maxTrue, tolerance);
        EXPECT_EQ(stats.counters.rootFailures, 0);
        std::sort(ratios.begin(), ratios.end());
        std::printf("tolerance %g: %d pixels, true max %.3g, claimed max %.3g, within 100x "
                    "%.4f, quadrature nodes %.0f; claimed / true: min %.3g, median %.3g, 99%% "
                    "%.3g, max %.3g\n",
                    tolerance, touched, maxTrue, maxClaim, double(sharp) / touched, nodes[k],
                    minRatio, ratios[ratios.size() / 2], ratios[ratios.size() * 99 / 100],
                    ratios.back());
    }
    // A looser tolerance buys speed: fewer integrand samples.
    EXPECT_LT(nodes[0], 0.75 * nodes[2]);
    EXPECT_LT(nodes[0], nodes[1]);
    EXPECT_LT(nodes[1], nodes[2]);
}

}  // namespace
}  // namespace hpray
