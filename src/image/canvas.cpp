// Drawing on the PNG's picture: anti-aliased lines by coverage, rectangles, bitmap text.
#include "image/canvas.h"

#include <algorithm>
#include <cmath>

#include "image/font.h"
#include "util/check.h"

namespace hpray {

namespace {

/// The parameter range [u0, u1] of the part of `p` inside the rectangle [xlo, xhi] x
/// [ylo, yhi] (Liang-Barsky); false if no part is.
bool ClipToRect(const LinePiece& p, double xlo, double ylo, double xhi, double yhi,
                double& u0, double& u1) {
    u0 = 0;
    u1 = 1;
    const double dx = p.x1 - p.x0, dy = p.y1 - p.y0;
    // Inside iff pk * u <= qk for every side k.
    const double sides[4][2] = {
        {-dx, p.x0 - xlo}, {dx, xhi - p.x0}, {-dy, p.y0 - ylo}, {dy, yhi - p.y0}};
    for (const auto& side : sides) {
        const double pk = side[0], qk = side[1];
        if (pk == 0) {
            if (qk < 0) return false;
            continue;
        }
        const double r = qk / pk;
        if (pk < 0)
            u0 = std::max(u0, r);
        else
            u1 = std::min(u1, r);
    }
    return u0 <= u1;
}

/// Distance from (px, py) to the piece and the parameter of its nearest point.
double DistanceTo(const LinePiece& p, double px, double py, double& u) {
    const double dx = p.x1 - p.x0, dy = p.y1 - p.y0;
    const double length2 = dx * dx + dy * dy;
    u = length2 > 0
            ? std::clamp(((px - p.x0) * dx + (py - p.y0) * dy) / length2, 0.0, 1.0)
            : 0.0;
    return std::hypot(p.x0 + u * dx - px, p.y0 + u * dy - py);
}

}  // namespace

Canvas Canvas::Over(const Image& image, const Rgb& background) {
    const std::size_t n = image.PixelCount();
    HPRAY_CHECK(image.r.size() == n && image.g.size() == n && image.b.size() == n &&
                image.a.size() == n);
    Canvas canvas;
    canvas.width = image.width;
    canvas.height = image.height;
    canvas.rgb.resize(3 * n);
    for (std::size_t p = 0; p < n; ++p) {
        const double transmit = 1.0 - image.a[p];
        canvas.rgb[3 * p + 0] = image.r[p] + transmit * background[0];
        canvas.rgb[3 * p + 1] = image.g[p] + transmit * background[1];
        canvas.rgb[3 * p + 2] = image.b[p] + transmit * background[2];
    }
    return canvas;
}

Rgb Canvas::At(int i, int j) const {
    const std::size_t p = 3 * (static_cast<std::size_t>(j) * width + i);
    return {rgb[p], rgb[p + 1], rgb[p + 2]};
}

void Canvas::Blend(int i, int j, const Rgb& color, double alpha) {
    if (i < 0 || j < 0 || i >= width || j >= height || !(alpha > 0)) return;
    alpha = std::min(alpha, 1.0);
    double* p = &rgb[3 * (static_cast<std::size_t>(j) * width + i)];
    for (int c = 0; c < 3; ++c) p[c] = (1 - alpha) * p[c] + alpha * color[c];
}

void Canvas::FillRect(int x, int y, int w, int h, const Rgb& color, double alpha) {
    const int i0 = std::max(x, 0), i1 = std::min(x + w, width);
    const int j0 = std::max(y, 0), j1 = std::min(y + h, height);
    for (int j = j0; j < j1; ++j)
        for (int i = i0; i < i1; ++i) Blend(i, j, color, alpha);
}

void Canvas::FrameRect(int x, int y, int w, int h, int thickness, const Rgb& color) {
    const int t = thickness;
    FillRect(x - t, y - t, w + 2 * t, t, color);  // top
    FillRect(x - t, y + h, w + 2 * t, t, color);  // bottom
    FillRect(x - t, y, t, h, color);              // left
    FillRect(x + w, y, t, h, color);              // right
}

std::vector<float> LineCoverage(int width, int height,
                                const std::vector<LinePiece>& pieces, double lineWidth,
                                const LineVisibility& visible) {
    std::vector<float> coverage(static_cast<std::size_t>(width) * height, 0.0f);
    // A pixel centre farther than `reach` from a piece gets none of it.
    const double reach = 0.5 * lineWidth + 0.5;
    for (std::size_t k = 0; k < pieces.size(); ++k) {
        const LinePiece& p = pieces[k];
        double u0, u1;
        if (!ClipToRect(p, -reach - 1, -reach - 1, width + reach + 1, height + reach + 1,
                        u0, u1))
            continue;
        // Walk the major axis pixel by pixel over the part on the canvas; across it, the
        // pixels within reach of the line (measured along the minor axis: reach / cos).
        const double dx = p.x1 - p.x0, dy = p.y1 - p.y0;
        const bool alongX = std::fabs(dx) >= std::fabs(dy);
        const double major0 = alongX ? p.x0 : p.y0, dMajor = alongX ? dx : dy;
        const double minor0 = alongX ? p.y0 : p.x0, dMinor = alongX ? dy : dx;
        const double slope = dMajor != 0 ? dMinor / dMajor : 0.0;
        const double across = reach * std::sqrt(1 + slope * slope) + 1;
        const double m0 = major0 + u0 * dMajor, m1 = major0 + u1 * dMajor;
        const int majorSize = alongX ? width : height,
                  minorSize = alongX ? height : width;
        const int a0 =
            std::max(0, static_cast<int>(std::floor(std::min(m0, m1) - reach)));
        const int a1 = std::min(majorSize - 1,
                                static_cast<int>(std::floor(std::max(m0, m1) + reach)));
        for (int a = a0; a <= a1; ++a) {
            const double uc =
                dMajor != 0 ? std::clamp((a + 0.5 - major0) / dMajor, u0, u1) : u0;
            const double centre = minor0 + uc * dMinor;
            const int b0 = std::max(0, static_cast<int>(std::floor(centre - across)));
            const int b1 =
                std::min(minorSize - 1, static_cast<int>(std::floor(centre + across)));
            for (int b = b0; b <= b1; ++b) {
                const int i = alongX ? a : b, j = alongX ? b : a;
                double u;
                const double d = DistanceTo(p, i + 0.5, j + 0.5, u);
                const double c = std::clamp(reach - d, 0.0, 1.0);
                float& out = coverage[static_cast<std::size_t>(j) * width + i];
                if (c <= out) continue;
                const double seen =
                    visible ? std::clamp(visible(k, u, i, j), 0.0, 1.0) : 1.0;
                out = std::max(out, static_cast<float>(c * seen));
            }
        }
    }
    return coverage;
}

void DrawCoverage(Canvas& canvas, const std::vector<float>& coverage, const Rgb& color) {
    HPRAY_CHECK_EQ(coverage.size(),
                   static_cast<std::size_t>(canvas.width) * canvas.height);
    for (int j = 0; j < canvas.height; ++j)
        for (int i = 0; i < canvas.width; ++i)
            canvas.Blend(i, j, color,
                         coverage[static_cast<std::size_t>(j) * canvas.width + i]);
}

int TextWidth(const std::string& text, int scale) {
    return text.empty() ? 0
                        : (static_cast<int>(text.size()) * font::kAdvance - 1) * scale;
}

int TextHeight(int scale) { return font::kGlyphHeight * scale; }

void DrawText(Canvas& canvas, int x, int y, const std::string& text, int scale,
              const Rgb& color) {
    for (std::size_t k = 0; k < text.size(); ++k) {
        const std::uint8_t* rows = font::Glyph(text[k]);
        const int left = x + static_cast<int>(k) * font::kAdvance * scale;
        for (int r = 0; r < font::kGlyphHeight; ++r)
            for (int c = 0; c < font::kGlyphWidth; ++c)
                if ((rows[r] >> (font::kGlyphWidth - 1 - c)) & 1)
                    canvas.FillRect(left + c * scale, y + r * scale, scale, scale, color);
    }
}

}  // namespace hpray
