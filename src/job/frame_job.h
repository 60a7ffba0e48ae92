// A render job that lives across frames: the data loaded once, the whole mesh prepared
// once, the ranks' plan; each frame renders a camera on every rank and composites it.
#pragma once

#include <array>
#include <functional>
#include <memory>
#include <optional>
#include <set>
#include <string>

#include <mpi.h>

#include "image/image.h"
#include "io/mesh_io.h"
#include "job/brick_plan.h"
#include "render/render_job.h"
#include "render/stats.h"
#include "scene/scene.h"

namespace hpray::job {

/// The step of `collection` that `scene.data.time` selects (0 without it). Throws
/// InputError naming the scene's data.time when the collection has no such step, or when
/// there is no collection (nullptr).
int ResolveTimeStep(const Scene& scene, const Collection* collection);

/// How a job's ranks share a frame (scene.h Distribution, resolved).
enum class Split { None, Image, Space };

/// A render job over MPI_COMM_WORLD (one process or many). Construction and every Render
/// are collective: every rank constructs it with the same scene and calls Render with the
/// same camera, in the same order.
///
/// Construction reads the data the scene names: a mesh (every rank holds it whole and
/// prepares it: geometry, traversal, per-field set-up), one time step of a .pvd
/// collection (`data.time`; held and prepared as a mesh) or a partition directory (the
/// manifest; each frame reads the bricks a rank renders and can contribute). Frames of
/// another camera reuse all of it; see Render for frames that change more.
class FrameJob {
  public:
    /// Throws InputError for bad input (the same on every rank: the scene and data are
    /// checked before any collective that could leave ranks waiting).
    explicit FrameJob(const Scene& scene);
    ~FrameJob();
    FrameJob(const FrameJob&) = delete;
    FrameJob& operator=(const FrameJob&) = delete;

    /// Renders the job's scene seen through `camera` (nullopt: the scene's camera). On
    /// rank 0 returns the composited image and fills `stats` (reduced over ranks; the
    /// first frame also carries the load and preparation times); other ranks return
    /// scratch. Writes no file.
    Image Render(const std::optional<SceneCamera>& camera, RenderStats& stats);

    /// What a frame changes against the job's current scene.
    enum class Change { CameraOnly, Scene };
    /// Renders `scene` (same data as the job's; `threads` and `distribute` stay the
    /// job's) and makes it the job's current scene. CameraOnly reuses all preparation;
    /// Scene keeps the data and the traversal and rebuilds the per-scene set-up (field
    /// ranges, transfer functions), loading fields not yet loaded (then the mesh is read
    /// and prepared again). A scene whose `data.time` selects another step of the job's
    /// collection is a Scene change whatever `change` says: that step is read and
    /// prepared in place of the current one. Throws InputError if `scene` names other
    /// data or a time step the collection does not have.
    ///
    /// `cancelRequest` makes the frame cancellable. It is part of the collective contract:
    /// every rank passes one, or none does. Rank 0's is asked while the frame renders
    /// (from any of its threads; other ranks' are never called); once it answers true,
    /// every rank stops taking tiles within about one tile's time, the frame is neither
    /// composited nor reduced, Cancelled() is true on every rank and the image is empty.
    Image Render(const Scene& scene, Change change, RenderStats& stats,
                 const std::function<bool()>& cancelRequest = {});
    /// Whether the last frame was cancelled (the same answer on every rank).
    bool Cancelled() const { return cancelled_; }

    /// On rank 0, after a frame: what probably went wrong, in words a user can act on —
    /// an isovalue outside its field's range over the data, an image with nothing drawn,
    /// mapping or root failures on more than 0.1% of the segments. Added to stats.warnings.
    void AddWarnings(const Scene& scene, const Image& image, RenderStats& stats) const;

    Split Distribution() const { return split_; }
    const Scene& GetScene() const { return scene_; }
    /// The guaranteed bounds of the data (the whole mesh's cells, or the partition's
    /// bricks): what an automatic camera fits (scene/camera.h: FitCamera).
    Box DataBounds() const;
    /// The diagonal of the data's bounds: the scale of a default volume's extinction.
    double DataSize() const;
    /// [min, max] of a field over the data (nothing if the data has no such field).
    std::optional<std::array<double, 2>> FieldRange(const std::string& name) const;
    /// The whole mesh every rank holds (nullptr for a partition directory).
    const Mesh* WholeMesh() const { return whole_ ? &*whole_ : nullptr; }
    /// The partition's manifest (nullptr for a mesh).
    const partition::Partition* GetPartition() const { return part_ ? &*part_ : nullptr; }
    /// The .pvd collection the data comes from (nullptr for other data), and the index of
    /// the step the job holds.
    const Collection* GetCollection() const { return collection_ ? &*collection_ : nullptr; }
    int TimeStep() const { return timeStep_; }
    /// The step of the job's collection that `scene.data.time` selects (ResolveTimeStep).
    int TimeStepOf(const Scene& scene) const { return ResolveTimeStep(scene, GetCollection()); }

  private:
    class FrameCancel;
    Image RenderSingle(const Scene& scene, RenderStats& stats, FrameCancel* cancel);
    Image RenderDistributed(const Scene& scene, RenderStats& stats, FrameCancel* cancel);
    /// Reads the whole mesh (readOptions_, and the job's time step of a collection).
    void LoadWhole();

    Scene scene_;
    Split split_ = Split::None;
    std::optional<partition::Partition> part_;
    std::optional<Mesh> whole_;
    std::optional<Collection> collection_;
    int timeStep_ = 0;
    std::unique_ptr<PreparedBrick> prepared_;
    BrickPlan partitionPlan_;
    ReadOptions readOptions_;
    RenderStats setupStats_;  ///< load and preparation, reported with the next frame
    std::set<std::string> loadedFields_;
    bool firstFrame_ = true;
    bool cancelled_ = false;
    /// Rank 0's cancellation messages to the other ranks (a communicator of their own, so
    /// they never match the compositor's messages).
    MPI_Comm cancelComm_ = MPI_COMM_NULL;
};

}  // namespace hpray::job
