// Calibration of the partitioner's cost model (partition/cost_model.h) against the
// renderer: for each data set, on one thread,
//   - the setup time per cell (geometry classification, traverser, per-field data: what a
//     rank spends on a brick before its first ray), and
//   - the render time per ray segment of each cell class (shape, order, family, affine or
//     curved), from the renderer's own per-segment cost samples (SegmentCostSample), in a
//     volume scene whose transfer functions vary over the whole field range, so every
//     segment is integrated (the partitioner cannot know the scene; this is the upper
//     envelope, isosurface scenes skip the cells whose range holds no isovalue).
// Writes one CSV row per (data set, class) to stdout; scripts/calibrate_cost.sh runs it
// and fits the model's coefficients (scripts/fit_cost_model.py).
//
// Usage: calibrate_cost [--size N] [--reps R] [--data DIR] [name ...]
#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <string>
#include <tuple>
#include <vector>

#include "elements/mesh_geometry.h"
#include "io/mesh_io.h"
#include "mesh/builtin.h"
#include "mesh/cell.h"
#include "render/brick_renderer.h"
#include "render/render_job.h"
#include "scene/camera.h"
#include "scene/scene.h"

namespace {

using namespace hpray;

struct DataSet {
    std::string name;
    std::string source;  ///< builtin spec or a file under the data directory
    bool warp = false;   ///< bend the mesh smoothly so that every cell is curved
};

const std::vector<DataSet> kDataSets = {
    {"tet1", "builtin:cube-tets-16"},
    {"tet2", "builtin:cube-tets-8?order=2"},
    {"tet3", "builtin:cube-tets-6?order=3"},
    {"tet4", "builtin:cube-tets-5?order=4"},
    {"tet6", "builtin:cube-tets-4?order=6"},
    {"tet8", "builtin:cube-tets-3?order=8"},
    {"tet2c", "builtin:cube-tets-8?order=2", true},
    {"tet3c", "builtin:cube-tets-6?order=3", true},
    {"tet4c", "builtin:cube-tets-5?order=4", true},
    {"hex1", "builtin:nk-sinc?order=1"},
    {"hex2", "builtin:nk-sinc?order=2"},
    {"hex3", "builtin:nk-sinc?order=3"},
    {"hex4", "builtin:nk-sinc?order=4"},
    {"hex6", "builtin:nk-sinc?order=6"},
    {"hex8", "builtin:nk-sinc?order=8"},
    {"hex1c", "builtin:nk-sinc?order=1", true},
    {"hex2c", "builtin:nk-sinc?order=2", true},
    {"hex3c", "builtin:nk-sinc?order=3", true},
    {"hex4c", "builtin:nk-sinc?order=4", true},
    {"t16_tets_1M", "mfem_gmsh_t16_tets_1M.vtu"},
    {"escher_tet_p3", "mfem_escher_tet_p3.vtu"},
    {"escher_quadtet_p2", "mfem_escher_quadtet_p2.vtu"},
    {"boolean_tet_p4", "gmsh_boolean_tet_p4.vtu"},
    {"step65_hex_q3", "dealii_step65_hex_q3.vtu"},
    {"step44_hex_q2", "dealii_step44_hex_q2.vtu"},
    {"beam_hex_p3", "mfem_beam_hex_elasticity_p3.vtu"},
    {"toroid_hex_p3", "mfem_toroid_hex_p3.vtu"},
    {"toroid_wedge_p3", "mfem_toroid_wedge_p3.vtu"},
    {"fichera_mixed_linear", "mfem_fichera_mixed16_linear.vtu"},
    {"fichera_mixed_p3", "mfem_fichera_mixed_p3.vtu"},
    {"hybrid_pyr_p3", "gmsh_hybrid_pyr_p3.msh"},
    {"pripyrtet_p2", "gmsh_pripyrtet_p2.msh"},
};

double Seconds(std::chrono::steady_clock::time_point since) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - since)
        .count();
}

/// A smooth bend of the unit cube onto itself (boundary moves too: the mesh stays valid
/// for amplitudes well below the cell size over 2 pi).
void Warp(Mesh& mesh) {
    for (std::int64_t i = 0; i < mesh.PointCount(); ++i) {
        double* p = &mesh.points[3 * i];
        const double x = p[0], y = p[1], z = p[2];
        p[0] += 0.04 * std::sin(M_PI * y) * std::sin(M_PI * z + 0.3);
        p[1] += 0.04 * std::sin(M_PI * z) * std::sin(M_PI * x + 0.7);
        p[2] += 0.04 * std::sin(M_PI * x) * std::sin(M_PI * y + 1.1);
    }
}

