// The PNG's annotations against independent truth: the outline's pixels against the box
// edges projected with the camera formulas of docs/contracts.md (and hidden behind an
// analytic sphere), the legend's bar against the colour map it shows, its labels against
// the font; round ticks; ImagePoint as the inverse of the rays.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "image/font.h"
#include "io/image.h"
#include "mesh/builtin.h"
#include "render/annotate.h"
#include "render/render_job.h"
#include "scene/camera.h"
#include "scene/colormaps.h"
#include "scene/scene.h"

namespace hpray {
namespace {

namespace fs = std::filesystem;
using V3 = std::array<double, 3>;

V3 Sub(const V3& a, const V3& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
double Dot(const V3& a, const V3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
V3 Cross(const V3& a, const V3& b) {
    return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0]};
}
V3 Unit(const V3& a) {
    const double n = std::sqrt(Dot(a, a));
    return {a[0] / n, a[1] / n, a[2] / n};
}
V3 Lerp(const V3& a, const V3& b, double s) {
    return {a[0] + s * (b[0] - a[0]), a[1] + s * (b[1] - a[1]), a[2] + s * (b[2] - a[2])};
}

/// The camera of docs/contracts.md, written out again: the test's own truth.
struct ContractCamera {
    V3 position, forward, right, up;
    double W, H, h;
    bool ortho;
    explicit ContractCamera(const SceneCamera& c)
        : position(c.position), W(c.width), H(c.height), ortho(c.orthographic) {
        forward = Unit(Sub(c.lookAt, c.position));
        right = Unit(Cross(forward, c.up));
        up = Cross(right, forward);
        h = ortho ? c.orthoHeight / 2 : std::tan(c.fovYDegrees * M_PI / 360);
    }
    /// The ray through the centre of pixel (i, j).
    void Ray(int i, int j, V3& origin, V3& dir) const {
        const double sx = (2 * (i + 0.5) / W - 1) * (W / H) * h;
        const double sy = (1 - 2 * (j + 0.5) / H) * h;
        if (ortho) {
            for (int k = 0; k < 3; ++k)
                origin[k] = position[k] + sx * right[k] + sy * up[k];
            dir = forward;
        } else {
            origin = position;
            dir = Unit({forward[0] + sx * right[0] + sy * up[0],
                        forward[1] + sx * right[1] + sy * up[1],
                        forward[2] + sx * right[2] + sy * up[2]});
        }
    }
    /// Solves the ray formula for the image point of p (in front of the camera).
    std::array<double, 2> Project(const V3& p) const {
        const V3 d = Sub(p, position);
        double sx = Dot(d, right), sy = Dot(d, up);
        if (!ortho) {
            sx /= Dot(d, forward);
            sy /= Dot(d, forward);
        }
        return {(sx / (h * W / H) + 1) * W / 2, (1 - sy / h) * H / 2};
    }
};

/// A box edge seen by the camera: its part in front of it and the projection of that.
struct Edge {
    V3 a, b;
    std::array<double, 2> pa, pb;
};

/// The 12 edges of [lo, hi]^3, each cut to its part at depth >= minDepth.
std::vector<Edge> BoxEdges(const ContractCamera& cam, double lo, double hi,
                           double minDepth) {
    std::vector<Edge> edges;
    for (int q = 0; q < 8; ++q)
        for (int d = 0; d < 3; ++d) {
            if ((q >> d) & 1) continue;
            V3 a, b;
            for (int k = 0; k < 3; ++k) {
                a[k] = (q >> k) & 1 ? hi : lo;
                b[k] = ((q | (1 << d)) >> k) & 1 ? hi : lo;
            }
            const double za = Dot(Sub(a, cam.position), cam.forward);
            const double zb = Dot(Sub(b, cam.position), cam.forward);
            if (za < minDepth && zb < minDepth) continue;
            if (za < minDepth) a = Lerp(a, b, (minDepth - za) / (zb - za));
            if (zb < minDepth) b = Lerp(a, b, (minDepth - za) / (zb - za));
            edges.push_back({a, b, cam.Project(a), cam.Project(b)});
        }
    return edges;
}

double SegmentDistance(const std::array<double, 2>& a, const std::array<double, 2>& b,
                       double x, double y) {
    const double dx = b[0] - a[0], dy = b[1] - a[1];
    const double l2 = dx * dx + dy * dy;
    const double u =
        l2 > 0 ? std::clamp(((x - a[0]) * dx + (y - a[1]) * dy) / l2, 0.0, 1.0) : 0.0;
    return std::hypot(a[0] + u * dx - x, a[1] + u * dy - y);
}

/// The ray parameter of the edge point nearest the ray (closest points of two lines).
double EdgeT(const Edge& e, const V3& o, const V3& d) {
    const V3 u = Sub(e.b, e.a), w = Sub(o, e.a);
    const double b = Dot(d, u), c = Dot(u, u), dd = Dot(d, w), ee = Dot(u, w);
    const double denom = c - b * b;  // |d| = 1
    const double t = denom > 1e-15 ? (b * ee - c * dd) / denom : -dd;
    return t;
}

/// The parameters t >= 0 where a ray crosses the sphere |x| = R (none, or both).
std::vector<double> SphereCrossings(const V3& o, const V3& d, double R) {
    const double b = Dot(o, d), c = Dot(o, o) - R * R, disc = b * b - c;
    if (R <= 0 || disc <= 0) return {};
    std::vector<double> ts;
    for (const double t : {-b - std::sqrt(disc), -b + std::sqrt(disc)})
        if (t >= 0) ts.push_back(t);
    return ts;
}

double Srgb(double linear) { return LinearToSrgb(linear) * 255; }
/// The linear value of an 8-bit sRGB sample.
double Linear(std::uint8_t v) {
    const double c = v / 255.0;
    return c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4);
}

struct Png {
    int width = 0, height = 0;
    std::vector<std::uint8_t> rgb;
    const std::uint8_t* At(int i, int j) const {
        return &rgb[3 * (std::size_t(j) * width + i)];
    }
};

/// Renders `yaml` (ball-p2: u = |x|^2 on [-1, 1]^3) to a PNG and reads it back; the
/// image rendered into `rendered` if given.
Png RenderPng(const std::string& yaml, const std::string& name,
              Image* rendered = nullptr) {
    const fs::path dir = fs::temp_directory_path() / "hpray_test_annotate";
    fs::create_directories(dir);
    const std::string path = (dir / (name + ".png")).string();
    Scene scene = ParseScene(yaml + "output: {png: " + path + "}\n", "test.yaml", {}, "");
    RenderStats stats;
    Image image = RenderMeshJob(MakeBuiltin("builtin:ball-p2"), scene, stats);
    if (rendered) *rendered = std::move(image);
    Png png;
    ReadPng(path, png.width, png.height, png.rgb);
    fs::remove(path);
    return png;
}

/// The outline (red, 1.5 px) against the projected edges of [-1, 1]^3, with a sphere
/// |x| = R of the given opacity inside (R = 0: none), as a line at the edge's depth
/// composites with the surfaces: pixels beyond 2 px of every edge are as without the
/// outline; at a pixel near one edge (within 1.3 px, none other), with the sphere's k
/// crossings in front of the edge and none behind it, the line is seen through them by
/// T = (1 - opacity)^k in place of the white background (G falls by coverage * T, and
/// by at least 0.75 T within 0.5 px; nothing changes where T = 0), and with none in front
/// it is drawn over the picture (G falls to at most a quarter within 0.5 px). Returns
/// how many pixels near hidden or dimmed edges were checked.
int CheckOutline(const std::string& camera, double R, const std::string& name,
                 double opacity = 1) {
    const std::string base =
        "data: {mesh: 'builtin:ball-p2'}\ncamera: " + camera + "\n" +
        (R > 0 ? "isosurfaces: [{field: u, value: " + std::to_string(R * R) +
                     ", opacity: " + std::to_string(opacity) + "}]\n"
               : "");
    const Png plain = RenderPng(base, name + "_plain");
    const Png lined = RenderPng(base + "outline: {color: [1, 0, 0], width: 1.5}\n", name);
    const Scene scene = ParseScene(base, "test.yaml", {}, "");
    const ContractCamera cam(scene.camera);
    // The edges' parts at least 1e-6 in front of the camera (the renderer cuts at 1e-9
    // of its distance; what lies between projects far outside the image).
    const std::vector<Edge> edges = BoxEdges(cam, -1, 1, 1e-6);
    EXPECT_EQ(lined.width, scene.camera.width);
    const double tol = 0.012;  // linear, above 8-bit rounding
    int seen = 0, far = 0, behind = 0;
    for (int j = 0; j < lined.height; ++j)
        for (int i = 0; i < lined.width; ++i) {
            V3 o, d;
            cam.Ray(i, j, o, d);
            const std::vector<double> crossings = SphereCrossings(o, d, R);
            double nearest = 1e300, dist = 0, tEdge = 0;
            int near = 0;
            for (const Edge& e : edges) {
                const double de = SegmentDistance(e.pa, e.pb, i + 0.5, j + 0.5);
                nearest = std::min(nearest, de);
                if (de > 1.3) continue;
                ++near;
                dist = de;
                tEdge = EdgeT(e, o, d);
            }
            const std::uint8_t* p = lined.At(i, j);
            const std::uint8_t* q = plain.At(i, j);
            const std::string where =
                name + ": pixel (" + std::to_string(i) + ", " + std::to_string(j) + ")";
            if (nearest > 2.0) {
                EXPECT_TRUE(p[0] == q[0] && p[1] == q[1] && p[2] == q[2])
                    << where << " at " << nearest << " px from the outline changed";
                ++far;
                continue;
            }
            if (near != 1) continue;
            int inFront = 0, inBack = 0;
            bool clear = true;
            for (const double t : crossings) {
                clear &= std::fabs(t - tEdge) > 0.15;
                (t < tEdge ? inFront : inBack) += 1;
            }
            if (!clear) continue;
            const double g = Linear(p[1]), plainG = Linear(q[1]);
            if (inFront == 0) {
                if (dist > 0.5) continue;
                EXPECT_LE(g, 0.25 * plainG + tol)
                    << where << " on the outline, not red enough";
                EXPECT_GE(p[0] + 1, q[0]) << where;
                ++seen;
            } else if (inBack == 0) {
                const double T = std::pow(1 - opacity, inFront);
                if (T == 0) {
                    EXPECT_TRUE(p[0] == q[0] && p[1] == q[1] && p[2] == q[2])
                        << where << ": an edge behind an opaque surface shows";
                } else {
                    EXPECT_GE(g, plainG - T - tol) << where;
                    EXPECT_LE(g, plainG + tol) << where;
                    if (dist <= 0.5) {
                        EXPECT_LE(g, plainG - 0.75 * T + tol) << where;
                    }
                }
                ++behind;
            }
        }
    EXPECT_GT(seen, 200) << name;
    EXPECT_GT(far, lined.width * lined.height / 2) << name;
    std::printf("%s: %d pixels on seen edges, %d near edges behind the sphere, %d far\n",
                name.c_str(), seen, behind, far);
    return behind;
}

TEST(OutlineTest, PerspectivePixelsFollowTheProjectedEdges) {
    CheckOutline(
        "{position: [2.6, 1.9, 3.4], look_at: [0, 0, 0], fov_y: 40, width: 160, "
        "height: 120}",
        0, "perspective");
}

TEST(OutlineTest, OrthographicPixelsFollowTheProjectedEdges) {
    CheckOutline(
        "{position: [3, -2, 2.5], look_at: [0, 0, 0], up: [0, 0, 1], "
        "ortho_height: 4, width: 150, height: 130}",
        0, "ortho");
}

// The eye inside the box: edges that pass beside and behind it are cut at its plane.
TEST(OutlineTest, EdgesBehindThePerspectiveEyeAreCut) {
    CheckOutline(
        "{position: [0.3, 0.2, 0.4], look_at: [-0.5, -0.6, -1], fov_y: 90, "
        "width: 140, height: 100}",
        0, "inside");
}

// Behind an opaque isosurface (the sphere u = 0.81) the far edges are hidden, in front
// of it the near ones drawn over it.
TEST(OutlineTest, EdgesBehindAnOpaqueIsosurfaceAreHidden) {
    const int hidden = CheckOutline(
        "{position: [2.2, 1.3, 2.8], look_at: [0, 0, 0], fov_y: 45, width: 200, "
        "height: 160}",
        0.9, "sphere");
    EXPECT_GT(hidden, 20);
}

// Behind a translucent isosurface the far edges show through it, by 1 - its opacity.
TEST(OutlineTest, EdgesBehindATranslucentIsosurfaceShowThroughIt) {
    const int hidden = CheckOutline(
        "{position: [2.2, 1.3, 2.8], look_at: [0, 0, 0], fov_y: 45, width: 200, "
        "height: 160}",
        0.9, "translucent", 0.4);
    EXPECT_GT(hidden, 10);
}

/// Where the ray enters the box [lo, hi]^3 (slab method), or +inf if it misses it.
double BoxEntry(const V3& o, const V3& d, double lo, double hi) {
    double tIn = 0, tOut = 1e300;
    for (int k = 0; k < 3; ++k) {
        if (d[k] == 0) {
            if (o[k] < lo || o[k] > hi) return 1e300;
            continue;
        }
        const double a = (lo - o[k]) / d[k], b = (hi - o[k]) / d[k];
        tIn = std::max(tIn, std::min(a, b));
        tOut = std::min(tOut, std::max(a, b));
    }
    return tIn <= tOut ? tIn : 1e300;
}

// A volume fills the box: an edge where the rays leave the box is seen through all of it
// (by 1 - alpha of the pixel, in place of the background), one where they enter it is
// drawn over it.
TEST(OutlineTest, EdgesBehindAVolumeAreSeenThroughIt) {
    const std::string base =
        "data: {mesh: 'builtin:ball-p2'}\n"
        "camera: {position: [2.4, 1.6, 3.1], look_at: [0, 0, 0], fov_y: 45, width: 180, "
        "height: 150}\nvolume: {color_field: u, extinction_tf: [[0, 0.6], [3, 0.6]]}\n";
    Image image;
    const Png plain = RenderPng(base, "volume_plain", &image);
    const Png lined = RenderPng(base + "outline: {color: [1, 0, 0]}\n", "volume");
    const ContractCamera cam(ParseScene(base, "t.yaml", {}, "").camera);
    const std::vector<Edge> edges = BoxEdges(cam, -1, 1, 1e-6);
    const double tol = 0.012;
    int over = 0, under = 0;
    for (int j = 0; j < lined.height; ++j)
        for (int i = 0; i < lined.width; ++i) {
            V3 o, d;
            cam.Ray(i, j, o, d);
            int near = 0;
            double dist = 0, tEdge = 0;
            for (const Edge& e : edges) {
                const double de = SegmentDistance(e.pa, e.pb, i + 0.5, j + 0.5);
                if (de > 1.3) continue;
                ++near;
                dist = de;
                tEdge = EdgeT(e, o, d);
            }
            if (near != 1 || dist > 0.5) continue;
            const double tIn = BoxEntry(o, d, -1, 1);
            const double g = Linear(lined.At(i, j)[1]),
                         plainG = Linear(plain.At(i, j)[1]);
            const std::string where =
                "pixel (" + std::to_string(i) + ", " + std::to_string(j) + ")";
            if (std::fabs(tEdge - tIn) < 0.02) {
                EXPECT_LE(g, 0.25 * plainG + tol)
                    << where << ": an edge in front, not drawn over";
                ++over;
            } else if (tEdge > tIn + 0.3) {
                const double T = 1 - image.a[std::size_t(j) * image.width + i];
                EXPECT_GT(T, 0.05) << where;
                EXPECT_LE(T, 0.95) << where;
                EXPECT_GE(g, plainG - T - tol) << where;
                EXPECT_LE(g, plainG - 0.75 * T + tol) << where << ": an edge behind";
                ++under;
            }
        }
    EXPECT_GT(over, 100);
    EXPECT_GT(under, 50);
}

TEST(OutlineTest, ImagePointInvertsTheRays) {
    std::mt19937 rng(5);
    std::uniform_real_distribution<double> unit(0, 1);
    for (const bool ortho : {false, true}) {
        SceneCamera c;
        c.position = {1.5, -2, 3};
        c.lookAt = {0.1, 0.2, -0.3};
        c.up = {0.2, 1, 0.1};
        c.width = 301;
        c.height = 173;
        c.orthographic = ortho;
        c.orthoHeight = 2.5;
        const Camera camera(c);
        for (int k = 0; k < 100; ++k) {
            const double x = unit(rng) * c.width, y = unit(rng) * c.height;
            const CameraRay ray = camera.RayAt(x, y);
            const double t = 0.5 + 5 * unit(rng);
            const V3 p = {ray.origin[0] + t * ray.direction[0],
                          ray.origin[1] + t * ray.direction[1],
                          ray.origin[2] + t * ray.direction[2]};
            const auto xy = camera.ImagePoint(p);
            EXPECT_NEAR(xy[0], x, 1e-9);
            EXPECT_NEAR(xy[1], y, 1e-9);
            EXPECT_NEAR(camera.RayParameter(p), t, 1e-12);
        }
    }
}

// The outline's box is the data's cut to the clip box.
TEST(OutlineTest, TheClipBoxCutsTheOutlinedBox) {
    Scene scene =
        ParseScene("data: {mesh: m.vtu}\nclip: {box: [[0, -5, 0], [5, 0.5, 5]]}\n",
                   "t.yaml", {}, "/");
    const Box data{{-1, -1, -1}, {1, 1, 1}};
    const Box box = OutlineBox(scene, data);
    EXPECT_EQ(box.lo, (V3{0, -1, 0}));
    EXPECT_EQ(box.hi, (V3{1, 0.5, 1}));
    scene.clip.box = Box{{3, 3, 3}, {4, 4, 4}};  // apart from the data: the clip box
    EXPECT_EQ(OutlineBox(scene, data).lo, (V3{3, 3, 3}));
    scene.clip.box.reset();
    EXPECT_EQ(OutlineBox(scene, data).hi, (V3{1, 1, 1}));
}

TEST(LegendTest, TicksAreThreeToFiveRoundValues) {
    std::mt19937 rng(11);
    std::uniform_real_distribution<double> unit(0, 1);
    for (int k = 0; k < 2000; ++k) {
        const double scale = std::pow(10.0, -8 + 16 * unit(rng));
        const double lo = (unit(rng) * 2 - 1) * scale;
        const double hi =
            lo + scale * std::pow(10.0, -3 * unit(rng)) * (0.01 + unit(rng));
        const std::vector<double> ticks = NiceTicks(lo, hi);
        ASSERT_GE(ticks.size(), 3u) << lo << " " << hi;
        ASSERT_LE(ticks.size(), 5u) << lo << " " << hi;
        const double step = ticks[1] - ticks[0];
        const double e = std::floor(std::log10(step) + 1e-9);
        const double m = step / std::pow(10.0, e);
        EXPECT_TRUE(std::fabs(m - 1) < 1e-6 || std::fabs(m - 2) < 1e-6 ||
                    std::fabs(m - 2.5) < 1e-6 || std::fabs(m - 5) < 1e-6)
            << step;
        // Labels tell the ticks apart.
        for (std::size_t i = 1; i < ticks.size(); ++i)
            EXPECT_NE(
                TickLabel(ticks[i], step, std::max(std::fabs(lo), std::fabs(hi))),
                TickLabel(ticks[i - 1], step, std::max(std::fabs(lo), std::fabs(hi))));
        for (std::size_t i = 0; i < ticks.size(); ++i) {
            EXPECT_GE(ticks[i], lo - 1e-9 * (hi - lo));
            EXPECT_LE(ticks[i], hi + 1e-9 * (hi - lo));
            const double multiple = ticks[i] / step;
            EXPECT_NEAR(multiple, std::round(multiple), 1e-6);
            if (i > 0) {
                EXPECT_NEAR(ticks[i] - ticks[i - 1], step, 1e-9 * step);
            }
        }
    }
    EXPECT_EQ(NiceTicks(0, 1), (std::vector<double>{0, 0.5, 1}));
    EXPECT_EQ(NiceTicks(0, 2), (std::vector<double>{0, 1, 2}));
    EXPECT_EQ(NiceTicks(-3, 3), (std::vector<double>{-2, 0, 2}));
    EXPECT_EQ(NiceTicks(0, 7), (std::vector<double>{0, 2, 4, 6}));
    EXPECT_EQ(NiceTicks(0.1, 11.6), (std::vector<double>{2, 4, 6, 8, 10}));
    EXPECT_EQ(NiceTicks(0.1, 12.1), (std::vector<double>{2.5, 5, 7.5, 10}));
}

TEST(LegendTest, TickLabels) {
    EXPECT_EQ(TickLabel(0, 0.5, 1), "0");
    EXPECT_EQ(TickLabel(0.5, 0.5, 1), "0.5");
    EXPECT_EQ(TickLabel(-0.2, 0.2, 1), "-0.2");
    EXPECT_EQ(TickLabel(2, 1, 2), "2");
    EXPECT_EQ(TickLabel(0.30000000000000004, 0.1, 1), "0.3");
    EXPECT_EQ(TickLabel(1250, 50, 1300), "1250");
    EXPECT_EQ(TickLabel(150000, 50000, 3e5), "1.5e5");
    EXPECT_EQ(TickLabel(2e-5, 1e-5, 3e-5), "2e-5");
    EXPECT_EQ(TickLabel(-1.2e-4, 2e-5, 2e-4), "-1.2e-4");
    EXPECT_EQ(TickLabel(7.5, 2.5, 11.6), "7.5");
    EXPECT_EQ(TickLabel(0.75, 0.25, 1), "0.75");
    EXPECT_EQ(TickLabel(7.5e5, 2.5e5, 1e6), "7.5e5");
    EXPECT_EQ(TickLabel(1e6, 2.5e5, 1e6), "1e6");
    EXPECT_EQ(TickLabel(1.25e-4, 2.5e-5, 2e-4), "1.25e-4");
}

// A slice coloured by viridis over [0, 2]: the bar shows the map at its rows' values, the
// labels are the font's glyphs at the ticks of [0, 2], the title is drawn.
TEST(LegendTest, BarShowsTheColorMapAndLabelsAreDrawn) {
    const std::string yaml =
        "data: {mesh: 'builtin:ball-p2'}\n"
        "camera: {position: [0, 0, 5], look_at: [0, 0, 0], width: 420, height: 300}\n"
        "slices: [{point: [0, 0, 0], normal: [0, 0, 1], field: u,\n"
        "          color_tf: {map: viridis, range: [0, 2]}}]\n"
        "background: [1, 1, 1]\nlegend: true\n";
    const Png png = RenderPng(yaml, "legend");
    const LegendLayout layout = LayOutLegend(ParseScene(yaml, "t.yaml", {}, ""));
    ASSERT_EQ(layout.bars.size(), 1u);
    EXPECT_EQ(layout.omitted, 0);
    const LegendBar& bar = layout.bars[0];
    EXPECT_EQ(bar.title, "u");
    ASSERT_GE(bar.x, 0);
    ASSERT_LE(bar.x + bar.width, png.width);
    ASSERT_GE(bar.y, 0);
    ASSERT_LE(bar.y + bar.height, png.height);
    EXPECT_GE(bar.height, 100);

    // The map's own control points, interpolated here: the colour at each row's value.
    const std::vector<ColorControlPoint> map = ExpandColorMap("viridis", 0, 2);
    auto truth = [&](double v) {
        std::size_t k = 0;
        while (k + 2 < map.size() && v > map[k + 1].scalar) ++k;
        const double s = std::clamp(
            (v - map[k].scalar) / (map[k + 1].scalar - map[k].scalar), 0.0, 1.0);
        std::array<double, 3> c;
        for (int i = 0; i < 3; ++i)
            c[i] = map[k].rgb[i] + s * (map[k + 1].rgb[i] - map[k].rgb[i]);
        return c;
    };
    for (int k = 0; k < bar.height; k += std::max(1, bar.height / 9)) {
        const double v = 2 - (k + 0.5) / bar.height * 2;
        const auto c = truth(v);
        for (int i = bar.x; i < bar.x + bar.width; ++i) {
            const std::uint8_t* p = png.At(i, bar.y + k);
            for (int ch = 0; ch < 3; ++ch)
                EXPECT_NEAR(p[ch], Srgb(c[ch]), 0.51 + 1e-9)
                    << "bar row " << k << " (value " << v << ") column " << i;
        }
    }
    // The bottom and top rows hold the ends of the map.
    EXPECT_NEAR(png.At(bar.x, bar.y + bar.height - 1)[2],
                Srgb(truth(1.0 / bar.height)[2]), 0.51);

    // Ticks at 0, 1, 2, each label the font's glyphs in black at its box.
    ASSERT_EQ(bar.ticks.size(), 3u);
    const char* labels[] = {"0", "1", "2"};
    for (std::size_t t = 0; t < 3; ++t) {
        const LegendBar::Tick& tick = bar.ticks[t];
        EXPECT_EQ(tick.label, labels[t]);
        EXPECT_EQ(tick.row,
                  bar.y + std::min(bar.height - 1,
                                   int(std::floor((2 - tick.value) / 2 * bar.height))));
        const std::uint8_t* glyph = font::Glyph(tick.label[0]);
        int ink = 0, paper = 0;
        for (int r = 0; r < font::kGlyphHeight; ++r)
            for (int c = 0; c < font::kGlyphWidth; ++c) {
                const std::uint8_t* p = png.At(tick.labelX + c, tick.labelY + r);
                if ((glyph[r] >> (font::kGlyphWidth - 1 - c)) & 1) {
                    EXPECT_TRUE(p[0] == 0 && p[1] == 0 && p[2] == 0)
                        << "label " << tick.label << " pixel (" << c << ", " << r << ")";
                    ++ink;
                } else {
                    EXPECT_GT(p[0] + p[1] + p[2], 3 * 100) << "label " << tick.label;
                    ++paper;
                }
            }
        EXPECT_GT(ink, 5);
        EXPECT_GT(paper, 5);
        // The tick mark: black, right of the bar.
        const std::uint8_t* mark = png.At(bar.x + bar.width + 1, tick.row);
        EXPECT_TRUE(mark[0] == 0 && mark[1] == 0 && mark[2] == 0) << tick.label;
    }
    int titleInk = 0;
    for (int r = 0; r < font::kGlyphHeight; ++r)
        for (int c = 0; c < font::kGlyphWidth; ++c) {
            const std::uint8_t* p = png.At(bar.titleX + c, bar.titleY + r);
            titleInk += p[0] == 0 && p[1] == 0 && p[2] == 0;
        }
    EXPECT_GT(titleInk, 5);

    // Without `legend` the PNG differs exactly inside the panel.
    std::string plainYaml = yaml;
    plainYaml.replace(plainYaml.find("legend: true"), 12, "legend: false");
    const Png plain = RenderPng(plainYaml, "legend_plain");
    int changedOutside = 0, changedInside = 0;
    for (int j = 0; j < png.height; ++j)
        for (int i = 0; i < png.width; ++i) {
            const bool inside = i >= bar.panelX && i < bar.panelX + bar.panelWidth &&
                                j >= bar.panelY && j < bar.panelY + bar.panelHeight;
            const bool changed = std::memcmp(png.At(i, j), plain.At(i, j), 3) != 0;
            (inside ? changedInside : changedOutside) += changed;
        }
    EXPECT_EQ(changedOutside, 0);
    EXPECT_GT(changedInside, bar.width * bar.height);
}

// One bar per distinct field and map; bars that do not fit a small image are left out.
TEST(LegendTest, OneBarPerColouredFieldAndOnlyWhatFits) {
    const std::string base =
        "data: {mesh: 'builtin:ball-p2'}\ncamera: {width: 600, height: 400}\nlegend: "
        "true\n"
        "slices: [{normal: [0, 0, 1], point: [0, 0, 0], field: u, color_tf: {map: "
        "viridis, "
        "range: [0, 3]}},\n"
        "         {normal: [0, 1, 0], point: [0, 0, 0], field: u, color_tf: {map: "
        "viridis, "
        "range: [0, 3]}},\n"
        "         {normal: [1, 0, 0], point: [0, 0, 0], field: v, color_tf: [[-1, 0, 0, "
        "1], "
        "[1, 1, 0, 0]]}]\n"
        "isosurfaces: [{value: 0.5, color_field: v, color_tf: {map: inferno, range: [-1, "
        "1]}}]\n";
    const LegendLayout layout = LayOutLegend(ParseScene(base, "t.yaml", {}, ""));
    ASSERT_EQ(layout.bars.size(), 3u);
    EXPECT_EQ(layout.bars[0].title, "v (isosurface)");  // the isosurface's first
    EXPECT_EQ(layout.bars[1].title, "u");
    EXPECT_EQ(layout.bars[2].title, "v (slice)");
    for (std::size_t k = 1; k < layout.bars.size(); ++k)
        EXPECT_LT(layout.bars[k].panelX + layout.bars[k].panelWidth,
                  layout.bars[k - 1].panelX);
    const LegendLayout small = LayOutLegend(
        ParseScene(base + "", "t.yaml", {"camera.width=90", "camera.height=90"}, ""));
    EXPECT_EQ(small.bars.size() + small.omitted, 3u);
    EXPECT_GT(small.omitted, 0);
}

}  // namespace
}  // namespace hpray
