// What a newcomer gets without tuning: the automatic camera frames every real mesh of
// ../shared/data, and a volume given only its field is neither faint nor opaque.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <set>
#include <string>
#include <vector>

#include "elements/mesh_geometry.h"
#include "io/mesh_io.h"
#include "mesh/builtin.h"
#include "render/render_job.h"
#include "scene/camera.h"
#include "scene/colormaps.h"
#include "scene/scene.h"

namespace hpray {
namespace {

namespace fs = std::filesystem;
using Vec3 = std::array<double, 3>;

double Dot(const Vec3& a, const Vec3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

/// Where the camera images world point `p`: the continuous image point (x from the left
/// edge, y from the top, in pixels) whose ray Camera::RayAt passes through p, and the
/// depth of p along the view direction. The inverse of docs/contracts.md's ray generation;
/// the caller checks it against RayAt.
struct Projected {
    double x = 0, y = 0, depth = 0;
};

Projected Project(const Camera& camera, const SceneCamera& settings, const Vec3& p) {
    const double w = camera.Width(), h = camera.Height(), aspect = w / h;
    Vec3 d;
    for (int k = 0; k < 3; ++k) d[k] = p[k] - camera.Position()[k];
    Projected out;
    out.depth = Dot(d, camera.Forward());
    double sx = Dot(d, camera.Right()), sy = Dot(d, camera.TrueUp()), half;
    if (camera.Orthographic()) {
        half = settings.orthoHeight / 2;
    } else {
        half = std::tan(settings.fovYDegrees * M_PI / 360);
        sx /= out.depth;
        sy /= out.depth;
    }
    out.x = (sx / (aspect * half) + 1) * w / 2;
    out.y = (1 - sy / half) * h / 2;
    return out;
}

/// The distance of p from the ray, relative to the distance of p from its origin.
double MissRelative(const CameraRay& ray, const Vec3& p) {
    Vec3 d;
    for (int k = 0; k < 3; ++k) d[k] = p[k] - ray.origin[k];
    const double along = Dot(d, ray.direction);
    Vec3 off;
    for (int k = 0; k < 3; ++k) off[k] = d[k] - along * ray.direction[k];
    return std::sqrt(Dot(off, off)) / std::sqrt(Dot(d, d));
}

std::vector<fs::path> SharedMeshes() {
    std::vector<fs::path> files;
    const fs::path dir(HPRAY_SHARED_DATA);
    if (!fs::is_directory(dir)) return files;
    for (const auto& entry : fs::directory_iterator(dir)) {
        const std::string ext = entry.path().extension().string();
        if (ext == ".vtu" || ext == ".msh") files.push_back(entry.path());
    }
    std::sort(files.begin(), files.end());
    return files;
}

// For every mesh of the shared data that hpray reads, the automatic camera of a scene that
// gives none (and of views from +x and -z, and a wide image) is fitted to the bounds the
// renderer fits (MeshGeometry's guaranteed box): all 8 corners of the box project inside
// the image, in front of the eye, and the projected box spans at least 60% of the image's
// width or height. The projection is checked against the renderer's own rays (RayAt
// through each projected corner passes through the corner).
TEST(AutoView, FramesEverySharedMesh) {
    const std::vector<fs::path> meshes = SharedMeshes();
    if (meshes.empty()) GTEST_SKIP() << "no shared data at " << HPRAY_SHARED_DATA;
    const std::vector<std::string> cameras = {"", "camera: {view: +x}\n",
                                              "camera: {view: -z}\n",
                                              "camera: {width: 640, height: 360}\n"};
    ReadOptions noFields;
    noFields.fields = std::set<std::string>{};
    int checked = 0;
    for (const fs::path& path : meshes) {
        const Mesh mesh = ReadMesh(path.string(), noFields);
        const Box box = MeshGeometry::Build(mesh).bounds;
        for (const std::string& cam : cameras) {
            Scene scene =
                ParseScene("data: {mesh: " + path.string() + "}\n" + cam, "auto_view.yaml");
            ASSERT_TRUE(scene.camera.autoFit) << cam;
            FitCamera(scene.camera, box, scene.clip.box);
            const Camera camera(scene.camera);
            const double W = camera.Width(), H = camera.Height();
            const std::string what = path.filename().string() + " " +
                                     (cam.empty() ? std::string("default camera") : cam);
            double x0 = W, x1 = 0, y0 = H, y1 = 0;
            for (int q = 0; q < 8; ++q) {
                Vec3 corner;
                for (int d = 0; d < 3; ++d) corner[d] = (q >> d) & 1 ? box.hi[d] : box.lo[d];
                const Projected p = Project(camera, scene.camera, corner);
                ASSERT_GT(p.depth, 0) << what << " corner " << q;
                EXPECT_LT(MissRelative(camera.RayAt(p.x, p.y), corner), 1e-9)
                    << what << " corner " << q;
                EXPECT_GE(p.x, 0) << what << " corner " << q;
                EXPECT_LE(p.x, W) << what << " corner " << q;
                EXPECT_GE(p.y, 0) << what << " corner " << q;
                EXPECT_LE(p.y, H) << what << " corner " << q;
                x0 = std::min(x0, p.x), x1 = std::max(x1, p.x);
                y0 = std::min(y0, p.y), y1 = std::max(y1, p.y);
            }
            EXPECT_GE(std::max((x1 - x0) / W, (y1 - y0) / H), 0.6)
                << what << ": the box spans " << (x1 - x0) / W << " of the width and "
                << (y1 - y0) / H << " of the height";
            ++checked;
        }
    }
    EXPECT_EQ(checked, static_cast<int>(meshes.size() * cameras.size()));
}

// A scene with nothing but the data and `volume: {color_field: u}` (default transfer
// functions, automatic camera) gives a picture with substance: over the pixels the volume
// covers (alpha > 1e-3, at least 30% of the image) the mean opacity is at least 0.5 and
// the most opaque pixel at least 0.8, yet at most 35% of them are opaque (alpha > 0.95).
// An extinction ramp to 4 / diagonal gave a pale fog (mean 0.35 to 0.45 here).
TEST(AutoView, DefaultVolumeIsNeitherFaintNorOpaque) {
    for (const std::string spec : {"builtin:ball-p2", "builtin:cube-tets-4", "builtin:nk-sinc"}) {
        const Scene scene = ParseScene("data: {mesh: \"" + spec + "\"}\n"
                                       "volume: {color_field: u}\n"
                                       "camera: {width: 64, height: 64}\n",
                                       "auto_view.yaml");
        RenderStats stats;
        const Image image = RenderMeshJob(MakeBuiltin(spec), scene, stats);
        std::size_t covered = 0, opaque = 0;
        double sum = 0, most = 0;
        for (const double a : image.a) {
            if (!(a > 1e-3)) continue;
            ++covered;
            opaque += a > 0.95;
            sum += a;
            most = std::max(most, a);
        }
        ASSERT_GE(covered, image.a.size() * 3 / 10) << spec;
        EXPECT_GE(sum / covered, 0.5) << spec;
        EXPECT_GE(most, 0.8) << spec;
        EXPECT_LE(opaque, covered * 35 / 100) << spec;
    }
}

// The stats report the volume's transfer functions as rendered, the defaults resolved:
// viridis over the field's range, extinction from 0 to 10 / the data's diagonal (what the
// browser viewer shows for a volume that gives only its field).
TEST(AutoView, StatsReportTheDefaultTransferFunctions) {
    const Mesh mesh = MakeBuiltin("builtin:cube-tets-4");
    const Scene scene = ParseScene("data: {mesh: \"builtin:cube-tets-4\"}\n"
                                   "volume: {color_field: u}\n"
                                   "camera: {width: 8, height: 8}\n",
                                   "auto_view.yaml");
    RenderStats stats;
    RenderMeshJob(mesh, scene, stats);
    ASSERT_TRUE(stats.hasVolume);
    EXPECT_EQ(stats.volumeColorField, "u");
    EXPECT_EQ(stats.volumeExtinctionField, "u");
    const auto range = mesh.FindPointField("u")->Range();  // x + 2y + 3z: [0, 6]
    const auto viridis = ExpandColorMap("viridis", range[0], range[1]);
    ASSERT_EQ(stats.volumeColorTf.size(), viridis.size());
    for (std::size_t k = 0; k < viridis.size(); ++k)
        EXPECT_EQ(stats.volumeColorTf[k],
                  (std::array<double, 4>{viridis[k].scalar, viridis[k].rgb[0],
                                         viridis[k].rgb[1], viridis[k].rgb[2]}));
    const std::vector<std::array<double, 2>> extinction = {
        {range[0], 0.0}, {range[1], 10.0 / mesh.Bounds().Diagonal()}};
    EXPECT_EQ(stats.volumeExtinctionTf, extinction);
    EXPECT_EQ(range[0], 0.0);
    EXPECT_EQ(range[1], 6.0);
}

}  // namespace
}  // namespace hpray
