// Tests of the 'over' operator and active-pixel encoding against closed forms.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <limits>
#include <random>
#include <vector>

#include "active_pixels.h"
#include "image/image.h"
#include "util/error.h"

namespace hpray::compositor {
namespace {

const double kInf = std::numeric_limits<double>::infinity();

/// A random non-empty pixel: premultiplied colour (rgb <= a), a hit with probability 1/2.
Pixel RandomPixel(std::mt19937& rng) {
    std::uniform_real_distribution<double> u(0.0, 1.0);
    Pixel p;
    p.rgba[3] = u(rng);
    p.rgba[0] = p.rgba[3] * u(rng);
    p.rgba[1] = p.rgba[3] * u(rng);
    p.rgba[2] = p.rgba[3] * u(rng);
    if (u(rng) < 0.5) {
        p.z = 10.0 * u(rng);
        p.normal[0] = u(rng);
        p.normal[1] = u(rng);
        p.normal[2] = u(rng);
        p.isoResidual = 1e-12 * u(rng);
        p.isoId = std::floor(4.0 * u(rng));
    }
    p.volError = 1e-8 * u(rng);
    return p;
}

/// Channel-wise comparison; NaN equals NaN.
void ExpectPixelNear(const Pixel& x, const Pixel& y, double tol,
                     const std::string& what) {
    const double xs[kChannels] = {x.rgba[0],  x.rgba[1],  x.rgba[2],           x.rgba[3],     x.z,       x.normal[0],
                                  x.normal[1], x.normal[2], x.isoResidual, x.isoId, x.volError};
    const double ys[kChannels] = {y.rgba[0],  y.rgba[1],  y.rgba[2],           y.rgba[3],     y.z,       y.normal[0],
                                  y.normal[1], y.normal[2], y.isoResidual, y.isoId, y.volError};
    for (int c = 0; c < kChannels; ++c) {
        if (std::isnan(xs[c]) || std::isnan(ys[c])) {
            EXPECT_TRUE(std::isnan(xs[c]) && std::isnan(ys[c]))
                << what << " channel " << c;
        } else if (std::isinf(xs[c]) || std::isinf(ys[c])) {
            EXPECT_EQ(xs[c], ys[c]) << what << " channel " << c;
        } else {
            EXPECT_NEAR(xs[c], ys[c], tol) << what << " channel " << c;
        }
    }
}

TEST(Over, ClosedFormOfTwoLayers) {
    Pixel front, back;
    front.rgba[0] = 0.1, front.rgba[1] = 0.2, front.rgba[2] = 0.3, front.rgba[3] = 0.4, front.volError = 1e-6;
    back.rgba[0] = 0.5, back.rgba[1] = 0.25, back.rgba[2] = 0.125, back.rgba[3] = 0.75, back.volError = 2e-6;
    back.z = 3.0, back.normal[0] = 1.0, back.isoResidual = 1e-13, back.isoId = 2.0;
    const Pixel out = Over(front, back);
    EXPECT_DOUBLE_EQ(out.rgba[0], 0.1 + 0.6 * 0.5);
    EXPECT_DOUBLE_EQ(out.rgba[1], 0.2 + 0.6 * 0.25);
    EXPECT_DOUBLE_EQ(out.rgba[2], 0.3 + 0.6 * 0.125);
    EXPECT_DOUBLE_EQ(out.rgba[3], 0.4 + 0.6 * 0.75);
    EXPECT_DOUBLE_EQ(out.volError, 3e-6);
    // The only hit is behind a translucent front: it is the nearest hit.
    EXPECT_EQ(out.z, 3.0);
    EXPECT_EQ(out.normal[0], 1.0);
    EXPECT_EQ(out.isoResidual, 1e-13);
    EXPECT_EQ(out.isoId, 2.0);
}

TEST(Over, NLayersOfEqualFogMatchBeerLambert) {
    // N slabs of optical depth d each: alpha_k = 1 - e^-d, colour c alpha_k; the whole
    // column has alpha 1 - e^(-N d) and colour c (1 - e^(-N d)).
    const double d = 0.3, c = 0.7;
    for (int layers = 1; layers <= 12; ++layers) {
        Pixel slab;
        slab.rgba[3] = 1.0 - std::exp(-d);
        slab.rgba[0] = slab.rgba[1] = slab.rgba[2] = c * slab.rgba[3];
        Pixel acc;
        for (int k = 0; k < layers; ++k) acc = Over(acc, slab);
        const double alpha = 1.0 - std::exp(-layers * d);
        EXPECT_NEAR(acc.rgba[3], alpha, 1e-15) << layers;
        EXPECT_NEAR(acc.rgba[0], c * alpha, 1e-15) << layers;
    }
}

TEST(Over, NearestHitWinsAndTiesKeepFront) {
    Pixel front, back;
    front.z = 2.0, front.normal[0] = 1.0, front.isoId = 0.0, front.isoResidual = 1e-3;
    back.z = 1.0, back.normal[1] = 1.0, back.isoId = 1.0, back.isoResidual = 2e-3;
    EXPECT_EQ(Over(front, back).isoId, 1.0);
    EXPECT_EQ(Over(front, back).normal[1], 1.0);
    EXPECT_EQ(Over(back, front).isoId, 1.0);
    back.z = 2.0;
    EXPECT_EQ(Over(front, back).isoId, 0.0);
    EXPECT_EQ(Over(back, front).isoId, 1.0);
}

TEST(Over, EmptyPixelIsTwoSidedIdentity) {
    std::mt19937 rng(7);
    const Pixel empty;
    EXPECT_TRUE(IsEmpty(empty));
    for (int k = 0; k < 200; ++k) {
        const Pixel p = RandomPixel(rng);
        ExpectPixelNear(Over(empty, p), p, 0.0, "empty over p");
        ExpectPixelNear(Over(p, empty), p, 0.0, "p over empty");
    }
}

TEST(Over, GlowWithoutOpacityIsNotEmpty) {
    Pixel glow;
    glow.rgba[0] = 0.2;  // emission with no absorption: alpha 0, colour adds
    EXPECT_FALSE(IsEmpty(glow));
    Pixel errorOnly;
    errorOnly.volError = 1e-9;
    EXPECT_FALSE(IsEmpty(errorOnly));
    Pixel hitOnly;
    hitOnly.z = 1.0;
    EXPECT_FALSE(IsEmpty(hitOnly));
}

/// Composites layers[first, last) with a random binary grouping.
Pixel RandomGrouping(const std::vector<Pixel>& layers, int first, int last,
                     std::mt19937& rng) {
    if (last - first == 1) return layers[first];
    std::uniform_int_distribution<int> cut(first + 1, last - 1);
    const int mid = cut(rng);
    return Over(RandomGrouping(layers, first, mid, rng),
                RandomGrouping(layers, mid, last, rng));
}

TEST(Over, AnyGroupingInTheSameOrderGivesTheSameResult) {
    for (int seed = 0; seed < 300; ++seed) {
        std::mt19937 rng(seed);
        const int n = 2 + seed % 7;
        std::vector<Pixel> layers;
        for (int k = 0; k < n; ++k) layers.push_back(RandomPixel(rng));
        Pixel leftFold = layers[0];
        for (int k = 1; k < n; ++k) leftFold = Over(leftFold, layers[k]);
        Pixel rightFold = layers[n - 1];
        for (int k = n - 2; k >= 0; --k) rightFold = Over(layers[k], rightFold);
        ExpectPixelNear(leftFold, rightFold, 1e-15, "seed " + std::to_string(seed));
        for (int g = 0; g < 5; ++g)
            ExpectPixelNear(leftFold, RandomGrouping(layers, 0, n, rng), 1e-15,
                            "seed " + std::to_string(seed));
    }
}

TEST(Over, WholeImagesOverAndUnder) {
    std::mt19937 rng(3);
    Image front, back;
    front.Resize(5, 3);
    back.Resize(5, 3);
    for (std::size_t p = 0; p < front.PixelCount(); ++p) {
        if (p % 3 != 0) StorePixel(front, p, RandomPixel(rng));
        if (p % 4 != 0) StorePixel(back, p, RandomPixel(rng));
    }
    Image over = front, under = back;
    CompositeOver(over, back);
    CompositeUnder(front, under);
    for (std::size_t p = 0; p < front.PixelCount(); ++p) {
        const Pixel expected = Over(LoadPixel(front, p), LoadPixel(back, p));
        ExpectPixelNear(LoadPixel(over, p), expected, 0.0, "over " + std::to_string(p));
        ExpectPixelNear(LoadPixel(under, p), expected, 0.0, "under " + std::to_string(p));
    }
    Image wrong;
    wrong.Resize(4, 3);
    EXPECT_THROW(CompositeOver(wrong, back), InternalError);
}

/// An image whose pixel p is non-empty iff active[p].
Image SparseImage(const std::vector<bool>& active, int width, std::mt19937& rng) {
    Image image;
    image.Resize(width, static_cast<int>(active.size()) / width);
    for (std::size_t p = 0; p < active.size(); ++p)
        if (active[p]) StorePixel(image, p, RandomPixel(rng));
    return image;
}

TEST(ActivePixels, RoundTripCostsOnlyActivePixelsAndRunHeaders) {
    for (int seed = 0; seed < 40; ++seed) {
        std::mt19937 rng(seed);
        const int width = 17, height = 11;
        const double fill = (seed % 5) / 4.0;
        std::bernoulli_distribution on(fill);
        std::vector<bool> active(width * height);
        for (std::size_t p = 0; p < active.size(); ++p) active[p] = on(rng);
        const Image image = SparseImage(active, width, rng);
        const PixelRange range{static_cast<std::size_t>(seed % 13),
                               active.size() - static_cast<std::size_t>(seed % 7)};
        std::size_t runs = 0, count = 0;
        for (std::size_t p = range.begin; p < range.end; ++p) {
            count += active[p];
            runs += active[p] && (p == range.begin || !active[p - 1]);
        }
        WireBuffer message;
        EXPECT_EQ(EncodeActive(image, range, message), count);
        EXPECT_EQ(message.size(), 2 * runs + kChannels * count) << seed;

        Image decoded;
        decoded.Resize(width, height);
        DecodeActive(message.data(), message.size(), range, DecodeMode::Assign, decoded);
        for (std::size_t p = 0; p < active.size(); ++p) {
            const bool inside = p >= range.begin && p < range.end;
            const Pixel expected = inside ? LoadPixel(image, p) : Pixel{};
            ExpectPixelNear(LoadPixel(decoded, p), expected, 0.0,
                            "pixel " + std::to_string(p));
        }
    }
}

TEST(ActivePixels, DecodeModesCompositeInFrontOrBehind) {
    std::mt19937 rng(11);
    const int width = 9, height = 4;
    std::vector<bool> all(width * height, true), half(width * height);
    for (std::size_t p = 0; p < half.size(); ++p) half[p] = p % 2 == 0;
    const Image base = SparseImage(all, width, rng);
    const Image incoming = SparseImage(half, width, rng);
    WireBuffer message;
    EncodeActive(incoming, {0, incoming.PixelCount()}, message);
    Image over = base, under = base;
    DecodeActive(message.data(), message.size(), {0, base.PixelCount()}, DecodeMode::Over,
                 over);
    DecodeActive(message.data(), message.size(), {0, base.PixelCount()},
                 DecodeMode::Under, under);
    for (std::size_t p = 0; p < base.PixelCount(); ++p) {
        const Pixel b = LoadPixel(base, p), in = LoadPixel(incoming, p);
        ExpectPixelNear(LoadPixel(over, p), Over(in, b), 0.0, "over");
        ExpectPixelNear(LoadPixel(under, p), Over(b, in), 0.0, "under");
    }
}

TEST(ActivePixels, EmptyImageSendsNothingAndClearRangeEmpties) {
    Image image;
    image.Resize(8, 8);
    WireBuffer message;
    EXPECT_EQ(EncodeActive(image, {0, 64}, message), 0u);
    EXPECT_TRUE(message.empty());
    std::mt19937 rng(5);
    for (std::size_t p = 0; p < 64; ++p) StorePixel(image, p, RandomPixel(rng));
    ClearRange(image, {10, 20});
    for (std::size_t p = 0; p < 64; ++p)
        EXPECT_EQ(IsEmpty(LoadPixel(image, p)), p >= 10 && p < 20) << p;
    EXPECT_TRUE(std::isnan(image.isoResidual[15]));
    EXPECT_EQ(image.isoId[15], -1.0);
    EXPECT_EQ(image.z[15], kInf);
}

TEST(ActivePixels, MalformedMessagesAreInternalErrors) {
    Image image;
    image.Resize(4, 4);
    const std::vector<double> truncatedHeader{0.0};
    const std::vector<double> outside{10.0, 7.0};
    const std::vector<double> truncatedPixels{0.0, 2.0, 1.0, 2.0, 3.0};
    const std::vector<double> notANumber{std::nan(""), 1.0};
    for (const auto* m : {&truncatedHeader, &outside, &truncatedPixels, &notANumber})
        EXPECT_THROW(
            DecodeActive(m->data(), m->size(), {0, 16}, DecodeMode::Assign, image),
            InternalError);
}

}  // namespace
}  // namespace hpray::compositor
