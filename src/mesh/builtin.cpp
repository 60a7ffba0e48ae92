// Built-in data sets: exact analytic test meshes generated in memory (see builtin.h).
#include "mesh/builtin.h"

#include <cmath>
#include <map>
#include <sstream>
#include <unordered_map>

#include "util/check.h"
#include "util/error.h"

namespace hpray {
namespace {

constexpr double kPi = 3.14159265358979323846;

struct Spec {
    std::string full;
    std::string name;
    std::map<std::string, std::string> params;
};

Spec ParseSpec(const std::string& spec) {
    Spec s;
    s.full = spec;
    std::string rest = spec.substr(std::string("builtin:").size());
    auto q = rest.find('?');
    s.name = rest.substr(0, q);
    if (q != std::string::npos) {
        std::stringstream ss(rest.substr(q + 1));
        std::string kv;
        while (std::getline(ss, kv, '&')) {
            auto eq = kv.find('=');
            if (eq == std::string::npos || eq == 0)
                throw InputError(spec, kv, "expected key=value");
            s.params[kv.substr(0, eq)] = kv.substr(eq + 1);
        }
    }
    return s;
}

int IntParam(Spec& s, const std::string& key, int def, int lo, int hi) {
    auto it = s.params.find(key);
    if (it == s.params.end()) return def;
    const std::string v = it->second;
    s.params.erase(it);
    std::size_t used = 0;
    int value = 0;
    try {
        value = std::stoi(v, &used);
    } catch (const std::exception&) {
        used = 0;
    }
    if (used != v.size() || value < lo || value > hi) {
        std::ostringstream os;
        os << "parameter '" << key << "' must be an integer in [" << lo << ", " << hi
           << "], got '" << v << "'";
        throw InputError(s.full, key, os.str());
    }
    return value;
}

void RejectUnusedParams(const Spec& s) {
    if (!s.params.empty())
        throw InputError(s.full, s.params.begin()->first,
                         "unknown parameter for builtin:" + s.name);
}

/// Adds the point field `u` with the values u(x, y, z) at the mesh's points.
template <typename FieldFn>
void AddFieldU(Mesh& mesh, FieldFn u) {
    Field f{"u", Association::Point, 1, {}};
    f.values.resize(mesh.PointCount());
    for (std::int64_t i = 0; i < mesh.PointCount(); ++i)
        f.values[i] = u(mesh.points[3 * i], mesh.points[3 * i + 1], mesh.points[3 * i + 2]);
    mesh.pointFields.push_back(std::move(f));
}

/// A structured block of n[0] x n[1] x n[2] hexahedra of order p whose vertex (a, b, c)
/// sits at vertexPos(a, b, c); nodes inside a cell are placed by the trilinear map of its
/// eight vertices, so neighbouring cells agree on shared faces exactly.
template <typename VertexPos, typename FieldFn>
Mesh HexBlock(const int n[3], int p, VertexPos vertexPos, FieldFn u) {
    Mesh mesh;
    const std::int64_t gx = std::int64_t(n[0]) * p + 1, gy = std::int64_t(n[1]) * p + 1,
                       gz = std::int64_t(n[2]) * p + 1;
    mesh.points.assign(3 * gx * gy * gz, 0.0);
    std::vector<char> placed(gx * gy * gz, 0);
    const auto& lattice = LatticeNodes(CellShape::Hex, p);
    std::vector<std::int64_t> nodes(lattice.size());
    for (int c = 0; c < n[2]; ++c)
        for (int b = 0; b < n[1]; ++b)
            for (int a = 0; a < n[0]; ++a) {
                std::array<double, 3> v[8];
                for (int q = 0; q < 8; ++q)
                    v[q] = vertexPos(a + (q & 1), b + ((q >> 1) & 1), c + ((q >> 2) & 1));
                for (std::size_t k = 0; k < lattice.size(); ++k) {
                    const auto& ijk = lattice[k];
                    const std::int64_t I = std::int64_t(a) * p + ijk[0],
                                       J = std::int64_t(b) * p + ijk[1],
                                       K = std::int64_t(c) * p + ijk[2];
                    const std::int64_t g = I + gx * (J + gy * K);
                    nodes[k] = g;
                    if (placed[g]) continue;
                    placed[g] = 1;
                    const double r = double(ijk[0]) / p, s = double(ijk[1]) / p,
                                 t = double(ijk[2]) / p;
                    for (int d = 0; d < 3; ++d) {
                        double x = 0;
                        for (int q = 0; q < 8; ++q)
                            x += v[q][d] * ((q & 1) ? r : 1 - r) *
                                 (((q >> 1) & 1) ? s : 1 - s) * (((q >> 2) & 1) ? t : 1 - t);
                        mesh.points[3 * g + d] = x;
                    }
                }
                mesh.AddCell(CellShape::Hex, p, CellFamily::Lagrange, nodes.data(),
                             static_cast<int>(nodes.size()));
            }
    AddFieldU(mesh, u);
    return mesh;
}

// Nelson & Kirby example 1: u = 2 (y - 0.3) - sinc(r), r = |(x - 0.5, z - 0.5)|.
Mesh NkSinc(Spec& s) {
    const int p = IntParam(s, "order", 8, 1, kMaxOrder);
    RejectUnusedParams(s);
    // Uneven spacing: cells shrink towards the middle, where the sinc varies fastest.
    static const double kBreaks[6] = {0.0, 0.27, 0.44, 0.56, 0.73, 1.0};
    const int n[3] = {5, 5, 5};
    return HexBlock(
        n, p,
        [](int a, int b, int c) {
            return std::array<double, 3>{kBreaks[a], kBreaks[b], kBreaks[c]};
        },
        [](double x, double y, double z) {
            const double r = std::hypot(x - 0.5, z - 0.5);
            const double sinc = r == 0 ? 1.0 : std::sin(kPi * r) / (kPi * r);
            return 2.0 * (y - 0.3) - sinc;
        });
}

// Nelson & Kirby example 2: 8 hexes whose interior vertices are displaced, so interior
// faces are non-planar bilinear patches; boundary vertices move only within their boundary
// face or edge, so the domain stays exactly [0,1]^3.
Mesh NkQuartic(Spec& s) {
    const int p = IntParam(s, "order", 8, 1, kMaxOrder);
    RejectUnusedParams(s);
    const int n[3] = {2, 2, 2};
    return HexBlock(
        n, p,
        [](int a, int b, int c) {
            std::array<double, 3> x{0.5 * a, 0.5 * b, 0.5 * c};
            const int idx[3] = {a, b, c};
            // Deterministic displacements, different per vertex and axis, kept small
            // enough (<= 0.08) that every cell stays well shaped.
            for (int d = 0; d < 3; ++d)
                if (idx[d] == 1)
                    x[d] += 0.06 * std::sin(1.7 * (d + 1) + 2.3 * a + 1.1 * b + 0.7 * c);
            return x;
        },
        [](double x, double y, double z) {
            double u = 0;
            for (double xi : {x, y, z}) {
                const double d2 = (0.5 - xi) * (0.5 - xi);
                u += d2 * (d2 - 0.169);
            }
            return u;
        });
}

// The unit cube [0,1]^3 (or [-1,1]^3 for the ball) as N^3 cubes split into 5 tetrahedra
// each, with the split mirrored on alternate cubes so the face diagonals match; order-p
// tets place their nodes on the lattice, shared through a map keyed by the fine grid index.
template <typename FieldFn>
Mesh CubeTets(int N, int p, double lo, double hi, FieldFn u) {
    Mesh mesh;
    std::unordered_map<std::int64_t, std::int64_t> index;
    const std::int64_t g = std::int64_t(N) * p + 1;
    const double h = (hi - lo) / (double(N) * p);
    auto pointId = [&](std::int64_t I, std::int64_t J, std::int64_t K) {
        const std::int64_t key = I + g * (J + g * K);
        auto [it, inserted] = index.emplace(key, mesh.PointCount());
        if (inserted) {
            mesh.points.push_back(lo + h * I);
            mesh.points.push_back(lo + h * J);
            mesh.points.push_back(lo + h * K);
        }
        return it->second;
    };
    // Corner tets of the 5-tet split around even-parity vertices; central tet on odd ones.
    static const int kSplitA[5][4] = {{0, 1, 2, 4}, {3, 2, 1, 7}, {5, 4, 7, 1}, {6, 7, 4, 2},
                                      {1, 2, 4, 7}};
    static const int kSplitB[5][4] = {{1, 0, 5, 3}, {2, 3, 6, 0}, {4, 5, 0, 6}, {7, 6, 3, 5},
                                      {0, 3, 5, 6}};
    const auto& lattice = LatticeNodes(CellShape::Tet, p);
    std::vector<std::int64_t> nodes(lattice.size());
    for (int c = 0; c < N; ++c)
        for (int b = 0; b < N; ++b)
            for (int a = 0; a < N; ++a) {
                const auto& split = ((a + b + c) % 2 == 0) ? kSplitA : kSplitB;
                for (const auto& tet : split) {
                    // Vertex grid indices (in units of the fine grid).
                    std::array<std::int64_t, 3> v[4];
                    for (int q = 0; q < 4; ++q)
                        v[q] = {std::int64_t(a + (tet[q] & 1)) * p,
                                std::int64_t(b + ((tet[q] >> 1) & 1)) * p,
                                std::int64_t(c + ((tet[q] >> 2) & 1)) * p};
                    // Positive orientation: swap two vertices if the volume is negative.
                    auto sub = [&](int q, int d) { return double(v[q][d] - v[0][d]); };
                    const double det = sub(1, 0) * (sub(2, 1) * sub(3, 2) - sub(2, 2) * sub(3, 1)) -
                                       sub(1, 1) * (sub(2, 0) * sub(3, 2) - sub(2, 2) * sub(3, 0)) +
                                       sub(1, 2) * (sub(2, 0) * sub(3, 1) - sub(2, 1) * sub(3, 0));
                    HPRAY_CHECK(det != 0);
                    if (det < 0) std::swap(v[1], v[2]);
                    for (std::size_t k = 0; k < lattice.size(); ++k) {
                        const auto& ijk = lattice[k];
                        std::int64_t G[3];
                        for (int d = 0; d < 3; ++d)
                            G[d] = v[0][d] + ((v[1][d] - v[0][d]) * ijk[0] +
                                              (v[2][d] - v[0][d]) * ijk[1] +
                                              (v[3][d] - v[0][d]) * ijk[2]) / p;
                        nodes[k] = pointId(G[0], G[1], G[2]);
                    }
                    mesh.AddCell(CellShape::Tet, p, CellFamily::Lagrange, nodes.data(),
                                 static_cast<int>(nodes.size()));
                }
            }
    AddFieldU(mesh, u);
    return mesh;
}

}  // namespace

std::vector<std::string> BuiltinNames() {
    return {"nk-sinc", "nk-quartic", "ball-p2", "cube-tets-N"};
}

Mesh MakeBuiltin(const std::string& spec) {
    Spec s = ParseSpec(spec);
    Mesh mesh;
    if (s.name == "nk-sinc") {
        mesh = NkSinc(s);
    } else if (s.name == "nk-quartic") {
        mesh = NkQuartic(s);
    } else if (s.name == "ball-p2") {
        const int n = IntParam(s, "n", 4, 1, 64);
        RejectUnusedParams(s);
        mesh = CubeTets(n, 2, -1.0, 1.0,
                        [](double x, double y, double z) { return x * x + y * y + z * z; });
        // A second field, v = x (exact in the quadratic space), to colour by.
        Field v;
        v.name = "v";
        v.values.resize(mesh.PointCount());
        for (std::int64_t p = 0; p < mesh.PointCount(); ++p) v.values[p] = mesh.points[3 * p];
        mesh.pointFields.push_back(std::move(v));
    } else if (s.name.rfind("cube-tets-", 0) == 0) {
        const std::string digits = s.name.substr(std::string("cube-tets-").size());
        if (digits.empty() || digits.size() > 4 ||
            digits.find_first_not_of("0123456789") != std::string::npos ||
            std::stoi(digits) < 1 || std::stoi(digits) > 200)
            throw InputError(spec, "", "cube-tets-N needs an integer N in [1, 200]");
        const int order = IntParam(s, "order", 1, 1, kMaxOrder);
        RejectUnusedParams(s);
        mesh = CubeTets(std::stoi(digits), order, 0.0, 1.0,
                        [](double x, double y, double z) { return x + 2 * y + 3 * z; });
    } else {
        std::string names;
        for (const auto& n : BuiltinNames()) names += (names.empty() ? "" : ", ") + n;
        throw InputError(spec, "", "unknown builtin '" + s.name + "' (known: " + names + ")");
    }
    mesh.Validate(spec);
    return mesh;
}

}  // namespace hpray
