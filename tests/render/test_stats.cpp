// Stats: reduction semantics and the keys of the stats contract in docs/contracts.md.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cmath>

#include "render/stats.h"

namespace hpray {
namespace {

TEST(Stats, MergeSumsCountersAndMaxesMaxima) {
    RenderCounters a, b;
    a.rays = 10;
    a.isoHits = 2;
    a.isoResidualSqSum = 8;
    a.isoResidualMax = 3;
    a.projectionOrderMax = 12;
    b.rays = 5;
    b.isoHits = 1;
    b.isoResidualSqSum = 1;
    b.isoResidualMax = 1;
    b.projectionOrderMax = 17;
    a.Merge(b);
    EXPECT_EQ(a.rays, 15);
    EXPECT_EQ(a.isoHits, 3);
    EXPECT_EQ(a.isoResidualSqSum, 9);
    EXPECT_EQ(a.isoResidualMax, 3);
    EXPECT_EQ(a.projectionOrderMax, 17);
    // Round trip through the reduction array keeps every field.
    EXPECT_EQ(RenderCounters::FromArray(a.ToArray()).ToArray(), a.ToArray());
}

TEST(Stats, JsonHasEveryContractKey) {
    RenderStats s;
    s.width = 64;
    s.height = 32;
    s.counters.isoHits = 4;
    s.counters.isoResidualSqSum = 4 * 1e-24;
    s.counters.isoResidualMax = 2e-12;
    s.isoFieldRange = {-1, 3};
    const auto j = nlohmann::json::parse(StatsToJson(s));
    for (const char* key : {"ranks", "threads", "image", "timing_s", "rays", "segments",
                            "segments_culled", "bricks_loaded", "bricks_total", "iso",
                            "mapping", "volume", "composite"})
        EXPECT_TRUE(j.contains(key)) << key;
    for (const char* key : {"load", "accel", "render", "composite", "write", "total"})
        EXPECT_TRUE(j["timing_s"].contains(key)) << key;
    for (const char* key : {"hits", "rms_residual", "max_residual", "mean_projection_order",
                            "max_projection_order", "root_failures", "field_range"})
        EXPECT_TRUE(j["iso"].contains(key)) << key;
    for (const char* key : {"inversions", "mean_iterations", "failures"})
        EXPECT_TRUE(j["mapping"].contains(key)) << key;
    for (const char* key : {"rms_error_estimate", "max_error_estimate"})
        EXPECT_TRUE(j["volume"].contains(key)) << key;
    for (const char* key :
         {"rounds", "bytes_per_pixel", "bytes_sent_max", "bytes_sent_total", "bytes_gather"})
        EXPECT_TRUE(j["composite"].contains(key)) << key;
    EXPECT_EQ(j["image"], nlohmann::json({64, 32}));
    EXPECT_DOUBLE_EQ(j["iso"]["rms_residual"].get<double>(), 1e-12);
    EXPECT_DOUBLE_EQ(j["iso"]["max_residual_relative"].get<double>(), 0.5e-12);
    EXPECT_FALSE(j["volume"].contains("color_tf"));  // no volume rendered
}

TEST(Stats, JsonHasTheVolumeRendered) {
    RenderStats s;
    s.hasVolume = true;
    s.volumeColorField = "u";
    s.volumeExtinctionField = "v";
    s.volumeColorTf = {{0.0, 0.1, 0.2, 0.3}, {2.0, 1.0, 0.5, 0.0}};
    s.volumeExtinctionTf = {{-1.0, 0.0}, {1.0, 2.5}};
    const auto j = nlohmann::json::parse(StatsToJson(s))["volume"];
    EXPECT_EQ(j["color_field"], "u");
    EXPECT_EQ(j["extinction_field"], "v");
    EXPECT_EQ(j["color_tf"], nlohmann::json::parse("[[0, 0.1, 0.2, 0.3], [2, 1, 0.5, 0]]"));
    EXPECT_EQ(j["extinction_tf"], nlohmann::json::parse("[[-1, 0], [1, 2.5]]"));
    EXPECT_TRUE(j.contains("rms_error_estimate"));
}

}  // namespace
}  // namespace hpray
