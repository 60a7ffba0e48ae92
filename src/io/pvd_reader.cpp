// ParaView collections (.pvd): the list of time steps and their part files, and one step
// read as a mesh (its parts merged as the pieces of a .pvtu are).
#include <pugixml.hpp>

#include <algorithm>
#include <cerrno>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "io/file_bytes.h"
#include "io/mesh_io.h"
#include "io/vtk_xml_detail.h"
#include "util/error.h"

namespace hpray {
namespace {

namespace fs = std::filesystem;

std::string Trim(const std::string& s) {
    const auto space = [](unsigned char c) { return std::isspace(c) != 0; };
    auto b = std::find_if_not(s.begin(), s.end(), space);
    auto e = std::find_if_not(s.rbegin(), s.rend(), space).base();
    return b < e ? std::string(b, e) : std::string();
}

/// The whole (trimmed) text as a finite number.
bool ParseNumber(const std::string& text, double& value) {
    const std::string t = Trim(text);
    if (t.empty()) return false;
    char* end = nullptr;
    errno = 0;
    value = std::strtod(t.c_str(), &end);
    return end == t.c_str() + t.size() && errno != ERANGE && std::isfinite(value);
}

/// The whole (trimmed) text as an integer >= 0.
bool ParsePart(const std::string& text, long long& value) {
    const std::string t = Trim(text);
    if (t.empty() || !std::all_of(t.begin(), t.end(),
                                  [](unsigned char c) { return std::isdigit(c) != 0; }))
        return false;
    if (t.size() > 9) return false;
    value = std::stoll(t);
    return true;
}

std::string FormatTime(double t) {
    char text[32];
    std::snprintf(text, sizeof text, "%.10g", t);
    return text;
}

std::string LowerExtension(const fs::path& path) {
    std::string ext = path.extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(),
                   [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    return ext;
}

struct Entry {
    long long part = 0;
    int index = 0;  ///< of the <DataSet> in the file, for messages
    std::string file;
};

}  // namespace

std::string Collection::TimesText(std::size_t most) const {
    std::string out;
    for (std::size_t k = 0; k < steps.size(); ++k) {
        if (k == most) return out + ", ...";
        out += (k == 0 ? "" : ", ") + FormatTime(steps[k].time);
    }
    return out;
}

int Collection::FindTime(double time) const {
    if (steps.empty() || !std::isfinite(time)) return -1;
    double scale = steps.back().time - steps.front().time;
    for (const CollectionStep& s : steps) scale = std::max(scale, std::fabs(s.time));
    const double tolerance = 1e-9 * scale;
    int best = -1;
    double bestDistance = 0;
    for (std::size_t k = 0; k < steps.size(); ++k) {
        const double d = std::fabs(steps[k].time - time);
        if (d <= tolerance && (best < 0 || d < bestDistance)) {
            best = static_cast<int>(k);
            bestDistance = d;
        }
    }
    return best;
}

Collection ReadCollection(const std::string& path) {
    std::error_code ec;
    if (!fs::exists(path, ec)) throw InputError(path, "", "no such file");
    if (fs::is_directory(path, ec))
        throw InputError(path, "", "is a directory, not a .pvd collection file");
    std::string bytes = ReadWholeFile(path);
    pugi::xml_document doc;
    const pugi::xml_parse_result parsed = doc.load_buffer(bytes.data(), bytes.size());
    if (!parsed)
        throw InputError(path,
                         ByteOrLineWhere(bytes, static_cast<std::size_t>(std::max<std::ptrdiff_t>(
                                                    0, parsed.offset)),
                                         false),
                         std::string("malformed XML: ") + parsed.description());
    const pugi::xml_node root = doc.child("VTKFile");
    if (!root)
        throw InputError(path, "", "is not a VTK XML file (no <VTKFile> root element)");
    const std::string type = root.attribute("type").value();
    if (type != "Collection")
        throw InputError(path, "<VTKFile>",
                         "type '" + type + "' is not Collection (a .pvd holds <VTKFile "
                         "type=\"Collection\"><Collection><DataSet .../>...)");
    const pugi::xml_node list = root.child("Collection");
    if (!list) throw InputError(path, "<VTKFile>", "has no <Collection> element");

    const fs::path folder = fs::path(path).parent_path();
    std::map<double, std::vector<Entry>> byTime;
    int index = 0, withTime = 0;
    for (pugi::xml_node node : list.children("DataSet")) {
        const std::string where = "<DataSet> " + std::to_string(index);
        Entry entry;
        entry.index = index;
        const pugi::xml_attribute fileAttr = node.attribute("file");
        entry.file = Trim(fileAttr.value());
        if (entry.file.empty())
            throw InputError(path, where, fileAttr ? "has an empty file attribute"
                                                   : "has no file attribute");
        double time = 0.0;
        const pugi::xml_attribute timeAttr = node.attribute("timestep");
        if (timeAttr) {
            if (!ParseNumber(timeAttr.value(), time))
                throw InputError(path,
                                 where + " timestep=\"" + timeAttr.value() + "\"",
                                 "the timestep is not a finite number");
            ++withTime;
        }
        if (withTime != (timeAttr ? index + 1 : 0))
            throw InputError(path, where,
                             "some DataSets have a timestep attribute and others not; give "
                             "every DataSet one (or none: then all are parts of one step)");
        if (const pugi::xml_attribute partAttr = node.attribute("part");
            partAttr && !ParsePart(partAttr.value(), entry.part))
            throw InputError(path, where + " part=\"" + partAttr.value() + "\"",
                             "the part is not an integer >= 0");
        for (const Entry& other : byTime[time])
            if (other.part == entry.part)
                throw InputError(path, where,
                                 "repeats timestep " + FormatTime(time) + " part " +
                                     std::to_string(entry.part) + " of <DataSet> " +
                                     std::to_string(other.index));
        const fs::path file = (folder / entry.file).lexically_normal();
        const std::string fileWhere = where + " file=\"" + entry.file + "\"";
        if (!fs::exists(file, ec))
            throw InputError(path, fileWhere, "no such file: " + file.string());
        if (fs::is_directory(file, ec))
            throw InputError(path, fileWhere,
                             file.string() + " is a folder (a partition directory?): a time "
                             "series of partition directories is not supported; give each "
                             "step as a .vtu or .pvtu file");
        const std::string ext = LowerExtension(file);
        if (ext == ".pvd")
            throw InputError(path, fileWhere, "a collection inside a collection is not supported");
        static const char* const kKnown[] = {".vtu", ".pvtu", ".vts", ".pvts", ".vtk", ".msh"};
        if (std::find(std::begin(kKnown), std::end(kKnown), ext) == std::end(kKnown))
            throw InputError(path, fileWhere,
                             "'" + ext + "' is not a mesh format hpray reads (.vtu, .pvtu, "
                             ".vts, .pvts, .vtk, .msh)");
        entry.file = file.string();
        byTime[time].push_back(std::move(entry));
        ++index;
    }
    if (index == 0)
        throw InputError(path, "<Collection>", "has no <DataSet>: the collection is empty");

    Collection collection;
    collection.path = path;
    for (auto& [time, entries] : byTime) {
        std::sort(entries.begin(), entries.end(),
                  [](const Entry& a, const Entry& b) { return a.part < b.part; });
        CollectionStep step;
        step.time = time;
        for (const Entry& e : entries) step.files.push_back(e.file);
        collection.steps.push_back(std::move(step));
    }
    return collection;
}

Mesh ReadCollectionStep(const Collection& collection, int step, const ReadOptions& options) {
    const int count = static_cast<int>(collection.steps.size());
    if (step < 0 || step >= count)
        throw InputError(collection.path, "",
                         "has " + std::to_string(count) + " time step" +
                             (count == 1 ? "" : "s") + " (0 to " + std::to_string(count - 1) +
                             "); step " + std::to_string(step) + " does not exist");
    const CollectionStep& s = collection.steps[static_cast<std::size_t>(step)];
    Mesh mesh;
    for (std::size_t k = 0; k < s.files.size(); ++k) {
        Mesh part = ReadMesh(s.files[k], options);
        vtkxml::AppendPiece(mesh, k == 0, std::move(part), s.files[k],
                            "part " + std::to_string(k) + " of time step " +
                                std::to_string(step) + " (t = " + FormatTime(s.time) +
                                ") of " + collection.path);
    }
    return mesh;
}

}  // namespace hpray
