// Primary ray generation for perspective and orthographic cameras.
#include "scene/camera.h"

#include <cmath>

#include "util/check.h"

namespace hpray {

namespace {

using Vec3 = std::array<double, 3>;

Vec3 Cross(const Vec3& a, const Vec3& b) {
    return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0]};
}

double Length(const Vec3& a) {
    return std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
}

Vec3 Normalize(const Vec3& a) {
    const double length = Length(a);
    HPRAY_CHECK_MSG(length > 0.0 && std::isfinite(length),
                    "cannot normalise a zero vector");
    return {a[0] / length, a[1] / length, a[2] / length};
}

}  // namespace

Camera::Camera(const SceneCamera& settings)
    : position_(settings.position),
      width_(settings.width),
      height_(settings.height),
      orthographic_(settings.orthographic) {
    HPRAY_CHECK(width_ >= 1 && height_ >= 1);
    forward_ =
        Normalize({settings.lookAt[0] - position_[0], settings.lookAt[1] - position_[1],
                   settings.lookAt[2] - position_[2]});
    right_ = Normalize(Cross(forward_, settings.up));
    trueUp_ = Cross(right_, forward_);
    aspect_ = static_cast<double>(width_) / static_cast<double>(height_);
    if (orthographic_) {
        HPRAY_CHECK(settings.orthoHeight > 0.0);
        halfExtent_ = settings.orthoHeight / 2.0;
    } else {
        HPRAY_CHECK(settings.fovYDegrees > 0.0 && settings.fovYDegrees < 180.0);
        const double pi = 3.14159265358979323846;
        halfExtent_ = std::tan(settings.fovYDegrees * pi / 180.0 / 2.0);
    }
}

CameraRay Camera::RayAt(double x, double y) const {
    const double sx = (2.0 * x / width_ - 1.0) * aspect_ * halfExtent_;
    const double sy = (1.0 - 2.0 * y / height_) * halfExtent_;
    CameraRay ray;
    if (orthographic_) {
        for (int k = 0; k < 3; ++k)
            ray.origin[k] = position_[k] + sx * right_[k] + sy * trueUp_[k];
        ray.direction = forward_;
    } else {
        ray.origin = position_;
        ray.direction = Normalize({forward_[0] + sx * right_[0] + sy * trueUp_[0],
                                   forward_[1] + sx * right_[1] + sy * trueUp_[1],
                                   forward_[2] + sx * right_[2] + sy * trueUp_[2]});
    }
    return ray;
}

ViewOrigin ViewOriginOf(const SceneCamera& camera) {
    if (!camera.orthographic) return ViewOrigin::Perspective(camera.position);
    // Only the sign of each component matters, so no normalisation is needed.
    return ViewOrigin::Orthographic({camera.lookAt[0] - camera.position[0],
                                     camera.lookAt[1] - camera.position[1],
                                     camera.lookAt[2] - camera.position[2]});
}

}  // namespace hpray
