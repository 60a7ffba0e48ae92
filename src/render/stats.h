// Render statistics: the counters of the stats JSON (docs/contracts.md), merged over threads
// and ranks, and written as JSON by rank 0.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace hpray {

/// Wall-clock seconds of each phase. Across ranks the maximum is reported.
struct PhaseTimes {
    double load = 0, accel = 0, render = 0, composite = 0, write = 0, total = 0;
    /// Distributed jobs: the cost-measuring pre-pass of an in-memory split, the wait for
    /// the slowest rank before compositing (imbalance), and the fastest rank's render.
    double prepass = 0, wait = 0, renderMin = 0;
};

/// Counters accumulated per thread and summed; plain so they can be reduced over MPI as
/// arrays of doubles (see ToArray / FromArray).
struct RenderCounters {
    double rays = 0;
    double segments = 0;
    double segmentsCulled = 0;  ///< skipped: field range cannot contribute
    // Isosurfaces.
    double isoHits = 0;
    double isoResidualSqSum = 0;
    double isoResidualMax = 0;          ///< reduced with max
    double isoResidualRelMax = 0;       ///< reduced with max
    double projections = 0;             ///< projected segments
    double projectionOrderSum = 0;
    double projectionOrderMax = 0;      ///< reduced with max
    double projectionUnconverged = 0;
    double rootFailures = 0;
    double fieldEvaluations = 0;
    // Mapping inversion.
    double inversions = 0;
    double inversionIterations = 0;
    double inversionFailures = 0;
    // Volume.
    double volumeErrorSqSum = 0;
    double volumeErrorMax = 0;          ///< reduced with max
    double volumePixels = 0;
    double volumeNodes = 0;  ///< integrand samples of the volume quadratures
    // Isosurfaces again: segments whose projection the sub-cell bounds ruled out, and
    // those they shortened (SubCellBounds::Clip).
    double isoSubcellCulled = 0;
    double isoSubcellClipped = 0;

    static constexpr int kSize = 22;
    /// Indices of the fields reduced with max rather than sum.
    static bool IsMax(int index);
    std::array<double, kSize> ToArray() const;
    static RenderCounters FromArray(const std::array<double, kSize>& a);
    /// Adds (or maxes) `other` into this.
    void Merge(const RenderCounters& other);
};

/// How the ray walk met the mesh: non-conforming input found when the traverser was
/// built (trace/brick_traverser.h: TraverserStats), and the numerically hard events of
/// the walks (TraceCounters), over all bricks and ranks.
struct TraversalStats {
    double nonConformingFaces = 0;
    double nonConformingEdges = 0;
    double nonConformity = 0;  ///< largest node mismatch over edge length / face size
    double walkRepairs = 0;
    double walkFailures = 0;
    double faceNewtonFailures = 0;
};

struct CompositeStats {
    int rounds = 0;
    int bytesPerPixel = 0;
    double bytesSentMax = 0;
    double bytesSentTotal = 0;
    double bytesGather = 0;
};

struct RenderStats {
    int ranks = 1;
    std::string distribute;  ///< on several ranks: "space" or "image" (scene.h: Distribution)
    int threads = 1;
    int width = 0, height = 0;
    /// The camera the frame was rendered with (an automatic one as placed), so that it
    /// can be reused: position, look_at, up, and fov_y or ortho_height.
    std::array<double, 3> cameraPosition{0, 0, 0}, cameraLookAt{0, 0, 0}, cameraUp{0, 1, 0};
    bool cameraOrthographic = false;
    double cameraFovY = 0, cameraOrthoHeight = 0;
    /// The volume the frame was rendered with (hasVolume), its transfer functions as
    /// resolved from the data (defaults, `range: auto` colour maps), so that a client can
    /// show and edit what was drawn: [s, r, g, b] and [s, sigma] control points.
    bool hasVolume = false;
    std::string volumeColorField, volumeExtinctionField;
    std::vector<std::array<double, 4>> volumeColorTf;
    std::vector<std::array<double, 2>> volumeExtinctionTf;
    PhaseTimes timing;
    RenderCounters counters;
    CompositeStats composite;
    TraversalStats traversal;
    int bricksLoaded = 0;
    int bricksTotal = 0;
    std::array<double, 2> isoFieldRange{0, 0};  ///< [min, max] of the isosurface fields
    double accelBytes = 0;
    double accelBytesPerCell = 0;
    std::string scene;
    std::string mesh;
    /// A step of a .pvd collection: its index and time (timeStep < 0: not a collection).
    int timeStep = -1;
    double time = 0.0;
    /// The frame's index in a run of several frames (scene key `frames`), else -1.
    int frame = -1;
    /// What probably went wrong, for the user (also logged once on rank 0).
    std::vector<std::string> warnings;
};

/// The stats JSON of docs/contracts.md (pretty-printed).
std::string StatsToJson(const RenderStats& stats);
/// Writes StatsToJson to `path` atomically (tmp + rename). Throws InputError(path).
void WriteStats(const std::string& path, const RenderStats& stats);

}  // namespace hpray
