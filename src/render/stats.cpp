// Render statistics: reduction helpers and the JSON of the stats contract.
#include "render/stats.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "io/output_file.h"

namespace hpray {

bool RenderCounters::IsMax(int index) {
    // isoResidualMax, isoResidualRelMax, projectionOrderMax, volumeErrorMax.
    return index == 5 || index == 6 || index == 9 || index == 18;
}

std::array<double, RenderCounters::kSize> RenderCounters::ToArray() const {
    return {rays,
            segments,
            segmentsCulled,
            isoHits,
            isoResidualSqSum,
            isoResidualMax,
            isoResidualRelMax,
            projections,
            projectionOrderSum,
            projectionOrderMax,
            projectionUnconverged,
            rootFailures,
            fieldEvaluations,
            inversions,
            inversionIterations,
            inversionFailures,
            volumeErrorSqSum,
            volumePixels,
            volumeErrorMax,
            volumeNodes,
            isoSubcellCulled,
            isoSubcellClipped};
}

RenderCounters RenderCounters::FromArray(const std::array<double, kSize>& a) {
    RenderCounters c;
    c.rays = a[0];
    c.segments = a[1];
    c.segmentsCulled = a[2];
    c.isoHits = a[3];
    c.isoResidualSqSum = a[4];
    c.isoResidualMax = a[5];
    c.isoResidualRelMax = a[6];
    c.projections = a[7];
    c.projectionOrderSum = a[8];
    c.projectionOrderMax = a[9];
    c.projectionUnconverged = a[10];
    c.rootFailures = a[11];
    c.fieldEvaluations = a[12];
    c.inversions = a[13];
    c.inversionIterations = a[14];
    c.inversionFailures = a[15];
    c.volumeErrorSqSum = a[16];
    c.volumePixels = a[17];
    c.volumeErrorMax = a[18];
    c.volumeNodes = a[19];
    c.isoSubcellCulled = a[20];
    c.isoSubcellClipped = a[21];
    return c;
}

void RenderCounters::Merge(const RenderCounters& other) {
    auto a = ToArray();
    const auto b = other.ToArray();
    for (int i = 0; i < kSize; ++i) a[i] = IsMax(i) ? std::max(a[i], b[i]) : a[i] + b[i];
    *this = FromArray(a);
}

std::string StatsToJson(const RenderStats& s) {
    using nlohmann::json;
    const RenderCounters& c = s.counters;
    auto safeDiv = [](double a, double b) { return b > 0 ? a / b : 0.0; };
    json j;
    j["scene"] = s.scene;
    j["mesh"] = s.mesh;
    if (s.timeStep >= 0) j["time"] = {{"step", s.timeStep}, {"value", s.time}};
    if (s.frame >= 0) j["frame"] = s.frame;
    j["ranks"] = s.ranks;
    j["threads"] = s.threads;
    j["image"] = {s.width, s.height};
    j["camera"] = {{"position", s.cameraPosition}, {"look_at", s.cameraLookAt},
                   {"up", s.cameraUp}, {"width", s.width}, {"height", s.height}};
    if (s.cameraOrthographic)
        j["camera"]["ortho_height"] = s.cameraOrthoHeight;
    else
        j["camera"]["fov_y"] = s.cameraFovY;
    j["timing_s"] = {{"load", s.timing.load},           {"accel", s.timing.accel},
                     {"render", s.timing.render},       {"composite", s.timing.composite},
                     {"write", s.timing.write},         {"total", s.timing.total}};
    if (s.ranks > 1) {
        j["distribute"] = s.distribute;
        j["timing_s"]["prepass"] = s.timing.prepass;
        j["timing_s"]["wait"] = s.timing.wait;
        j["timing_s"]["render_min"] = s.timing.renderMin;
    }
    j["rays"] = c.rays;
    j["segments"] = c.segments;
    j["segments_culled"] = c.segmentsCulled;
    j["warnings"] = s.warnings;
    j["bricks_loaded"] = s.bricksLoaded;
    j["bricks_total"] = s.bricksTotal;
    j["accel"] = {{"bytes", s.accelBytes}, {"bytes_per_cell", s.accelBytesPerCell}};
    const double range = s.isoFieldRange[1] - s.isoFieldRange[0];
    const double rms = std::sqrt(safeDiv(c.isoResidualSqSum, c.isoHits));
    j["iso"] = {{"hits", c.isoHits},
                {"rms_residual", rms},
                {"max_residual", c.isoResidualMax},
                {"rms_residual_relative", safeDiv(rms, range)},
                {"max_residual_relative", safeDiv(c.isoResidualMax, range)},
                {"field_range", {s.isoFieldRange[0], s.isoFieldRange[1]}},
                {"projections", c.projections},
                {"mean_projection_order", safeDiv(c.projectionOrderSum, c.projections)},
                {"max_projection_order", c.projectionOrderMax},
                {"projection_unconverged", c.projectionUnconverged},
                {"root_failures", c.rootFailures},
                {"field_evaluations", c.fieldEvaluations},
                {"subcell_culled", c.isoSubcellCulled},
                {"subcell_clipped", c.isoSubcellClipped}};
    j["mapping"] = {{"inversions", c.inversions},
                    {"mean_iterations", safeDiv(c.inversionIterations, c.inversions)},
                    {"failures", c.inversionFailures}};
    j["volume"] = {{"rms_error_estimate", std::sqrt(safeDiv(c.volumeErrorSqSum, c.volumePixels))},
                   {"max_error_estimate", c.volumeErrorMax},
                   {"quadrature_nodes", c.volumeNodes}};
    if (s.hasVolume) {
        json& v = j["volume"];
        v["color_field"] = s.volumeColorField;
        v["extinction_field"] = s.volumeExtinctionField;
        v["color_tf"] = s.volumeColorTf;
        v["extinction_tf"] = s.volumeExtinctionTf;
    }
    const TraversalStats& tr = s.traversal;
    j["traversal"] = {{"nonconforming_faces", tr.nonConformingFaces},
                      {"nonconforming_edges", tr.nonConformingEdges},
                      {"nonconformity", tr.nonConformity},
                      {"walk_repairs", tr.walkRepairs},
                      {"walk_failures", tr.walkFailures},
                      {"face_newton_failures", tr.faceNewtonFailures}};
    j["composite"] = {{"rounds", s.composite.rounds},
                      {"bytes_per_pixel", s.composite.bytesPerPixel},
                      {"bytes_sent_max", s.composite.bytesSentMax},
                      {"bytes_sent_total", s.composite.bytesSentTotal},
                      {"bytes_gather", s.composite.bytesGather}};
    return j.dump(2) + "\n";
}

void WriteStats(const std::string& path, const RenderStats& stats) {
    const std::string tmp = detail::BeginOutputFile(path);
    const std::string text = StatsToJson(stats);
    std::FILE* file = std::fopen(tmp.c_str(), "wb");
    if (!file) throw InputError(path, "", "cannot open for writing");
    const bool ok = std::fwrite(text.data(), 1, text.size(), file) == text.size();
    if (std::fclose(file) != 0 || !ok) {
        detail::AbandonOutputFile(tmp);
        throw InputError(path, "", "write failed");
    }
    detail::CommitOutputFile(tmp, path);
}

}  // namespace hpray
