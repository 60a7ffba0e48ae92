// Mesh model: validation of invariants, field ranges, scalar selection.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "mesh/mesh.h"
#include "util/error.h"

namespace hpray {
namespace {

Mesh OneTet() {
    Mesh m;
    m.points = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1};
    const std::int64_t nodes[4] = {0, 1, 2, 3};
    m.AddCell(CellShape::Tet, 1, CellFamily::Lagrange, nodes, 4);
    m.pointFields.push_back({"u", Association::Point, 1, {1, 2, 3, 4}});
    m.pointFields.push_back({"v", Association::Point, 3, {3, 4, 0, 0, 0, 0, 1, 0, 0, 0, 0, -2}});
    m.cellFields.push_back({"id", Association::Cell, 1, {7}});
    return m;
}

void ExpectInputError(const Mesh& m, const std::string& fragment) {
    try {
        m.Validate("mesh.vtu");
        ADD_FAILURE() << "no error, expected: " << fragment;
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("mesh.vtu"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
    }
}

TEST(Mesh, ValidMeshPasses) { EXPECT_NO_THROW(OneTet().Validate("x")); }

TEST(Mesh, ValidateRejectsBrokenInvariants) {
    Mesh m = OneTet();
    m.connectivity[2] = 4;
    ExpectInputError(m, "outside [0, 4)");
    m = OneTet();
    m.points[5] = std::numeric_limits<double>::quiet_NaN();
    ExpectInputError(m, "point 1");
    m = OneTet();
    m.pointFields[0].values[3] = std::numeric_limits<double>::infinity();
    ExpectInputError(m, "'u'");
    m = OneTet();
    m.cellFields[0].values.push_back(1);
    ExpectInputError(m, "'id'");
    m = OneTet();
    m.cellOrder[0] = 2;
    ExpectInputError(m, "node count");
}

TEST(Mesh, RangesAndScalarSelection) {
    Mesh m = OneTet();
    EXPECT_EQ(m.pointFields[0].Range(), (std::array<double, 2>{1, 4}));
    EXPECT_EQ(m.pointFields[1].Range(-1), (std::array<double, 2>{0, 5}));
    auto s = SelectScalar(m, "v");
    ASSERT_TRUE(s);
    EXPECT_EQ(s->component, -1);
    EXPECT_DOUBLE_EQ(ScalarValue(*s, 0), 5.0);
    auto sy = SelectScalar(m, "v.y");
    ASSERT_TRUE(sy);
    EXPECT_DOUBLE_EQ(ScalarValue(*sy, 0), 4.0);
    auto s2 = SelectScalar(m, "v[2]");
    ASSERT_TRUE(s2);
    EXPECT_DOUBLE_EQ(ScalarValue(*s2, 3), -2.0);
    EXPECT_FALSE(SelectScalar(m, "v[3]"));
    EXPECT_FALSE(SelectScalar(m, "w"));
    EXPECT_FALSE(SelectScalar(m, "u.y"));
    EXPECT_TRUE(SelectScalar(m, "id"));
    auto b = m.Bounds();
    EXPECT_EQ(b.hi, (std::array<double, 3>{1, 1, 1}));
}

}  // namespace
}  // namespace hpray
