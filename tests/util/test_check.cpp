// CHECK macros and error types: messages carry file, position and operands.
#include <gtest/gtest.h>

#include "util/check.h"
#include "util/error.h"

namespace hpray {
namespace {

TEST(Check, PassingChecksDoNothing) {
    EXPECT_NO_THROW(HPRAY_CHECK(1 + 1 == 2));
    EXPECT_NO_THROW(HPRAY_CHECK_EQ(3, 3));
    EXPECT_NO_THROW(HPRAY_CHECK_LT(1.0, 2.0));
}

TEST(Check, FailingCheckNamesExpressionOperandsAndLocation) {
    try {
        const int a = 2, b = 5;
        HPRAY_CHECK_EQ(a, b);
        FAIL() << "no throw";
    } catch (const InternalError& e) {
        const std::string m = e.what();
        EXPECT_NE(m.find("test_check.cpp"), std::string::npos) << m;
        EXPECT_NE(m.find("a == b"), std::string::npos) << m;
        EXPECT_NE(m.find("(2 vs 5)"), std::string::npos) << m;
    }
    EXPECT_THROW(HPRAY_CHECK_MSG(false, "context " << 42), InternalError);
}

TEST(Errors, InputErrorFormatsSourcePositionAndMessage) {
    InputError e("mesh.vtu", "byte 4096", "truncated");
    EXPECT_STREQ(e.what(), "mesh.vtu: byte 4096: truncated");
    EXPECT_EQ(e.source(), "mesh.vtu");
    InputError noPos("scene.yaml", "", "empty file");
    EXPECT_STREQ(noPos.what(), "scene.yaml: empty file");
    NotImplementedError ni("'hpray partition'");
    EXPECT_NE(std::string(ni.what()).find("not implemented"), std::string::npos);
}

}  // namespace
}  // namespace hpray
