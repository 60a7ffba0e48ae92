// MPI tests of the compositor: synthetic partial images of k-d regions of space,
// composited by binary swap, direct send and the gather reference, against a serial
// composite ordered by ray geometry; bytes sent against the binary-swap bound.
#include <gtest/gtest.h>
#include <mpi.h>

#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "composite_test_util.h"
#include "compositor.h"
#include "util/error.h"
#include "util/mpi.h"
#include "mpi/mpi_test_main.h"

namespace hpray::compositor {
namespace {

using testutil::Box;
using testutil::TestCamera;
using testutil::Vec3;

const double kInf = std::numeric_limits<double>::infinity();

int Rank() { return mpi::WorldRank(); }
int Size() { return mpi::WorldSize(); }

/// A uniform value in [0, 1) from integers (identical on every rank).
double Hash01(std::uint64_t a, std::uint64_t b, std::uint64_t c) {
    std::uint64_t h = a * 0x9E3779B97F4A7C15ull ^
                      (b + 0x632BE59BD9B4E019ull) * 0xBF58476D1CE4E5B9ull ^
                      (c + 0x94D049BB133111EBull) * 0x2545F4914F6CDD1Dull;
    h ^= h >> 31;
    h *= 0xD6E8FEB86659FD93ull;
    h ^= h >> 32;
    return static_cast<double>(h >> 11) * 0x1.0p-53;
}

/// The synthetic scene: rank k renders its leaf box, a fog of extinction sigma_k and
/// colour c_k (alpha = 1 - exp(-sigma_k L) over the length L of the ray inside the box),
/// on some pixels an isosurface hit inside the box, and a volume error proportional to L.
/// A fraction 1 - fill of each rank's pixels is left empty.
struct SyntheticScene {
    KdTree tree;
    std::vector<Box> boxes;
    TestCamera camera;
    double fill = 1.0;

    /// Rank `rank`'s pixel (i, j); `entry` receives the ray parameter where the ray
    /// enters the box (+inf if the pixel is empty).
    Pixel RankPixel(int rank, int i, int j, double& entry) const {
        entry = kInf;
        Vec3 origin, dir;
        camera.Ray(i, j, origin, dir);
        double t0, t1;
        if (!testutil::ClipRay(boxes[rank], origin, dir, t0, t1)) return Pixel{};
        const double length = t1 - t0;
        if (length <= 1e-9 || Hash01(i, j, rank) >= fill) return Pixel{};
        entry = t0;
        Pixel p;
        const double sigma = 0.6 + 0.45 * (rank % 5);
        p.rgba[3] = 1.0 - std::exp(-sigma * length);
        p.rgba[0] = (0.15 + 0.1 * (rank % 8)) * p.rgba[3];
        p.rgba[1] = (0.95 - 0.12 * (rank % 6)) * p.rgba[3];
        p.rgba[2] = (0.3 + 0.2 * (rank % 3)) * p.rgba[3];
        if ((i + 2 * j + rank) % 3 == 0) {
            p.z = t0 + 0.25 * length;
            const Vec3 n = testutil::Normalize({1.0 + rank, 0.5 + i % 3, -0.25 - j % 2});
            p.normal[0] = n[0], p.normal[1] = n[1], p.normal[2] = n[2];
            p.isoResidual = 1e-3 * (rank + 1);
            p.isoId = rank % 4;
        }
        p.volError = 1e-4 * (rank + 1) * length;
        return p;
    }

    Image RankImage(int rank) const {
        Image image;
        image.Resize(camera.width, camera.height);
        for (int j = 0; j < camera.height; ++j)
            for (int i = 0; i < camera.width; ++i) {
                double entry;
                StorePixel(image, static_cast<std::size_t>(j) * camera.width + i,
                           RankPixel(rank, i, j, entry));
            }
        return image;
    }

