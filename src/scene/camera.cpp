// Primary ray generation for perspective and orthographic cameras.
#include "scene/camera.h"

#include <algorithm>
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

double Camera::Depth(const std::array<double, 3>& p) const {
    return (p[0] - position_[0]) * forward_[0] + (p[1] - position_[1]) * forward_[1] +
           (p[2] - position_[2]) * forward_[2];
}

std::array<double, 2> Camera::ImagePoint(const std::array<double, 3>& p) const {
    const Vec3 d = {p[0] - position_[0], p[1] - position_[1], p[2] - position_[2]};
    double sx = d[0] * right_[0] + d[1] * right_[1] + d[2] * right_[2];
    double sy = d[0] * trueUp_[0] + d[1] * trueUp_[1] + d[2] * trueUp_[2];
    if (!orthographic_) {
        // The ray direction is forward + sx right + sy trueUp, normalised: p lies on it
        // where its offsets across the view, divided by its depth, are sx and sy.
        const double depth = Depth(p);
        HPRAY_CHECK_MSG(depth > 0, "a point behind the camera has no image point");
        sx /= depth;
        sy /= depth;
    }
    // RayAt solved for x and y.
    return {0.5 * width_ * (1.0 + sx / (aspect_ * halfExtent_)),
            0.5 * height_ * (1.0 - sy / halfExtent_)};
}

double Camera::RayParameter(const std::array<double, 3>& p) const {
    if (orthographic_) return Depth(p);
    return Length({p[0] - position_[0], p[1] - position_[1], p[2] - position_[2]});
}

ViewOrigin ViewOriginOf(const SceneCamera& camera) {
    if (!camera.orthographic) return ViewOrigin::Perspective(camera.position);
    // Only the sign of each component matters, so no normalisation is needed.
    return ViewOrigin::Orthographic({camera.lookAt[0] - camera.position[0],
                                     camera.lookAt[1] - camera.position[1],
                                     camera.lookAt[2] - camera.position[2]});
}

void FitCamera(SceneCamera& camera, const Box& bounds, const std::optional<Box>& clip) {
    if (!camera.autoFit) return;
    constexpr double kAutoFill = 0.9;  // the box fills 90% of the view where it is tightest
    using V = std::array<double, 3>;
    auto dot = [](const V& a, const V& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; };
    auto cross = [](const V& a, const V& b) {
        return V{a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
    };
    auto unit = [&](V a) {
        const double n = std::sqrt(dot(a, a));
        for (double& x : a) x /= n;
        return a;
    };
    Box box = bounds;
    if (clip) {
        const Box cut = bounds.Intersect(*clip);
        if (!cut.IsEmpty()) box = cut;
    }
    V lo = box.lo, hi = box.hi;
    for (int d = 0; d < 3; ++d)
        if (!(lo[d] <= hi[d]) || !std::isfinite(lo[d]) || !std::isfinite(hi[d])) lo[d] = hi[d] = 0;
    V centre;
    for (int d = 0; d < 3; ++d) centre[d] = 0.5 * (lo[d] + hi[d]);
    if (camera.lookAtGiven) centre = camera.lookAt;
    // The sphere about the centre that holds the whole box.
    double radius = 0;
    for (int q = 0; q < 8; ++q) {
        V corner;
        for (int d = 0; d < 3; ++d) corner[d] = ((q >> d) & 1 ? hi[d] : lo[d]) - centre[d];
        radius = std::max(radius, std::sqrt(dot(corner, corner)));
    }
    if (!(radius > 0)) radius = 1;

    V eye = {1, 1, 1};
    V up = {0, 1, 0};
    const std::string& v = camera.view;
    if (v == "+x") eye = {1, 0, 0};
    if (v == "-x") eye = {-1, 0, 0};
    if (v == "+y") eye = {0, 1, 0}, up = {0, 0, -1};
    if (v == "-y") eye = {0, -1, 0}, up = {0, 0, 1};
    if (v == "+z") eye = {0, 0, 1};
    if (v == "-z") eye = {0, 0, -1};
    if (camera.upGiven) up = camera.up;
    eye = unit(eye);
    up = unit(up);
    // Azimuth: about up (right-handed); elevation: toward up, never past the pole.
    const double az = camera.azimuthDegrees * M_PI / 180;
    const V side = cross(up, eye);
    const double along = dot(eye, up);
    V flat;  // eye's part across up
    for (int d = 0; d < 3; ++d) flat[d] = eye[d] - along * up[d];
    for (int d = 0; d < 3; ++d)
        eye[d] = along * up[d] + std::cos(az) * flat[d] + std::sin(az) * side[d];
    double elevation = std::asin(std::clamp(dot(unit(eye), up), -1.0, 1.0)) +
                       camera.elevationDegrees * M_PI / 180;
    elevation = std::clamp(elevation, -89.0 * M_PI / 180, 89.0 * M_PI / 180);
    V across;
    for (int d = 0; d < 3; ++d) across[d] = eye[d] - dot(eye, up) * up[d];
    const double acrossLength = std::sqrt(dot(across, across));
    if (acrossLength > 1e-12) {
        for (int d = 0; d < 3; ++d)
            eye[d] = std::cos(elevation) * across[d] / acrossLength + std::sin(elevation) * up[d];
    } else {
        // Looking along up (a given up parallel to the view): any side will do.
        up = std::fabs(eye[1]) < 0.9 ? V{0, 1, 0} : V{1, 0, 0};
    }
    eye = unit(eye);

    const double aspect = double(camera.width) / camera.height;
    double distance;
    if (camera.orthographic) {
        camera.orthoHeight /= camera.zoom;
        distance = 2 * radius;
    } else {
        // The nearest eye from which every corner of the box lies within kAutoFill of the
        // image's half-width and half-height about its centre (camera.h: Camera::RayAt):
        // a corner at c (from the centre) has depth distance + c.forward and needs
        // |c.right| <= kAutoFill tx depth and |c.trueUp| <= kAutoFill ty depth. The box is
        // the hull of its corners, so all of it is then in view.
        const V forward = {-eye[0], -eye[1], -eye[2]};
        const V right = unit(cross(forward, up));
        const V trueUp = cross(right, forward);
        const double ty = std::tan(0.5 * camera.fovYDegrees * M_PI / 180), tx = ty * aspect;
        distance = 0;
        for (int q = 0; q < 8; ++q) {
            V corner;
            for (int d = 0; d < 3; ++d) corner[d] = ((q >> d) & 1 ? hi[d] : lo[d]) - centre[d];
            const double depth = dot(corner, forward);
            distance = std::max({distance,
                                 std::fabs(dot(corner, right)) / (kAutoFill * tx) - depth,
                                 std::fabs(dot(corner, trueUp)) / (kAutoFill * ty) - depth,
                                 // never at a corner (a flat box seen edge-on)
                                 1e-3 * radius - depth});
        }
        distance /= camera.zoom;
    }
    for (int d = 0; d < 3; ++d) camera.position[d] = centre[d] + distance * eye[d];
    camera.lookAt = centre;
    camera.up = up;
    camera.autoFit = false;  // placed: an ordinary camera from here on
}

}  // namespace hpray