/// The volume scene of the calibration: a view of the whole mesh, transfer functions
/// linear over the field's range with an optical depth of about one across the mesh.
Scene CalibrationScene(const Mesh& mesh, const std::string& field, int size) {
    const auto b = mesh.Bounds();
    double c[3], diag = 0;
    for (int d = 0; d < 3; ++d) {
        c[d] = 0.5 * (b.lo[d] + b.hi[d]);
        diag += (b.hi[d] - b.lo[d]) * (b.hi[d] - b.lo[d]);
    }
    diag = std::sqrt(diag);
    const double dir[3] = {1.3 / 2.34, 0.9 / 2.34, 1.7 / 2.34};  // ~unit
    const Field* f = mesh.FindPointField(field.substr(0, field.find('[')));
    double lo = 0, hi = 1;
    if (f) {
        const auto r = f->Range(0);
        lo = r[0];
        hi = r[1] > r[0] ? r[1] : r[0] + 1;
    }
    const double k = 1.0 / diag;
    char yaml[2048];
    std::snprintf(yaml, sizeof yaml, R"(
data: {mesh: "calibration"}
camera: {position: [%.17g, %.17g, %.17g], look_at: [%.17g, %.17g, %.17g], up: [0, 1, 0],
         fov_y: 30, width: %d, height: %d}
volume:
  color_field: "%s"
  color_tf: [[%.17g, 0.1, 0.2, 0.9], [%.17g, 0.9, 0.3, 0.1]]
  extinction_tf: [[%.17g, %.17g], [%.17g, %.17g]]
threads: 1
)",
                  c[0] + 2.2 * diag * dir[0], c[1] + 2.2 * diag * dir[1],
                  c[2] + 2.2 * diag * dir[2], c[0], c[1], c[2], size, size, field.c_str(),
                  lo, hi, lo, 0.2 * k, hi, 2.0 * k);
    return ParseScene(yaml, "calibration.yaml", {}, "");
}

struct ClassKey {
    int shape, order, family, curved;
    bool operator<(const ClassKey& o) const {
        return std::tie(shape, order, family, curved) <
               std::tie(o.shape, o.order, o.family, o.curved);
    }
};

struct ClassTally {
    std::int64_t cells = 0;
    double segments = 0, seconds = 0;
};

}  // namespace

int main(int argc, char** argv) {
    int size = 160, reps = 3;
    std::string dataDir = HPRAY_SHARED_DATA;
    std::vector<std::string> only;
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        if (a == "--size" && i + 1 < argc) {
            size = std::atoi(argv[++i]);
        } else if (a == "--reps" && i + 1 < argc) {
            reps = std::atoi(argv[++i]);
        } else if (a == "--data" && i + 1 < argc) {
            dataDir = argv[++i];
        } else {
            only.push_back(a);
        }
    }
    tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
    std::printf(
        "data,shape,order,family,curved,cells,mesh_cells,classes,setup_s_per_cell,"
        "segments,render_s_per_segment\n");
    for (const DataSet& ds : kDataSets) {
        if (!only.empty() && std::find(only.begin(), only.end(), ds.name) == only.end())
            continue;
        Mesh mesh;
        try {
            if (ds.source.rfind("builtin:", 0) == 0) {
                mesh = MakeBuiltin(ds.source);
            } else {
                mesh = ReadMesh(dataDir + "/" + ds.source);
            }
        } catch (const std::exception& e) {
            std::fprintf(stderr, "skipping %s: %s\n", ds.name.c_str(), e.what());
            continue;
        }
        if (ds.warp) Warp(mesh);
        if (mesh.pointFields.empty()) {
            std::fprintf(stderr, "skipping %s: no point field\n", ds.name.c_str());
            continue;
        }
        const Field& f = mesh.pointFields[0];
        const std::string field = f.components == 1 ? f.name : f.name + "[0]";
        const Scene scene = CalibrationScene(mesh, field, size);
        // Medians over repetitions of the setup and of each class's seconds.
        std::vector<double> setups;
        std::map<ClassKey, std::vector<double>> perRep;
        std::map<ClassKey, ClassTally> tally;
        for (int r = 0; r < reps; ++r) {
            RenderStats stats = StartStats(scene);
            const auto t0 = std::chrono::steady_clock::now();
            PreparedBrick brick(mesh, std::nullopt, scene, stats);
            setups.push_back(Seconds(t0) / static_cast<double>(mesh.CellCount()));
            const MeshGeometry& g = brick.Geometry();
            std::vector<SegmentCostSample> samples;
            Image image;
            brick.Render(scene, Camera(scene.camera), std::nullopt, image, stats,
                         &samples);
            std::map<ClassKey, ClassTally> rep;
            CellScratch scratch;
            auto keyOf = [&](std::int64_t c) {
                return ClassKey{static_cast<int>(mesh.cellShape[c]), mesh.cellOrder[c],
                                static_cast<int>(mesh.cellFamily[c]),
                                g.Cell(c, scratch).affine ? 0 : 1};
            };
            for (const SegmentCostSample& s : samples) {
                ClassTally& t = rep[keyOf(s.cell)];
                t.segments += 1;
                t.seconds += s.seconds;
            }
            if (r == 0) {
                for (std::int64_t c = 0; c < mesh.CellCount(); ++c)
                    tally[keyOf(c)].cells += 1;
                for (const auto& [k, t] : rep) tally[k].segments = t.segments;
            }
            for (const auto& [k, t] : rep) perRep[k].push_back(t.seconds);
        }
        auto median = [](std::vector<double> v) {
            std::sort(v.begin(), v.end());
            return v.empty() ? 0.0 : v[v.size() / 2];
        };
        const double setup = median(setups);
        for (const auto& [k, t] : tally) {
            const double seconds = median(perRep[k]);
            std::printf("%s,%s,%d,%s,%d,%lld,%lld,%zu,%.6g,%.0f,%.6g\n", ds.name.c_str(),
                        ShapeName(static_cast<CellShape>(k.shape)), k.order,
                        k.family ? "serendipity" : "lagrange", k.curved,
                        static_cast<long long>(t.cells),
                        static_cast<long long>(mesh.CellCount()), tally.size(), setup,
                        t.segments, t.segments > 0 ? seconds / t.segments : 0.0);
            std::fflush(stdout);
        }
    }
    return 0;
}
