// Brick boundaries: a partitioned render equals the unpartitioned one for rays that lie
// exactly in split planes, run along box edges and pass through box corners (the
// ownership rule of geom/box.h). Partitions of the Fichera mixed mesh (linear tets,
// hexes, wedges, pyramids) and of its curved order-3 version into 2, 3, 5, 7 and 12
// bricks, each brick rendered with its rays cut at its box and composited in the k-d
// visibility order, as one rank does; and the same boxes as an in-memory split of the
// whole mesh. Isosurface, volume, and both with a slice lying in the root split plane.
#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "geom/kd_tree.h"
#include "io/mesh_io.h"
#include "image/image.h"
#include "partition.h"
#include "partition_test_util.h"
#include "render/render_job.h"
#include "scene/camera.h"
#include "scene/scene.h"

namespace hpray {
namespace {

const std::string kData = HPRAY_SHARED_DATA;
constexpr int kSize = 15;  // odd: the centre row and column have sx = 0, sy = 0 exactly

std::string Vec(const std::array<double, 3>& v) {
    std::ostringstream os;
    os.precision(17);
    os << "[" << v[0] << ", " << v[1] << ", " << v[2] << "]";
    return os.str();
}

/// The scenes: semi-transparent isosurfaces (a hit counted twice would show in alpha), a
/// volume, and both with a slice in the plane `slice` (axis, value).
std::vector<std::pair<std::string, std::string>> Scenes(int sliceAxis, double sliceValue) {
    const std::string head = "data: {mesh: \"unused\"}\nthreads: 2\n";
    const std::string isos =
        "isosurfaces:\n"
        "  - {field: u, value: 0.06, color: [0.9, 0.6, 0.2], opacity: 0.5}\n"
        "  - {field: analytic, value: 0.3, color: [0.2, 0.5, 0.9], opacity: 0.4}\n";
    const std::string volume =
        "volume:\n  color_field: u\n"
        "  color_tf: [[0.0, 0.1, 0.2, 0.8], [0.06, 0.2, 0.8, 0.5], [0.153, 1.0, 0.4, 0.1]]\n"
        "  extinction_tf: [[0.0, 0.2], [0.05, 1.5], [0.153, 6.0]]\n";
    std::array<double, 3> point{0, 0, 0}, normal{0, 0, 0};
    point[sliceAxis] = sliceValue;
    normal[sliceAxis] = 1;
    const std::string slice = "slices:\n  - {point: " + Vec(point) +
                              ", normal: " + Vec(normal) +
                              ", field: analytic, color_tf: [[-1.5, 0, 0, 1], [1.5, 1, 0, "
                              "0]], opacity: 0.3}\n";
    return {{"iso", head + isos},
            {"volume", head + volume},
            {"both", head + isos + volume + slice}};
}

SceneCamera Ortho(const std::array<double, 3>& position, int viewAxis,
                  const Box& root) {
    SceneCamera c;
    c.orthographic = true;
    c.orthoHeight = 1.2 * root.Diagonal();
    c.width = c.height = kSize;
    c.position = position;
    c.lookAt = position;
    c.lookAt[viewAxis] -= 1;
    c.up = {0, 0, 0};
    c.up[(viewAxis + 2) % 3] = 1;  // right = e_u, true up = e_w: both exact
    return c;
}

/// Cameras whose centre column and row lie in the planes through every leaf's lower
/// corner (split planes, or the root's faces) along each axis, so the centre ray runs
/// along a box edge and through the corner; perspective eyes on the root split plane and
/// at leaf corners inside the data.
std::vector<std::pair<std::string, SceneCamera>> Cameras(const KdTree& tree) {
    std::vector<std::pair<std::string, SceneCamera>> cams;
    const Box& root = tree.box;
    std::set<std::array<double, 3>> seen;
    const std::vector<Box> leaves = tree.LeafBoxes();
    for (std::size_t b = 0; b < leaves.size(); ++b)
        for (int v = 0; v < 3; ++v) {
            const int u = (v + 1) % 3, w = (v + 2) % 3;
            const std::array<double, 3> key{double(v), leaves[b].lo[u], leaves[b].lo[w]};
            if (!seen.insert(key).second) continue;
            std::array<double, 3> p;
            p[u] = leaves[b].lo[u];
            p[w] = leaves[b].lo[w];
            p[v] = root.hi[v] + 1;
            cams.push_back({"ortho along " + std::string(1, "xyz"[v]) + " through corner of " +
                                std::to_string(b) + " " + Vec(p),
                            Ortho(p, v, root)});
        }
    const KdNode& top = tree.nodes[tree.root];
    if (!top.IsLeaf()) {
        SceneCamera c;
        c.width = c.height = kSize;
        c.fovYDegrees = 50;
        c.position = {0.3, 0.4, 0.5};
        c.position[(top.axis + 2) % 3] = root.hi[(top.axis + 2) % 3] + 3;
        c.position[top.axis] = top.split;
        c.lookAt = root.Center();
        c.lookAt[top.axis] = top.split;
        cams.push_back({"perspective, eye on the root split plane " + Vec(c.position), c});
    }
    for (std::size_t b = 0; b < leaves.size() && b < 4; ++b) {
        SceneCamera c;
        c.width = c.height = kSize;
        c.fovYDegrees = 100;
        c.position = leaves[b].hi;
        if (!leaves[b].InnerHi(0) && !leaves[b].InnerHi(1) && !leaves[b].InnerHi(2))
            c.position = leaves[b].lo;
        c.lookAt = root.Center();  // off the corner's planes: a generic direction
        for (int d = 0; d < 3; ++d) c.lookAt[d] += 0.03 * (d + 1);
        cams.push_back({"perspective, eye at a corner of leaf " + std::to_string(b) +
                            " " + Vec(c.position),
                        c});
    }
    return cams;
}

/// Largest difference per channel; hit masks and isosurface ids must be identical.
void ExpectSameImage(const Image& ref, const Image& got, const std::string& what,
                     double& worst) {
    ASSERT_EQ(ref.PixelCount(), got.PixelCount()) << what;
    const auto a = ref.Channels();
    const auto b = got.Channels();
    std::size_t maskDiffers = 0;
    double diff = 0;
    for (std::size_t k = 0; k < a.size(); ++k) {
        const std::vector<double>& x = *a[k].second;
        const std::vector<double>& y = *b[k].second;
        for (std::size_t i = 0; i < x.size(); ++i) {
            if (std::isnan(x[i]) || std::isnan(y[i]) || std::isinf(x[i]) ||
                std::isinf(y[i])) {
                const bool same = std::isnan(x[i]) ? std::isnan(y[i]) : x[i] == y[i];
                maskDiffers += same ? 0 : 1;
                continue;
            }
            diff = std::max(diff, std::abs(x[i] - y[i]));
        }
    }
    for (std::size_t i = 0; i < ref.isoId.size(); ++i)
        maskDiffers += ref.isoId[i] != got.isoId[i];
    EXPECT_EQ(maskDiffers, 0u) << what << ": hit masks differ";
    EXPECT_LE(diff, 1e-6) << what;
    worst = std::max(worst, diff);
}

struct Case {
    std::string mesh;
    int bricks;
};

class BrickSeams : public ::testing::TestWithParam<Case> {};

TEST_P(BrickSeams, EveryCameraOnPlanesEdgesAndCornersGivesTheUnpartitionedImage) {
    const Case& param = GetParam();
    const std::string meshPath = kData + "/" + param.mesh;
    test::ScratchDir dir("seams_" + std::to_string(param.bricks));
    partition::PartitionOptions options;
    options.bricks = param.bricks;
    options.outDir = dir / "p";
    partition::PartitionMesh(meshPath, options);
    const partition::Partition part = partition::ReadPartition(options.outDir);
    const KdTree& tree = part.tree;
    ASSERT_EQ(tree.Problem(param.bricks), "");
    ReadOptions read;
    read.fields = std::set<std::string>{"u", "analytic"};
    const Mesh whole = ReadMesh(meshPath, read);
    std::vector<Mesh> bricks;
    for (int b = 0; b < param.bricks; ++b) bricks.push_back(partition::LoadBrick(part, b, read));
    const KdNode& top = tree.nodes[tree.root];
    const auto cameras = Cameras(tree);
    ASSERT_GE(cameras.size(), 3u);
    double worst = 0;
    for (const auto& [kind, yaml] : Scenes(top.IsLeaf() ? 0 : top.axis, top.split)) {
        const Scene scene = ParseScene(yaml, "seams.yaml", {}, "");
        RenderStats stats = StartStats(scene);
        PreparedBrick reference(whole, std::nullopt, scene, stats);
        std::vector<std::unique_ptr<PreparedBrick>> prepared;
        for (int b = 0; b < param.bricks; ++b)
            prepared.push_back(std::make_unique<PreparedBrick>(bricks[b], part.bricks[b].box,
                                                               scene, stats));
        for (const auto& [name, settings] : cameras) {
            const Camera camera(settings);
            const std::string what = param.mesh + ", " + std::to_string(param.bricks) +
                                     " bricks, " + kind + ", " + name;
            Image ref;
            reference.Render(scene, camera, std::nullopt, ref, stats);
            // A partition directory: every brick with its rays cut at its box, front to
            // back, pixels opaque in front not traced again.
            Image bricked, inMemory;
            bricked.Resize(kSize, kSize);
            inMemory.Resize(kSize, kSize);
            for (int b : tree.FrontToBack(ViewOriginOf(settings))) {
                Image image;
                prepared[b]->Render(scene, camera, std::nullopt, image, stats, nullptr,
                                    &bricked);
                CompositeOver(bricked, image);
                // The in-memory split of the whole mesh into the same boxes.
                Image piece;
                reference.Render(scene, camera, part.bricks[b].box, piece, stats, nullptr,
                                 &inMemory);
                CompositeOver(inMemory, piece);
            }
            ExpectSameImage(ref, bricked, what + " (partition)", worst);
            ExpectSameImage(ref, inMemory, what + " (in-memory split)", worst);
            // The test means something only if the camera sees the data.
            double alpha = 0;
            for (double a : ref.a) alpha += a;
            EXPECT_GT(alpha, 0) << what;
        }
    }
    RecordProperty("max_difference", std::to_string(worst));
}

INSTANTIATE_TEST_SUITE_P(
    Partitions, BrickSeams,
    ::testing::Values(Case{"mfem_fichera_mixed16_linear.vtu", 2},
                      Case{"mfem_fichera_mixed16_linear.vtu", 3},
                      Case{"mfem_fichera_mixed16_linear.vtu", 5},
                      Case{"mfem_fichera_mixed16_linear.vtu", 7},
                      Case{"mfem_fichera_mixed16_linear.vtu", 12},
                      Case{"mfem_fichera_mixed_p3.vtu", 2}, Case{"mfem_fichera_mixed_p3.vtu", 3},
                      Case{"mfem_fichera_mixed_p3.vtu", 5}, Case{"mfem_fichera_mixed_p3.vtu", 7},
                      Case{"mfem_fichera_mixed_p3.vtu", 12}),
    [](const ::testing::TestParamInfo<Case>& info) {
        return std::string(info.param.mesh.find("p3") != std::string::npos ? "curved_p3"
                                                                           : "linear") +
               "_" + std::to_string(info.param.bricks);
    });

}  // namespace
}  // namespace hpray