    /// The exact composite, serially: every rank's layer of the pixel, sorted by where
    /// the ray enters its box (the geometric truth, not the tree), accumulated front to
    /// back with the closed form of docs/contracts.md.
    Image Expected() const {
        Image out;
        out.Resize(camera.width, camera.height);
        const int ranks = static_cast<int>(boxes.size());
        for (int j = 0; j < camera.height; ++j)
            for (int i = 0; i < camera.width; ++i) {
                std::vector<std::pair<double, Pixel>> layers;
                for (int k = 0; k < ranks; ++k) {
                    double entry;
                    const Pixel p = RankPixel(k, i, j, entry);
                    if (entry < kInf) layers.push_back({entry, p});
                }
                std::sort(layers.begin(), layers.end(),
                          [](const auto& x, const auto& y) { return x.first < y.first; });
                Pixel acc;
                for (const auto& [entry, p] : layers) {
                    const double transmittance = 1.0 - acc.rgba[3];
                    acc.rgba[0] += transmittance * p.rgba[0];
                    acc.rgba[1] += transmittance * p.rgba[1];
                    acc.rgba[2] += transmittance * p.rgba[2];
                    acc.rgba[3] += transmittance * p.rgba[3];
                    acc.volError += p.volError;
                    if (p.z < acc.z) {
                        acc.z = p.z, acc.normal[0] = p.normal[0], acc.normal[1] = p.normal[1], acc.normal[2] = p.normal[2];
                        acc.isoResidual = p.isoResidual, acc.isoId = p.isoId;
                    }
                }
                StorePixel(out, static_cast<std::size_t>(j) * camera.width + i, acc);
            }
        return out;
    }
};

/// Channel-wise comparison (NaN equals NaN, infinities exactly); returns failures.
int CompareImages(const Image& got, const Image& expected, double tol,
                  const std::string& what) {
    EXPECT_EQ(got.width, expected.width) << what;
    EXPECT_EQ(got.height, expected.height) << what;
    if (got.PixelCount() != expected.PixelCount()) return 1;
    int failures = 0;
    const auto gotChannels = got.Channels();
    const auto expChannels = expected.Channels();
    for (std::size_t c = 0; c < gotChannels.size(); ++c) {
        const auto& x = *gotChannels[c].second;
        const auto& y = *expChannels[c].second;
        for (std::size_t p = 0; p < got.PixelCount(); ++p) {
            const bool ok = (std::isnan(x[p]) && std::isnan(y[p])) ||
                            (std::isinf(y[p]) && x[p] == y[p]) ||
                            std::abs(x[p] - y[p]) <= tol;
            if (!ok && ++failures <= 5)
                ADD_FAILURE() << what << ": channel " << gotChannels[c].first << " pixel "
                              << p << ": " << x[p] << " vs " << y[p];
        }
    }
    return failures;
}

/// The cameras of the test: outside, inside the data, on the root split plane looking
/// along it (perspective and orthographic), on that plane looking across it, oblique
/// orthographic. Width even, so no pixel ray lies in a split plane through the eye.
std::vector<std::pair<std::string, TestCamera>> Cameras(const KdTree& tree) {
    const int w = 36, h = 24;
    std::vector<std::pair<std::string, TestCamera>> cams;
    cams.push_back(
        {"perspective outside",
         TestCamera::Make(false, {2.6, 1.9, 3.3}, {0.5, 0.5, 0.5}, {0, 1, 0}, 35, w, h)});
    cams.push_back(
        {"perspective inside", TestCamera::Make(false, {0.41, 0.57, 0.33},
                                                {0.9, 0.1, 0.8}, {0, 1, 0}, 110, w, h)});
    cams.push_back(
        {"orthographic oblique", TestCamera::Make(true, {2.5, -1.2, 2.0}, {0.5, 0.5, 0.5},
                                                  {0, 0, 1}, 2.2, w, h)});
    const KdNode& root = tree.nodes[tree.root];
    if (!root.IsLeaf()) {
        const int a = root.axis, f = (a + 1) % 3, u = (a + 2) % 3;
        Vec3 eye{0.5, 0.5, 0.5}, look{0.5, 0.5, 0.5}, up{0, 0, 0};
        eye[a] = look[a] = root.split;
        eye[f] = -1.5;
        look[f] = 0.5;
        up[u] = 1.0;
        cams.push_back({"perspective along split plane",
                        TestCamera::Make(false, eye, look, up, 50, w, h)});
        cams.push_back({"orthographic along split plane",
                        TestCamera::Make(true, eye, look, up, 1.6, w, h)});
        Vec3 inside{0.45, 0.45, 0.45}, across{0.93, 0.81, 0.07};
        inside[a] = root.split;
        up = {0, 0, 0};
        up[f] = 1.0;
        cams.push_back({"perspective on split plane, inside",
                        TestCamera::Make(false, inside, across, up, 100, w, h)});
    }
    return cams;
}

/// Trees used at every P: the regular one, and random shapes with shuffled leaf ranks.
std::vector<std::pair<std::string, KdTree>> Trees(int ranks) {
    std::vector<std::pair<std::string, KdTree>> trees;
    trees.push_back({"regular", RegularKdTree(ranks, hpray::Box{{0, 0, 0}, {1, 1, 1}})});
    for (int s = 0; s < 2; ++s) {
        std::mt19937 rng(1000 * ranks + s);  // same seed, same tree, on every rank
        trees.push_back({"random " + std::to_string(s),
                         testutil::RandomRankTree(ranks, rng, Box{}, true)});
    }
    return trees;
}

const char* MethodName(Method m) {
    return m == Method::TreeSwap     ? "tree swap"
           : m == Method::DirectSend ? "direct send"
                                     : "gather reference";
}

TEST(CompositeMpi, EqualsGeometricSerialCompositeForEveryCameraAndTree) {
    const int ranks = Size();
    for (const auto& [treeName, tree] : Trees(ranks)) {
        for (const auto& [camName, camera] : Cameras(tree)) {
            SyntheticScene scene;
            scene.tree = tree;
            scene.boxes = testutil::LeafBoxes(tree, Box{}, ranks);
            scene.camera = camera;
            scene.fill = 0.8;
            const Image expected = scene.Expected();
            Image reference;
            for (Method method :
                 {Method::GatherReference, Method::TreeSwap, Method::DirectSend}) {
                Image image = scene.RankImage(Rank());
                const CompositeStats stats =
                    Composite(image, tree, camera.View(), MPI_COMM_WORLD, method);
                const std::string what =
                    treeName + ", " + camName + ", " + MethodName(method);
                if (method == Method::TreeSwap) {
                    EXPECT_EQ(stats.rounds, tree.Height()) << what;
                }
                if (Rank() != 0) continue;
                CompareImages(image, expected, 1e-12, what);
                if (method == Method::GatherReference)
                    reference = image;
                else
                    CompareImages(image, reference, 1e-12, what + " vs reference");
            }
        }
    }
}

TEST(CompositeMpi, BytesStayWithinTheBoundAndFallWithEmptyPixels) {
    const int ranks = Size();
    const int w = 64, h = 48;
    const double s = static_cast<double>(kBytesPerPixel) * w * h;  // uncompressed image
    const double bound = s * (1.0 - 1.0 / ranks);
    for (const auto& [treeName, tree] : Trees(ranks)) {
        std::uint64_t previousTotal = 0, previousMax = 0;
        bool first = true;
        for (double fill : {1.0, 0.6, 0.3, 0.1, 0.0}) {
            // Geometry-free content: every rank's pixel non-empty with probability
            // `fill`.
            Image image;
            image.Resize(w, h);
            for (std::size_t p = 0; p < image.PixelCount(); ++p) {
                if (Hash01(p, Rank(), 77) >= fill) continue;
                Pixel px;
                px.rgba[3] = 0.5 * Hash01(p, Rank(), 1);
                px.rgba[0] = px.rgba[1] = px.rgba[2] = 0.5 * px.rgba[3];
                px.volError = 1e-6;
                StorePixel(image, p, px);
            }
            Image copy = image;
            const ViewOrigin view = ViewOrigin::Perspective({-0.7, 2.2, 0.4});
            const CompositeStats stats = Composite(image, tree, view, MPI_COMM_WORLD);
            const CompositeStats ref =
                Composite(copy, tree, view, MPI_COMM_WORLD, Method::GatherReference);
            const std::string what = treeName + " fill " + std::to_string(fill);
            if (Rank() == 0) CompareImages(image, copy, 1e-12, what);
            EXPECT_EQ(stats.bytesPerPixel, 88);
            EXPECT_LE(static_cast<double>(stats.bytesSentMax), 1.1 * bound) << what;
            EXPECT_LE(stats.bytesSentLocal, stats.bytesSentMax) << what;
            EXPECT_LE(stats.bytesSentMax, stats.bytesSentTotal) << what;
            // Active pixels plus at most two doubles of run header per active pixel; a
            // composited pixel is active where any rank's is.
            const double active = 1.0 - std::pow(1.0 - fill, ranks);
            EXPECT_LE(static_cast<double>(stats.bytesSentMax),
                      bound * active * (88.0 + 16.0) / 88.0)
                << what;
            EXPECT_LE(static_cast<double>(stats.bytesGather),
                      s * active * (88.0 + 16.0) / 88.0)
                << what;
            EXPECT_EQ(ref.bytesGather, static_cast<std::uint64_t>((ranks - 1) * s))
                << what;
            if (fill == 1.0) {
                // Dense: exactly the binary-swap volume, run headers aside.
                EXPECT_GE(static_cast<double>(stats.bytesSentMax), 0.99 * bound) << what;
                EXPECT_NEAR(static_cast<double>(stats.bytesSentTotal), ranks * bound,
                            0.01 * ranks * bound + 1000.0)
                    << what;
            }
            if (fill == 0.0) {
                EXPECT_EQ(stats.bytesSentTotal, 0u) << what;
                EXPECT_EQ(stats.bytesGather, 0u) << what;
            }
            if (!first) {
                EXPECT_LT(stats.bytesSentTotal, previousTotal) << what;
                EXPECT_LE(stats.bytesSentMax, previousMax) << what;
            }
            previousTotal = stats.bytesSentTotal;
            previousMax = stats.bytesSentMax;
            first = false;
        }
    }
}

TEST(CompositeMpi, DisagreementMakesEveryRankThrowTogether) {
    const int ranks = Size();
    const KdTree tree = RegularKdTree(ranks, hpray::Box{{0, 0, 0}, {1, 1, 1}});
    const ViewOrigin view = ViewOrigin::Perspective({2, 2, 2});
    Image image;
    image.Resize(Rank() == 0 ? 10 : 12, 8);
    EXPECT_THROW(Composite(image, tree, view, MPI_COMM_WORLD), InternalError);
    // A tree that misses the last rank: every rank sees the same problem.
    image.Resize(12, 8);
    const KdTree small = RegularKdTree(ranks - 1, hpray::Box{{0, 0, 0}, {1, 1, 1}});
    EXPECT_THROW(Composite(image, small, view, MPI_COMM_WORLD), InternalError);
    // One rank with a different view.
    const ViewOrigin other =
        ViewOrigin::Perspective({2, 2, Rank() == 0 ? 2.0 : 3.0});
    EXPECT_THROW(Composite(image, tree, other, MPI_COMM_WORLD), InternalError);
    // And the communicator still works afterwards.
    Image ok;
    ok.Resize(4, 4);
    EXPECT_NO_THROW(Composite(ok, tree, view, MPI_COMM_WORLD));
}

}  // namespace
}  // namespace hpray::compositor
