// Stand-alone MPI benchmark of the compositor: time and bytes versus image size and P.
//
//   mpiexec -n P bench_composite [--sizes 512,1024,2048,4096] [--scenes dense,boxes]
//                                [--methods swap,direct,gather] [--reps 5]
//
// Every rank owns one leaf of RegularKdTree over the unit cube. Scenes: "dense", every
// pixel of every rank's image non-empty (the worst case, no run-length gain); "boxes",
// each rank's fog fills only the pixels whose ray crosses its box, seen by a perspective
// camera that frames the cube (what a renderer produces). Rank 0 prints one CSV row per
// (size, scene, method): the median over repetitions of the composite wall time (swap
// rounds plus gather, max over ranks) and the stats of the last repetition.
#include <mpi.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <sstream>
#include <string>
#include <vector>

#include "compositor.h"
#include "scene/camera.h"
#include "util/mpi.h"

namespace {

using namespace hpray;
using namespace hpray::compositor;

std::vector<std::string> SplitList(const std::string& text) {
    std::vector<std::string> out;
    std::stringstream in(text);
    for (std::string item; std::getline(in, item, ',');)
        if (!item.empty()) out.push_back(item);
    return out;
}

SceneCamera BenchCamera(int size) {
    SceneCamera camera;
    camera.position = {1.9, 1.5, 2.7};
    camera.lookAt = {0.5, 0.5, 0.5};
    camera.up = {0.0, 1.0, 0.0};
    camera.fovYDegrees = 40.0;
    camera.width = camera.height = size;
    return camera;
}

/// This rank's partial image of `scene` ("dense" or "boxes") with its leaf box `box`.
void MakeImage(Image& image, const std::string& scene, const Camera& camera,
               const std::array<double, 3>& lo, const std::array<double, 3>& hi,
               int rank) {
    image.Resize(camera.Width(), camera.Height());
    const double sigma = 1.0 + 0.5 * (rank % 4);
    for (int j = 0; j < camera.Height(); ++j)
        for (int i = 0; i < camera.Width(); ++i) {
            double length = 0.3;
            if (scene == "boxes") {
                const CameraRay ray = camera.PixelRay(i, j);
                double t0 = 0.0, t1 = 1e300;
                for (int d = 0; d < 3; ++d) {
                    double a = (lo[d] - ray.origin[d]) / ray.direction[d];
                    double b = (hi[d] - ray.origin[d]) / ray.direction[d];
                    if (a > b) std::swap(a, b);
                    t0 = std::max(t0, a);
                    t1 = std::min(t1, b);
                }
                length = t1 - t0;
                if (!(length > 0.0)) continue;
            }
            const std::size_t p = static_cast<std::size_t>(j) * camera.Width() + i;
            const double alpha = 1.0 - std::exp(-sigma * length);
            image.a[p] = alpha;
            image.r[p] = 0.8 * alpha;
            image.g[p] = 0.5 * alpha;
            image.b[p] = 0.2 * alpha;
            image.volError[p] = 1e-9 * length;
        }
}

/// Leaf box of `rank` in `tree` over the unit cube.
void LeafBox(const KdTree& tree, int rank, std::array<double, 3>& lo,
             std::array<double, 3>& hi) {
    lo = {0, 0, 0};
    hi = {1, 1, 1};
    // Walk down towards the leaf: the subtree holding `rank`.
    std::vector<int> parent(tree.nodes.size(), -1);
    int leaf = -1;
    for (std::size_t id = 0; id < tree.nodes.size(); ++id) {
        const KdNode& node = tree.nodes[id];
        if (node.IsLeaf()) {
            if (node.leaf == rank) leaf = static_cast<int>(id);
        } else {
            parent[node.low] = parent[node.high] = static_cast<int>(id);
        }
    }
    std::vector<int> path;
    for (int id = leaf; id >= 0; id = parent[id]) path.push_back(id);
    for (std::size_t k = path.size() - 1; k > 0; --k) {
        const KdNode& node = tree.nodes[path[k]];
        if (node.low == path[k - 1])
            hi[node.axis] = node.split;
        else
            lo[node.axis] = node.split;
    }
}

}  // namespace

