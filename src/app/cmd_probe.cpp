// hpray probe: the containing cell, reference coordinates, field values and gradients at
// world points (ParaView's Probe filter without linearisation).
#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <sstream>

#include "app/commands.h"
#include "elements/field.h"
#include "elements/mesh_geometry.h"
#include "io/mesh_io.h"
#include "util/error.h"
#include "util/log.h"

namespace hpray::app {
namespace {

std::vector<std::array<double, 3>> ReadPointsCsv(const std::string& path) {
    std::ifstream in(path);
    if (!in) throw InputError(path, "", "cannot open the points file");
    std::vector<std::array<double, 3>> points;
    std::string line;
    int lineNo = 0;
    while (std::getline(in, line)) {
        ++lineNo;
        if (!line.empty() && line.back() == '\r') line.pop_back();
        if (line.find_first_not_of(" \t") == std::string::npos) continue;
        for (char& ch : line)
            if (ch == ',' || ch == ';' || ch == '\t') ch = ' ';
        // strtod, unlike stream extraction, reads "nan" and "inf", which are then rejected.
        std::istringstream ss(line);
        std::vector<std::string> tokens;
        for (std::string tok; ss >> tok;) tokens.push_back(tok);
        std::array<double, 3> p{};
        bool numeric = tokens.size() == 3;
        for (std::size_t k = 0; numeric && k < 3; ++k) {
            char* end = nullptr;
            p[k] = std::strtod(tokens[k].c_str(), &end);
            numeric = end && *end == '\0';
        }
        if (!numeric) {
            if (points.empty() && lineNo == 1) continue;  // a header line
            throw InputError(path, "line " + std::to_string(lineNo),
                             "expected three numbers x,y,z");
        }
        for (double v : p)
            if (!std::isfinite(v))
                throw InputError(path, "line " + std::to_string(lineNo),
                                 "coordinate is NaN or Inf");
        points.push_back(p);
    }
    return points;
}

nlohmann::ordered_json Number(double v) {
    return std::isfinite(v) ? nlohmann::ordered_json(v) : nlohmann::ordered_json(nullptr);
}

}  // namespace

int RunProbe(const ProbeArgs& args) {
    ReadOptions options;
    if (!args.fields.empty()) options.fields = std::set<std::string>(args.fields.begin(), args.fields.end());
    const Mesh mesh = ReadMesh(args.mesh, options);
    const auto points = ReadPointsCsv(args.pointsCsv);

    // The fields to report: the requested names (any scalar selector), else every field.
    struct Probed {
        std::string name;
        ScalarSelector sel;
    };
    std::vector<Probed> probed;
    if (!args.fields.empty()) {
        for (const std::string& name : args.fields) {
            auto sel = SelectScalar(mesh, name);
            if (!sel) throw InputError(args.mesh, "", "no field '" + name + "'");
            probed.push_back({name, *sel});
        }
    } else {
        for (const Field& f : mesh.pointFields)
            for (int c = 0; c < f.components; ++c)
                probed.push_back({f.components == 1 ? f.name : f.name + "[" + std::to_string(c) + "]",
                                  ScalarSelector{&f, c}});
        for (const Field& f : mesh.cellFields)
            for (int c = 0; c < f.components; ++c)
                probed.push_back({f.components == 1 ? f.name : f.name + "[" + std::to_string(c) + "]",
                                  ScalarSelector{&f, c}});
    }

    const MeshGeometry geometry = MeshGeometry::Build(mesh);
    const PointLocator locator(mesh, geometry);
    EvalWorkspace ws;
    InversionOptions inversion;
    inversion.tolerance = 1e-14;
    std::vector<double> nodal;
    nlohmann::ordered_json out = nlohmann::ordered_json::array();
    std::int64_t outside = 0, failures = 0;
    for (const auto& p : points) {
        const PointLocator::Hit hit = locator.Locate(p.data(), ws, inversion);
        failures += hit.failures;
        nlohmann::ordered_json e;
        e["point"] = {p[0], p[1], p[2]};
        if (hit.cell < 0) {
            ++outside;
            e["cell"] = nullptr;
            e["ref"] = nullptr;
            e["values"] = nlohmann::ordered_json::object();
            if (args.gradient) e["gradients"] = nlohmann::ordered_json::object();
            out.push_back(e);
            continue;
        }
        e["cell"] = hit.cell;
        e["ref"] = {hit.ref[0], hit.ref[1], hit.ref[2]};
        nlohmann::ordered_json values = nlohmann::ordered_json::object(), gradients = nlohmann::ordered_json::object();
        CellScratch scratch;
        const CellGeometry& cell = geometry.Cell(hit.cell, scratch);
        for (const Probed& f : probed) {
            CellScalar scalar;
            if (f.sel.field->association == Association::Point) {
                GatherCellValues(mesh, *f.sel.field, f.sel.component, hit.cell, nodal);
                scalar.nodal = nodal.data();
            } else {
                scalar.constant = ScalarValue(f.sel, hit.cell);
            }
            double value, grad[3];
            FieldValueGradient(cell, scalar, hit.ref.data(), ws, value, grad);
            values[f.name] = Number(value);
            if (args.gradient) gradients[f.name] = {Number(grad[0]), Number(grad[1]), Number(grad[2])};
        }
        e["values"] = values;
        if (args.gradient) e["gradients"] = gradients;
        out.push_back(e);
    }
    if (args.json) {
        std::cout << out.dump(2) << std::endl;
    } else {
        std::printf("# x y z cell r s t");
        for (const Probed& f : probed) std::printf(" %s", f.name.c_str());
        std::printf("\n");
        for (const auto& e : out) {
            std::printf("%.17g %.17g %.17g", e["point"][0].get<double>(), e["point"][1].get<double>(),
                        e["point"][2].get<double>());
            if (e["cell"].is_null()) {
                std::printf(" outside\n");
                continue;
            }
            std::printf(" %lld %.17g %.17g %.17g", e["cell"].get<long long>(), e["ref"][0].get<double>(),
                        e["ref"][1].get<double>(), e["ref"][2].get<double>());
            for (const Probed& f : probed) {
                const auto& v = e["values"][f.name];
                std::printf(" %.17g", v.is_null() ? NAN : v.get<double>());
            }
            std::printf("\n");
        }
    }
    std::fflush(stdout);
    log::Info("probed " + std::to_string(points.size()) + " points: " + std::to_string(outside) +
              " outside, " + std::to_string(failures) + " inversion failures");
    return 0;
}

}  // namespace hpray::app
