// Primary rays of the scene camera (docs/contracts.md, Camera), double precision.
#pragma once

#include <array>
#include <optional>

#include "geom/kd_tree.h"
#include "scene/scene.h"

namespace hpray {

/// A primary ray: world origin and unit world direction; t is world distance along it.
struct CameraRay {
    std::array<double, 3> origin{0.0, 0.0, 0.0};
    std::array<double, 3> direction{0.0, 0.0, 1.0};
};

/// The camera frame and ray generation of docs/contracts.md:
/// forward = normalize(look_at - position), right = normalize(forward x up),
/// trueUp = right x forward. Pixel (i, j): i left to right, j top to bottom, sampled at
/// its centre. Cheap to copy; immutable after construction.
class Camera {
  public:
    /// `settings` must be valid (LoadScene guarantees it); a degenerate frame is an
    /// internal error here.
    explicit Camera(const SceneCamera& settings);

    /// The ray through the centre of pixel (i, j), i in [0, width), j in [0, height).
    CameraRay PixelRay(int i, int j) const { return RayAt(i + 0.5, j + 0.5); }

    /// The ray through the continuous image point (x, y): x in [0, width] from the left
    /// edge, y in [0, height] from the top edge, in pixels (pixel centres at +0.5).
    /// Perspective: origin = position, direction = normalize(forward + sx right + sy
    /// trueUp) with sx = (2x/W - 1)(W/H) tan(fov_y/2), sy = (1 - 2y/H) tan(fov_y/2).
    /// Orthographic: direction = forward, origin = position + sx' right + sy' trueUp with
    /// sx' = (2x/W - 1)(W/H) ortho_height/2, sy' = (1 - 2y/H) ortho_height/2.
    CameraRay RayAt(double x, double y) const;

    /// The distance of world point `p` in front of the camera: along forward from the
    /// camera's position (perspective) or from its image plane (orthographic).
    double Depth(const std::array<double, 3>& p) const;
    /// The inverse of RayAt: the image point (x, y) whose ray passes through `p`. For a
    /// perspective camera `p` must lie in front of it (Depth(p) > 0).
    std::array<double, 2> ImagePoint(const std::array<double, 3>& p) const;
    /// The ray parameter t at which the ray of ImagePoint(p) reaches `p`: |p - position|
    /// (perspective) or Depth(p) (orthographic); comparable with the image's Z channel.
    double RayParameter(const std::array<double, 3>& p) const;

    int Width() const { return width_; }
    int Height() const { return height_; }
    bool Orthographic() const { return orthographic_; }
    const std::array<double, 3>& Position() const { return position_; }
    const std::array<double, 3>& Forward() const { return forward_; }  ///< unit
    const std::array<double, 3>& Right() const { return right_; }      ///< unit
    const std::array<double, 3>& TrueUp() const { return trueUp_; }    ///< unit

  private:
    std::array<double, 3> position_{};
    std::array<double, 3> forward_{};
    std::array<double, 3> right_{};
    std::array<double, 3> trueUp_{};
    int width_ = 1;
    int height_ = 1;
    bool orthographic_ = false;
    double aspect_ = 1.0;      ///< W / H
    double halfExtent_ = 1.0;  ///< tan(fov_y / 2), or ortho_height / 2
};

/// What orders k-d leaves front to back for this camera: its position (perspective), or
/// look_at - position (orthographic, the ray direction).
ViewOrigin ViewOriginOf(const SceneCamera& camera);

/// Places an automatic camera (SceneCamera::autoFit; `camera: auto`) for data whose
/// guaranteed bounds are `bounds`, seen through `clip` when the scene has a clip box
/// (their intersection is what is fitted): look_at is the box's centre (or the given
/// look_at), the eye is on the side `view` names (iso: along (1, 1, 1)), turned by
/// `azimuth` about `up` and raised by `elevation` toward it, at the distance from which
/// the box's projection just fits 90% of the image's width and height about the image
/// centre (the nearest such eye; the limiting side is 90% filled), divided by `zoom`
/// (orthographic cameras stay outside the sphere around the box; their ortho_height is the
/// given one over `zoom`). Without a given up: +y, or -z and +z for views from +y and -y. The camera is
/// then an ordinary one (autoFit false). Does nothing to a camera that is not automatic.
void FitCamera(SceneCamera& camera, const Box& bounds, const std::optional<Box>& clip);

}  // namespace hpray