int main(int argc, char** argv) {
    mpi::Session session(&argc, &argv);
    std::vector<std::string> sizes{"512", "1024", "2048", "4096"};
    std::vector<std::string> scenes{"dense", "boxes"};
    std::vector<std::string> methods{"swap", "direct", "gather"};
    int reps = 5;
    for (int k = 1; k + 1 < argc; k += 2) {
        const std::string key = argv[k], value = argv[k + 1];
        if (key == "--sizes")
            sizes = SplitList(value);
        else if (key == "--scenes")
            scenes = SplitList(value);
        else if (key == "--methods")
            methods = SplitList(value);
        else if (key == "--reps")
            reps = std::max(1, std::atoi(value.c_str()));
        else
            mpi::Abort("unknown option " + key, 2);
    }
    const int rank = mpi::WorldRank(), size = mpi::WorldSize();
    const KdTree tree = RegularKdTree(size, hpray::Box{{0, 0, 0}, {1, 1, 1}});
    std::array<double, 3> lo, hi;
    LeafBox(tree, rank, lo, hi);
    if (rank == 0)
        std::printf(
            "ranks,size,scene,method,active_fraction,composite_s,swap_s,gather_s,"
            "rounds,bytes_sent_max,bytes_sent_total,bytes_gather\n");
    for (const std::string& sizeText : sizes) {
        const int n = std::atoi(sizeText.c_str());
        if (n < 1) mpi::Abort("bad size " + sizeText, 2);
        const SceneCamera settings = BenchCamera(n);
        const Camera camera(settings);
        const ViewOrigin view = ViewOriginOf(settings);
        for (const std::string& scene : scenes) {
            for (const std::string& methodName : methods) {
                const Method method = methodName == "swap"     ? Method::TreeSwap
                                      : methodName == "direct" ? Method::DirectSend
                                                               : Method::GatherReference;
                std::vector<double> times;
                CompositeStats stats;
                double activeFraction = 0.0;
                Image image;
                for (int r = 0; r < reps; ++r) {
                    MakeImage(image, scene, camera, lo, hi, rank);
                    if (r == 0) {
                        // Fraction of non-empty pixels, averaged over ranks.
                        double mine = 0.0;
                        for (double a : image.a) mine += a > 0.0 ? 1.0 : 0.0;
                        mine /= static_cast<double>(image.PixelCount());
                        MPI_Allreduce(&mine, &activeFraction, 1, MPI_DOUBLE, MPI_SUM,
                                      MPI_COMM_WORLD);
                        activeFraction /= size;
                    }
                    MPI_Barrier(MPI_COMM_WORLD);
                    const double t0 = MPI_Wtime();
                    stats = Composite(image, tree, view, MPI_COMM_WORLD, method);
                    double mine = MPI_Wtime() - t0, slowest = 0.0;
                    MPI_Allreduce(&mine, &slowest, 1, MPI_DOUBLE, MPI_MAX,
                                  MPI_COMM_WORLD);
                    times.push_back(slowest);
                }
                std::sort(times.begin(), times.end());
                if (rank == 0)
                    std::printf("%d,%d,%s,%s,%.4f,%.5f,%.5f,%.5f,%d,%llu,%llu,%llu\n",
                                size, n, scene.c_str(), methodName.c_str(),
                                activeFraction, times[times.size() / 2],
                                stats.swapSeconds, stats.gatherSeconds, stats.rounds,
                                static_cast<unsigned long long>(stats.bytesSentMax),
                                static_cast<unsigned long long>(stats.bytesSentTotal),
                                static_cast<unsigned long long>(stats.bytesGather));
                std::fflush(stdout);
            }
        }
    }
    return 0;
}
