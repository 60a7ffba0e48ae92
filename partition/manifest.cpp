// Reading a partition directory: manifest validation, brick checksums and loading,
// front-to-back brick order, and the summary `hpray info DIR` prints.
#include <openssl/evp.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <memory>
#include <sstream>

#include "kd_tree.h"
#include "partition.h"
#include "util/check.h"
#include "util/error.h"

namespace hpray::partition {
namespace fs = std::filesystem;
namespace {

using nlohmann::json;

/// Throws InputError(manifest, key, what).
struct ManifestChecker {
    std::string path;

    [[noreturn]] void Fail(const std::string& key, const std::string& what) const {
        throw InputError(path, key, what);
    }
    const json& Member(const json& object, const std::string& key,
                       const std::string& where) const {
        if (!object.is_object()) Fail(where, "is not an object");
        const auto it = object.find(key);
        if (it == object.end())
            Fail(where.empty() ? key : where + "." + key, "is missing");
        return *it;
    }
    double Number(const json& v, const std::string& where) const {
        if (!v.is_number()) Fail(where, "is not a number");
        const double d = v.get<double>();
        if (!std::isfinite(d)) Fail(where, "is not finite");
        return d;
    }
    std::int64_t Count(const json& v, const std::string& where) const {
        if (!v.is_number_integer() || v.get<std::int64_t>() < 0)
            Fail(where, "is not a non-negative integer");
        return v.get<std::int64_t>();
    }
    Box ParseBox(const json& v, const std::string& where) const {
        if (!v.is_array() || v.size() != 2 || !v[0].is_array() || !v[1].is_array() ||
            v[0].size() != 3 || v[1].size() != 3)
            Fail(where, "is not [[x0, y0, z0], [x1, y1, z1]]");
        Box b;
        for (int d = 0; d < 3; ++d) {
            b.lo[d] = Number(v[0][d], where);
            b.hi[d] = Number(v[1][d], where);
            if (b.lo[d] > b.hi[d])
                Fail(where, "has a lower corner above the upper corner");
        }
        return b;
    }
};

bool SameBox(const Box& a, const Box& b) { return a.lo == b.lo && a.hi == b.hi; }

}  // namespace

Sha256::Sha256() {
    EVP_MD_CTX* ctx = EVP_MD_CTX_new();
    HPRAY_CHECK(ctx && EVP_DigestInit_ex(ctx, EVP_sha256(), nullptr) == 1);
    context_ = ctx;
}

Sha256::~Sha256() { EVP_MD_CTX_free(static_cast<EVP_MD_CTX*>(context_)); }

void Sha256::Update(const void* data, std::size_t bytes) {
    if (bytes > 0)
        HPRAY_CHECK(EVP_DigestUpdate(static_cast<EVP_MD_CTX*>(context_), data, bytes) ==
                    1);
}

std::string Sha256::HexDigest() {
    unsigned char digest[EVP_MAX_MD_SIZE];
    unsigned int length = 0;
    HPRAY_CHECK(EVP_DigestFinal_ex(static_cast<EVP_MD_CTX*>(context_), digest, &length) ==
                1);
    std::string hex;
    char byte[3];
    for (unsigned int i = 0; i < length; ++i) {
        std::snprintf(byte, sizeof byte, "%02x", digest[i]);
        hex += byte;
    }
    return hex;
}

std::string FileSha256(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw InputError(path, "", "cannot open");
    Sha256 sha;
    std::vector<char> buffer(std::size_t(1) << 20);
    while (in) {
        in.read(buffer.data(), static_cast<std::streamsize>(buffer.size()));
        const std::streamsize n = in.gcount();
        if (n > 0) sha.Update(buffer.data(), static_cast<std::size_t>(n));
    }
    if (in.bad()) throw InputError(path, "", "read error");
    return sha.HexDigest();
}

std::string Partition::BrickPath(int brick) const {
    HPRAY_CHECK(brick >= 0 && brick < static_cast<int>(bricks.size()));
    return (fs::path(dir) / bricks[brick].file).string();
}

bool IsPartitionDirectory(const std::string& path) {
    std::error_code ec;
    return fs::is_directory(path, ec) &&
           fs::is_regular_file(fs::path(path) / "manifest.json", ec);
}

Partition ReadPartition(const std::string& dir) {
    const std::string path = (fs::path(dir) / "manifest.json").string();
    const ManifestChecker check{path};
    Partition p;
    p.dir = dir;
    {
        std::ifstream in(path, std::ios::binary);
        if (!in) throw InputError(path, "", "cannot open (not a partition directory?)");
        std::ostringstream text;
        text << in.rdbuf();
        if (text.str().size() > (std::size_t(256) << 20))
            throw InputError(path, "", "is larger than 256 MiB");
        try {
            p.manifest = json::parse(text.str());
        } catch (const json::parse_error& e) {
            throw InputError(path, "byte " + std::to_string(e.byte),
                             "JSON error: " + std::string(e.what()));
        }
    }
    const json& m = p.manifest;
    if (!m.is_object()) check.Fail("", "is not a JSON object");
    const json& bricks = check.Member(m, "bricks", "");
    if (!bricks.is_array() || bricks.empty())
        check.Fail("bricks", "is not a non-empty array");
    if (bricks.size() > 1000000) check.Fail("bricks", "has too many entries");
    for (std::size_t i = 0; i < bricks.size(); ++i) {
        const std::string where = "bricks[" + std::to_string(i) + "]";
        const json& b = bricks[i];
        BrickInfo info;
        const json& file = check.Member(b, "file", where);
        if (!file.is_string()) check.Fail(where + ".file", "is not a string");
        info.file = file.get<std::string>();
        if (info.file.empty() || info.file.find('/') != std::string::npos ||
            info.file == "." || info.file == "..")
            check.Fail(where + ".file",
                       "'" + info.file + "' is not a file name in the folder");
        info.box = check.ParseBox(check.Member(b, "box", where), where + ".box");
        info.cells = check.Count(check.Member(b, "cells", where), where + ".cells");
        info.ghosts = check.Count(check.Member(b, "ghosts", where), where + ".ghosts");
        if (info.ghosts > info.cells) check.Fail(where + ".ghosts", "exceeds cells");
        info.cost = check.Number(check.Member(b, "cost", where), where + ".cost");
        if (info.cost < 0) check.Fail(where + ".cost", "is negative");
        const json& ranges = check.Member(b, "ranges", where);
        if (!ranges.is_object()) check.Fail(where + ".ranges", "is not an object");
        for (const auto& [name, r] : ranges.items()) {
            const std::string rw = where + ".ranges." + name;
            if (!r.is_array() || r.size() != 2) check.Fail(rw, "is not [min, max]");
            const double lo = check.Number(r[0], rw), hi = check.Number(r[1], rw);
            if (lo > hi) check.Fail(rw, "has min > max");
            info.ranges[name] = {lo, hi};
        }
        const json& sha = check.Member(b, "sha256", where);
        if (!sha.is_string() || sha.get<std::string>().size() != 64 ||
            sha.get<std::string>().find_first_not_of("0123456789abcdef") !=
                std::string::npos)
            check.Fail(where + ".sha256", "is not 64 lowercase hex digits");
        info.sha256 = sha.get<std::string>();
        const std::string brickPath = (fs::path(dir) / info.file).string();
        std::error_code ec;
        if (!fs::is_regular_file(brickPath, ec))
            throw InputError(
                brickPath, "",
                "brick " + std::to_string(i) + " listed in " + path + " is missing");
        const std::uint64_t size = fs::file_size(brickPath, ec);
        if (b.contains("bytes")) {
            info.bytes =
                static_cast<std::uint64_t>(check.Count(b["bytes"], where + ".bytes"));
            if (size != info.bytes)
                throw InputError(
                    brickPath, "",
                    "has " + std::to_string(size) + " bytes, the manifest says " +
                        std::to_string(info.bytes) + " (truncated, or from another run)");
        } else {
            info.bytes = size;
        }
        p.bricks.push_back(std::move(info));
    }

    // Root box: given, or the union of the leaf boxes.
    Box& rootBox = p.tree.box;
    if (m.contains("root_box")) {
        rootBox = check.ParseBox(m["root_box"], "root_box");
    } else {
        rootBox = Box::Empty();
        for (const BrickInfo& b : p.bricks) rootBox.Extend(b.box);
    }
    std::vector<KdNode>& nodes = p.tree.nodes;

    // The tree: every brick exactly once, leaf boxes carved out of the root box.
    std::vector<int> seen(p.bricks.size(), 0);
    const std::size_t maxNodes = 2 * p.bricks.size() - 1;
    std::function<int(const json&, const std::string&, const Box&, int)> parse =
        [&](const json& node, const std::string& where, const Box& box,
            int depth) -> int {
        if (depth > 200) check.Fail(where, "is nested too deeply");
        if (nodes.size() >= maxNodes)
            check.Fail(where, "has more nodes than the bricks allow");
        if (!node.is_object()) check.Fail(where, "is not an object");
        const int index = static_cast<int>(nodes.size());
        nodes.emplace_back();
        if (node.contains("brick")) {
            const std::int64_t b = check.Count(node["brick"], where + ".brick");
            if (b >= static_cast<std::int64_t>(p.bricks.size()))
                check.Fail(where + ".brick", std::to_string(b) + " is not a brick index");
            if (seen[b]++)
                check.Fail(where + ".brick", std::to_string(b) + " appears twice");
            if (!SameBox(p.bricks[b].box, box))
                check.Fail("bricks[" + std::to_string(b) + "].box",
                           "differs from the box the tree's splits give");
            nodes[index].leaf = static_cast<int>(b);
            return index;
        }
        const std::int64_t axis =
            check.Count(check.Member(node, "axis", where), where + ".axis");
        if (axis > 2) check.Fail(where + ".axis", "is not 0, 1 or 2");
        const double split =
            check.Number(check.Member(node, "split", where), where + ".split");
        if (split < box.lo[axis] || split > box.hi[axis])
            check.Fail(where + ".split", "is outside the node's box");
        Box lowBox = box, highBox = box;
        lowBox.hi[axis] = split;
        highBox.lo[axis] = split;
        const int low =
            parse(check.Member(node, "low", where), where + ".low", lowBox, depth + 1);
        const int high =
            parse(check.Member(node, "high", where), where + ".high", highBox, depth + 1);
        KdNode& n = nodes[index];
        n.axis = static_cast<int>(axis);
        n.split = split;
        if (node.contains("tie")) {
            const json& tie = node["tie"];
            if (!tie.is_array() || tie.size() != 2)
                check.Fail(where + ".tie", "is not [y, z]");
            n.tieBreak = true;
            n.tie = {check.Number(tie[0], where + ".tie"),
                     check.Number(tie[1], where + ".tie")};
        }
        n.low = low;
        n.high = high;
        return index;
    };
    parse(check.Member(m, "tree", ""), "tree", rootBox, 0);
    for (std::size_t b = 0; b < seen.size(); ++b)
        if (!seen[b]) check.Fail("tree", "has no leaf for brick " + std::to_string(b));
    // The bricks' regions under the ownership rule (open faces on inner split planes).
    const std::vector<Box> leafBoxes = p.tree.LeafBoxes();
    for (std::size_t b = 0; b < p.bricks.size(); ++b) p.bricks[b].box = leafBoxes[b];
    return p;
}

void VerifyBrick(const Partition& partition, int brick) {
    const std::string path = partition.BrickPath(brick);
    const std::string actual = FileSha256(path);
    if (actual != partition.bricks[brick].sha256)
        throw InputError(path, "",
                         "checksum mismatch: the manifest says sha256 " +
                             partition.bricks[brick].sha256 + ", the file has " + actual +
                             " (corrupt, or written by another run)");
}

Mesh LoadBrick(const Partition& partition, int brick, const ReadOptions& options) {
    VerifyBrick(partition, brick);
    const std::string path = partition.BrickPath(brick);
    Mesh mesh = ReadMesh(path, options);
    const BrickInfo& info = partition.bricks[brick];
    std::int64_t ghosts = 0;
    for (std::uint8_t g : mesh.ghost) ghosts += (g & 1) != 0;
    if (mesh.CellCount() != info.cells || ghosts != info.ghosts)
        throw InputError(path, "",
                         "holds " + std::to_string(mesh.CellCount()) + " cells (" +
                             std::to_string(ghosts) + " ghosts), the manifest says " +
                             std::to_string(info.cells) + " (" +
                             std::to_string(info.ghosts) + ")");
    return mesh;
}

json SummarizePartition(const std::string& dir) {
    const Partition p = ReadPartition(dir);
    std::int64_t cells = 0, ghosts = 0;
    std::uint64_t bytes = 0;
    double maxCost = 0, sumCost = 0;
    const int depth = p.tree.Height();
    bool checksumsOk = true;
    json failures = json::array();
    for (int b = 0; b < static_cast<int>(p.bricks.size()); ++b) {
        const BrickInfo& info = p.bricks[b];
        cells += info.cells;
        ghosts += info.ghosts;
        bytes += info.bytes;
        maxCost = std::max(maxCost, info.cost);
        sumCost += info.cost;
        try {
            VerifyBrick(p, b);
        } catch (const InputError& e) {
            checksumsOk = false;
            failures.push_back(e.what());
        }
    }
    const double n = static_cast<double>(p.bricks.size());
    json j;
    j["partition"] = dir;
    j["bricks"] = p.bricks.size();
    j["cells"] = cells;
    j["owned_cells"] = cells - ghosts;
    j["ghosts"] = ghosts;
    j["ghost_fraction"] = cells > 0 ? static_cast<double>(ghosts) / cells : 0.0;
    j["cost_total"] = sumCost;
    j["cost_max"] = maxCost;
    j["cost_mean"] = sumCost / n;
    j["balance"] = sumCost > 0 ? maxCost / (sumCost / n) : 1.0;
    std::error_code ec;
    const std::uint64_t manifestBytes =
        fs::file_size(fs::path(dir) / "manifest.json", ec);
    const std::uint64_t indexBytes = fs::file_size(fs::path(dir) / "bricks.pvtu", ec);
    j["bytes"] = bytes + (ec ? 0 : indexBytes) + manifestBytes;
    j["brick_bytes"] = bytes;
    j["tree_depth"] = depth;
    j["bounds"] = {p.tree.box.lo, p.tree.box.hi};
    j["fields"] = p.manifest.contains("fields") ? p.manifest["fields"] : json::object();
    j["checksums_ok"] = checksumsOk;
    if (!checksumsOk) j["checksum_failures"] = failures;
    if (p.manifest.contains("source")) j["source"] = p.manifest["source"];
    return j;
}

std::string FormatPartitionSummary(const json& s) {
    std::ostringstream os;
    char line[256];
    os << s.value("partition", std::string()) << " (partition";
    if (s.contains("source") && s["source"].is_string())
        os << " of " << s["source"].get<std::string>();
    os << ")\n";
    std::snprintf(line, sizeof line, "  bricks    %lld (k-d tree depth %d)\n",
                  s["bricks"].get<long long>(), s["tree_depth"].get<int>());
    os << line;
    std::snprintf(
        line, sizeof line, "  cells     %lld stored, %lld owned, %lld ghosts (%.2f%%)\n",
        s["cells"].get<long long>(), s["owned_cells"].get<long long>(),
        s["ghosts"].get<long long>(), 100.0 * s["ghost_fraction"].get<double>());
    os << line;
    std::snprintf(line, sizeof line, "  balance   %.4f (max/mean cost: %.6g / %.6g)\n",
                  s["balance"].get<double>(), s["cost_max"].get<double>(),
                  s["cost_mean"].get<double>());
    os << line;
    const auto& b = s["bounds"];
    std::snprintf(line, sizeof line,
                  "  bounds    [%.9g, %.9g] x [%.9g, %.9g] x [%.9g, %.9g]\n",
                  b[0][0].get<double>(), b[1][0].get<double>(), b[0][1].get<double>(),
                  b[1][1].get<double>(), b[0][2].get<double>(), b[1][2].get<double>());
    os << line;
    for (const auto& [name, f] : s["fields"].items()) {
        std::snprintf(line, sizeof line, "  field     %-24s %-5s %d component%s\n",
                      name.c_str(), f.value("association", std::string("?")).c_str(),
                      f.value("components", 1), f.value("components", 1) == 1 ? "" : "s");
        os << line;
    }
    std::snprintf(line, sizeof line, "  bytes     %.1f MiB (%llu)\n",
                  s["bytes"].get<double>() / (1024.0 * 1024.0),
                  s["bytes"].get<unsigned long long>());
    os << line;
    os << "  checksums " << (s["checksums_ok"].get<bool>() ? "ok" : "MISMATCH") << "\n";
    if (s.contains("checksum_failures"))
        for (const auto& f : s["checksum_failures"])
            os << "    " << f.get<std::string>() << "\n";
    return os.str();
}

}  // namespace hpray::partition
