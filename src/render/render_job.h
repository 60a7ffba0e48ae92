// A whole render job on one process: load what the scene needs, build the acceleration
// structures, ray-cast, composite, write the outputs and the stats.
#pragma once

#include "image/image.h"
#include "mesh/mesh.h"
#include "trace/ray.h"

#include <functional>
#include <memory>
#include <optional>
#include <vector>
#include "render/stats.h"
#include "scene/scene.h"

namespace hpray {

struct SegmentCostSample;
struct MeshGeometry;
class Camera;

/// Renders `scene` for a mesh already in memory on this process and writes every output
/// it names (EXR, PNG, stats, hits, rgba); returns the image and fills `stats`
/// (`loadSeconds` is reported as timing_s.load). Jobs that read their data and may run on
/// many ranks are job/frame_job.h's FrameJob.
Image RenderMeshJob(const Mesh& mesh, const Scene& scene, RenderStats& stats,
                    double loadSeconds = 0);

/// Renders one brick — `mesh` with its rays clipped to `box` (std::nullopt: the guaranteed
/// bounds of all its cells) — into `image` (resized to the camera), adding the accel and
/// render times, counters, field range and accel bytes to `stats`. With `costSamples`,
/// the measured cost of every segment is appended to it (brick_renderer.h).
void RenderOneBrick(const Mesh& mesh, const std::optional<Box>& box, const Scene& scene,
                    Image& image, RenderStats& stats,
                    std::vector<SegmentCostSample>* costSamples = nullptr,
                    const Image* front = nullptr,
                    const std::function<bool()>& cancelled = {});

/// A brick ready to render many times: geometry, traverser and per-field setup built once
/// (the in-memory split renders a pre-pass and then its own box of the same mesh).
class PreparedBrick {
  public:
    /// Builds for `mesh` with rays clipped to `box` (std::nullopt: the guaranteed bounds
    /// of all cells); adds the build time to stats.timing.accel and the accel bytes.
    PreparedBrick(const Mesh& mesh, const std::optional<Box>& box, const Scene& scene,
                  RenderStats& stats);
    ~PreparedBrick();
    PreparedBrick(const PreparedBrick&) = delete;
    PreparedBrick& operator=(const PreparedBrick&) = delete;

    /// Renders for `camera` with rays further clipped to `clip` (besides the scene's clip
    /// box), adding the render time and counters to `stats`; see RenderOneBrick.
    /// `front`: the composite of what lies in front; pixels it makes opaque are not traced
    /// (brick_renderer.h: RenderBrick).
    void Render(const Scene& scene, const Camera& camera, const std::optional<Box>& clip,
                Image& image, RenderStats& stats,
                std::vector<SegmentCostSample>* costSamples = nullptr,
                const Image* front = nullptr);

    /// Renders only tiles [begin, end) of the camera's image (brick_renderer.h:
    /// RenderBrickTiles) into `image`, which must have the camera's size; other pixels are
    /// left as they are. For splitting the pixels of one view between ranks.
    void RenderTiles(const Scene& scene, const Camera& camera, int begin, int end,
                     Image& image, RenderStats& stats);

    /// Rebuilds the per-scene set-up (fields, isosurfaces, slices, volume, clip,
    /// accuracy) for `scene`, keeping the geometry and the traversal; adds the time to
    /// stats.timing.accel and the fields' range to the stats. The scene must name only
    /// fields the mesh holds and the same accuracy.mapping_tolerance (the traversal's).
    void Reconfigure(const Scene& scene, RenderStats& stats);
    double MappingTolerance() const;

    /// Cooperative cancellation of the following renders (BrickSetup::cancelled): asked
    /// before each tile; an empty function (the default) renders every tile.
    void SetCancel(std::function<bool()> cancelled);
    /// Progress lines every `seconds` during the following renders (0: none; see
    /// BrickSetup::progressSeconds).
    void SetProgress(double seconds);

    const MeshGeometry& Geometry() const;

  private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

/// Checks the outputs the scene names before any work: an extension of another known
/// format (output.png: x.jpg), a path that is a folder, or a folder that cannot be
/// written are InputErrors naming the key.
void CheckJobOutputs(const Scene& scene);

/// Writes the outputs the scene names (EXR, PNG, hits, rgba; then stats), timing the
/// writes into stats.timing.write. The PNG carries the scene's outline and legend
/// (render/annotate.h), the outline of `dataBounds` (the data's guaranteed bounds); the
/// other files are the image as rendered.
void WriteJobOutputs(const Scene& scene, const Image& image, const Box& dataBounds,
                     RenderStats& stats);

/// A fresh RenderStats for a scene (scene, mesh, threads, image size).
RenderStats StartStats(const Scene& scene);

/// The float64 (H, W, 5) hits array (docs/contracts.md): t, N, residual per pixel.
std::vector<double> HitsArray(const Image& image);
/// The float32 (H, W, 2) error array: iso.residual (NaN where no hit), vol.error.
std::vector<float> ErrorArray(const Image& image);
/// The float64 (H, W, 4) premultiplied R, G, B, A array.
std::vector<double> RgbaArray(const Image& image);

}  // namespace hpray
