// Mesh model: cell insertion, lookup, bounds, validation.
#include "mesh/mesh.h"

#include <cmath>
#include <limits>
#include <sstream>

#include "util/check.h"
#include "util/error.h"

namespace hpray {

std::array<double, 2> Field::Range(int component) const {
    double lo = std::numeric_limits<double>::infinity(), hi = -lo;
    const std::size_t n = components > 0 ? values.size() / components : 0;
    for (std::size_t e = 0; e < n; ++e) {
        const double* v = values.data() + e * components;
        double x;
        if (component >= 0) {
            x = v[component];
        } else {
            double s = 0;
            for (int c = 0; c < components; ++c) s += v[c] * v[c];
            x = std::sqrt(s);
        }
        lo = std::min(lo, x);
        hi = std::max(hi, x);
    }
    return {lo, hi};
}

void Mesh::AddCell(CellShape shape, int order, CellFamily family, const std::int64_t* nodes,
                   int count) {
    HPRAY_CHECK_EQ(count, NodeCount(shape, order, family));
    connectivity.insert(connectivity.end(), nodes, nodes + count);
    cellOffsets.push_back(static_cast<std::int64_t>(connectivity.size()));
    cellShape.push_back(shape);
    cellOrder.push_back(static_cast<std::uint8_t>(order));
    cellFamily.push_back(family);
}

const Field* Mesh::FindPointField(const std::string& name) const {
    for (const Field& f : pointFields)
        if (f.name == name) return &f;
    return nullptr;
}

const Field* Mesh::FindCellField(const std::string& name) const {
    for (const Field& f : cellFields)
        if (f.name == name) return &f;
    return nullptr;
}

const Field* Mesh::FindField(const std::string& name) const {
    if (const Field* f = FindPointField(name)) return f;
    return FindCellField(name);
}

Box Mesh::Bounds() const {
    Box b = Box::Empty();
    for (std::size_t i = 0; i + 2 < points.size(); i += 3) b.Extend(&points[i]);
    return b;
}

std::size_t Mesh::MemoryBytes() const {
    std::size_t bytes = points.size() * sizeof(double) +
                        cellOffsets.size() * sizeof(std::int64_t) +
                        connectivity.size() * sizeof(std::int64_t) +
                        cellShape.size() * 3 + ghost.size() + vtkType.size();
    for (const Field& f : pointFields) bytes += f.values.size() * sizeof(double);
    for (const Field& f : cellFields) bytes += f.values.size() * sizeof(double);
    return bytes;
}

namespace {
std::string Fmt(const char* what, std::int64_t i) {
    std::ostringstream os;
    os << what << " " << i;
    return os.str();
}
}  // namespace

void Mesh::Validate(const std::string& source) const {
    if (points.size() % 3 != 0) throw InputError(source, "", "point array length not a multiple of 3");
    const std::int64_t np = PointCount(), nc = CellCount();
    for (std::int64_t i = 0; i < np * 3; ++i)
        if (!std::isfinite(points[i]))
            throw InputError(source, Fmt("point", i / 3), "coordinate is NaN or Inf");
    if (static_cast<std::int64_t>(cellOffsets.size()) != nc + 1 || cellOffsets[0] != 0 ||
        cellOrder.size() != cellShape.size() || cellFamily.size() != cellShape.size())
        throw InputError(source, "", "inconsistent cell arrays");
    for (std::int64_t c = 0; c < nc; ++c) {
        const std::int64_t n = cellOffsets[c + 1] - cellOffsets[c];
        if (n != NodeCount(cellShape[c], cellOrder[c], cellFamily[c]))
            throw InputError(source, Fmt("cell", c), "wrong node count for its type and order");
    }
    if (cellOffsets.back() != static_cast<std::int64_t>(connectivity.size()))
        throw InputError(source, "", "connectivity length disagrees with the cell offsets");
    for (std::size_t i = 0; i < connectivity.size(); ++i)
        if (connectivity[i] < 0 || connectivity[i] >= np) {
            std::ostringstream os;
            os << "connectivity entry " << i << " = " << connectivity[i]
               << " is outside [0, " << np << ")";
            throw InputError(source, "", os.str());
        }
    auto checkField = [&](const Field& f, std::int64_t count, const char* kind) {
        if (f.components < 1 ||
            static_cast<std::int64_t>(f.values.size()) != count * f.components)
            throw InputError(source, std::string(kind) + " field '" + f.name + "'",
                             "has the wrong number of values");
        for (std::size_t i = 0; i < f.values.size(); ++i)
            if (!std::isfinite(f.values[i]))
                throw InputError(source, std::string(kind) + " field '" + f.name + "'",
                                 Fmt("NaN or Inf at entry", static_cast<std::int64_t>(i / f.components)));
    };
    for (const Field& f : pointFields) checkField(f, np, "point");
    for (const Field& f : cellFields) checkField(f, nc, "cell");
    if (!ghost.empty() && static_cast<std::int64_t>(ghost.size()) != nc)
        throw InputError(source, "vtkGhostType", "has the wrong number of values");
    if (!vtkType.empty() && static_cast<std::int64_t>(vtkType.size()) != nc)
        throw InputError(source, "",
                         "the cell type array has the wrong number of values");
}

std::optional<ScalarSelector> SelectScalar(const Mesh& mesh, const std::string& name) {
    if (const Field* f = mesh.FindField(name))
        return ScalarSelector{f, f->components == 1 ? 0 : -1};
    auto dot = name.rfind('.');
    auto bracket = name.rfind('[');
    std::string base, sub;
    if (bracket != std::string::npos && name.back() == ']') {
        base = name.substr(0, bracket);
        sub = name.substr(bracket + 1, name.size() - bracket - 2);
    } else if (dot != std::string::npos) {
        base = name.substr(0, dot);
        sub = name.substr(dot + 1);
    } else {
        return std::nullopt;
    }
    const Field* f = mesh.FindField(base);
    if (!f) return std::nullopt;
    if (sub == "magnitude") return ScalarSelector{f, -1};
    int comp = -1;
    if (sub == "x" || sub == "X") comp = 0;
    else if (sub == "y" || sub == "Y") comp = 1;
    else if (sub == "z" || sub == "Z") comp = 2;
    else if (!sub.empty() && sub.find_first_not_of("0123456789") == std::string::npos && sub.size() < 4)
        comp = std::stoi(sub);
    if (comp < 0 || comp >= f->components) return std::nullopt;
    return ScalarSelector{f, comp};
}

}  // namespace hpray
