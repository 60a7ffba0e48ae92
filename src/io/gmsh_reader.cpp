// Gmsh MSH 4.1 reader (ASCII and binary): nodes, 3-D elements, $NodeData and
// $ElementData.
//
// Layout of the sections read here (gmsh reference manual, "MSH file format" 4.1); in a
// binary file the numbers are raw (int: 4 bytes, size_t: the data size of $MeshFormat,
// double: 8 bytes, all in the writer's byte order, told by the integer 1 written after
// the format line), while section names and the string/real/integer tags of data sections
// stay text:
//   $Nodes    numBlocks numNodes minTag maxTag (size_t), then per block
//             entityDim entityTag parametric (int) numNodesInBlock (size_t),
//             the block's node tags (size_t), then x y z [u v w] (double) per node
//   $Elements numBlocks numElements minTag maxTag (size_t), then per block
//             entityDim entityTag elementType (int) numElementsInBlock (size_t),
//             then per element its tag and node tags (size_t)
//   $NodeData / $ElementData  text tags, then per entity tag (int) and values (double)
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <map>
#include <sstream>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include "io/gmsh_detail.h"
#include "io/gmsh_nodes.h"
#include "io/file_bytes.h"
#include "io/mesh_io.h"
#include "io/vtk_cells.h"
#include "util/check.h"
#include "util/error.h"
#include "util/log.h"

namespace hpray {
namespace {

// Values of one data section, by entity index (point or cell), before choosing a time
// step.
struct PendingField {
    Association association = Association::Point;
    long long timeStep = 0;
    int components = 1;
    std::vector<double> values;       // components per entity; NaN where not given
    std::vector<std::uint8_t> given;  // 1 where the entity has values
    std::size_t sectionPos = 0;       // where the (last) section starts, for errors
};

class MshParser {
  public:
    MshParser(const std::string& path, const ReadOptions& options)
        : path_(path), options_(options), buf_(ReadWholeFile(path)) {}

    Mesh Parse();

    // ---- the reader interface of io/gmsh_detail.h ----
    // positions and errors
    std::string Where(std::size_t pos) const { return ByteOrLineWhere(buf_, pos, binary_); }
    [[noreturn]] void FailAt(std::size_t pos, const std::string& message) const {
        throw InputError(path_, Where(pos), message);
    }
    [[noreturn]] void Fail(const std::string& message) const { FailAt(last_, message); }
    std::size_t Last() const { return last_; }
    bool Binary() const { return binary_; }
    void SetEncoding(bool binary, bool swap, int sizeT) {
        binary_ = binary;
        swap_ = swap;
        sizeT_ = sizeT;
    }
    std::uint32_t UnswappedUInt32(const char* what) {
        Need(4, what);
        std::uint32_t v;
        std::memcpy(&v, buf_.data() + pos_, 4);
        pos_ += 4;
        return v;
    }

    // ---- text ----
    static bool IsSpace(char c) {
        return c == ' ' || c == '\t' || c == '\r' || c == '\n';
    }
    void SkipSpace() {
        while (pos_ < buf_.size() && IsSpace(buf_[pos_])) ++pos_;
    }
    bool AtEnd() {
        SkipSpace();
        return pos_ >= buf_.size();
    }
    std::string_view Token(const char* what) {
        SkipSpace();
        last_ = pos_;
        if (pos_ >= buf_.size())
            Fail(std::string("unexpected end of file, expected ") + what);
        const std::size_t start = pos_;
        while (pos_ < buf_.size() && !IsSpace(buf_[pos_])) ++pos_;
        return std::string_view(buf_.data() + start, pos_ - start);
    }
    std::uint64_t TextUnsigned(const char* what) { return gmsh::TextUnsigned(*this, what); }
    long long TextInt(const char* what) { return gmsh::TextInt(*this, what); }
    double TextDouble(const char* what) { return gmsh::TextDouble(*this, what); }
    // A string tag: "quoted, possibly with spaces" or one bare token.
    std::string TextString(const char* what) {
        SkipSpace();
        last_ = pos_;
        if (pos_ < buf_.size() && buf_[pos_] == '"') {
            const std::size_t close = buf_.find('"', pos_ + 1);
            const std::size_t eol = buf_.find('\n', pos_ + 1);
            if (close == std::string::npos || (eol != std::string::npos && eol < close))
                Fail(std::string("unterminated quoted ") + what);
            std::string s = buf_.substr(pos_ + 1, close - pos_ - 1);
            pos_ = close + 1;
            return s;
        }
        return std::string(Token(what));
    }
    void Expect(const char* keyword) {
        const std::string_view t = AtEnd() ? std::string_view() : Token(keyword);
        if (t.empty())
            FailAt(buf_.size(),
                   std::string("unexpected end of file, expected ") + keyword);
        if (t != keyword)
            Fail(std::string("expected ") + keyword + ", found '" +
                 std::string(t.substr(0, 40)) + "'");
    }
    // Binary data starts right after the newline that ends the preceding text line.
    void EndOfTextLine() {
        while (pos_ < buf_.size() &&
               (buf_[pos_] == ' ' || buf_[pos_] == '\t' || buf_[pos_] == '\r'))
            ++pos_;
        last_ = pos_;
        if (pos_ >= buf_.size() || buf_[pos_] != '\n')
            Fail("expected the end of the line");
        ++pos_;
    }

    // ---- binary ----
    void Need(std::size_t bytes, const char* what) {
        last_ = pos_;
        if (buf_.size() - pos_ < bytes) {
            std::ostringstream os;
            os << "binary data cut short: " << what << " needs " << bytes << " bytes, "
               << buf_.size() - pos_ << " left in the file";
            Fail(os.str());
        }
    }
    template <typename T>
    T Raw() {
        T v;
        unsigned char b[sizeof(T)];
        std::memcpy(b, buf_.data() + pos_, sizeof(T));
        if (swap_) std::reverse(b, b + sizeof(T));
        std::memcpy(&v, b, sizeof(T));
        pos_ += sizeof(T);
        return v;
    }

    // ---- numbers of either encoding ----
    std::uint64_t Size(const char* what) {
        if (!binary_) return TextUnsigned(what);
        Need(sizeT_, what);
        return sizeT_ == 8 ? Raw<std::uint64_t>() : Raw<std::uint32_t>();
    }
    long long Int(const char* what) {
        if (!binary_) return TextInt(what);
        Need(4, what);
        return Raw<std::int32_t>();
    }
    double Double(const char* what) {
        if (!binary_) return TextDouble(what);
        Need(8, what);
        return Raw<double>();
    }
    // Skips `count` size_t values (binary) or tokens (ASCII).
    void SkipSizes(std::uint64_t count, const char* what) {
        if (binary_) {
            CheckCount(count, sizeT_, what);
            pos_ += count * sizeT_;
        } else {
            for (std::uint64_t i = 0; i < count; ++i) Token(what);
        }
    }
    // Rejects a declared count that the rest of the file cannot hold at `minBytes` each,
    // before anything is allocated for it.
    void CheckCount(std::uint64_t count, std::uint64_t minBytes, const char* what) {
        const std::uint64_t left = buf_.size() - std::min(pos_, buf_.size());
        if (minBytes > 0 && count > left / minBytes) {
            std::ostringstream os;
            os << "declared " << what << " count " << count << " is more than the "
               << left << " bytes left in the file can hold";
            Fail(os.str());
        }
    }
    // Minimal size of an item of `sizes` size_t and `doubles` doubles in this encoding
    // (ASCII: one digit and one separator per number).
    std::uint64_t MinBytes(int sizes, int ints, int doubles) const {
        return binary_ ? std::uint64_t(sizes) * sizeT_ + 4ull * ints + 8ull * doubles
                       : 2ull * (sizes + ints + doubles);
    }

  private:
    // ---- sections ----
    void ParseNodes();
    void ParseElements();
    void ParseData(const std::string& section);
    void SkipSection(const std::string& name, std::size_t headerPos);
    std::int64_t NodeIndex(std::uint64_t tag) const {
        if (denseTags_) return tag < nodeIndexDense_.size() ? nodeIndexDense_[tag] : -1;
        auto it = nodeIndexSparse_.find(tag);
        return it == nodeIndexSparse_.end() ? -1 : it->second;
    }
    void FinishFields();

    std::string path_;
    const ReadOptions& options_;
    std::string buf_;
    std::size_t pos_ = 0;
    std::size_t last_ = 0;  // start of the last value read: where errors point
    bool binary_ = false;
    bool swap_ = false;
    int sizeT_ = 8;
    bool haveNodes_ = false, haveElements_ = false;

    Mesh mesh_;
    bool denseTags_ = true;
    std::vector<std::int64_t> nodeIndexDense_;
    std::unordered_map<std::uint64_t, std::int64_t> nodeIndexSparse_;
    std::vector<std::uint64_t> cellTags_;
    std::uint64_t skippedElements_ = 0;
    std::map<std::string, PendingField> pointData_, cellData_;
};

void MshParser::ParseNodes() {
    if (haveNodes_) Fail("a second $Nodes section");
    haveNodes_ = true;
    if (binary_) EndOfTextLine();
    const gmsh::NodesHeader header = gmsh::ReadNodesHeader(*this);
    const std::uint64_t numBlocks = header.numBlocks, numNodes = header.numNodes;
    const std::uint64_t maxTag = header.maxTag;
    // A dense tag -> index table when the tags are not much sparser than the nodes.
    denseTags_ = numNodes == 0 || maxTag <= 2 * numNodes + 1024;
    if (denseTags_) nodeIndexDense_.assign(numNodes == 0 ? 0 : maxTag + 1, -1);
    mesh_.points.reserve(3 * numNodes);

    std::vector<std::uint64_t> tags;
    std::uint64_t total = 0;
    for (std::uint64_t b = 0; b < numBlocks; ++b) {
        const gmsh::NodeBlockHeader block =
            gmsh::ReadNodeBlockHeader(*this, header, total);
        const std::uint64_t count = block.count;
        const int extra = block.extra;
        tags.resize(count);
        for (std::uint64_t i = 0; i < count; ++i) {
            const std::uint64_t tag = Size("a node tag");
            gmsh::CheckNodeTag(*this, header, tag);
            const std::int64_t index = static_cast<std::int64_t>(total + i);
            bool fresh;
            if (denseTags_) {
                fresh = nodeIndexDense_[tag] < 0;
                if (fresh) nodeIndexDense_[tag] = index;
            } else {
                fresh = nodeIndexSparse_.emplace(tag, index).second;
            }
            if (!fresh) Fail("node tag " + std::to_string(tag) + " is defined twice");
            tags[i] = tag;
        }
        for (std::uint64_t i = 0; i < count; ++i) {
            for (int c = 0; c < 3; ++c) {
                const double x = Double("a node coordinate");
                if (!std::isfinite(x))
                    Fail("node tag " + std::to_string(tags[i]) +
                         " has a NaN or infinite coordinate");
                mesh_.points.push_back(x);
            }
            for (int c = 0; c < extra; ++c) Double("a parametric coordinate");
        }
        total += count;
    }
    if (total != numNodes)
        Fail("node blocks hold " + std::to_string(total) +
             " nodes, the header declares " + std::to_string(numNodes));
    Expect("$EndNodes");
}

void MshParser::ParseElements() {
    if (!haveNodes_) Fail("$Elements before $Nodes");
    if (haveElements_) Fail("a second $Elements section");
    haveElements_ = true;
    if (binary_) EndOfTextLine();
    const gmsh::ElementsHeader header = gmsh::ReadElementsHeader(*this);
    const std::uint64_t numBlocks = header.numBlocks, numElements = header.numElements;

    std::vector<std::int64_t> fileNodes, cellNodes;
    std::uint64_t total = 0;
    for (std::uint64_t b = 0; b < numBlocks; ++b) {
        const gmsh::ElementBlockHeader block =
            gmsh::ReadElementBlockHeader(*this, header, total);
        const std::uint64_t count = block.count;
        const int nodes = block.nodes;
        total += count;
        if (block.dim < 3) {
            SkipSizes(count * (1 + nodes), "an element tag or node tag");
            skippedElements_ += count;
            continue;
        }
        const std::optional<GmshCellType>& kind = block.kind;
        const std::vector<int>& perm = GmshToInternal(kind->type);
        // Gmsh has no VTK types; record the one a gmsh user expects to see in a .vtu
        // (tet10 -> 24, hex20 -> 25, hex27 -> 29, prism15 -> 26, prism18 -> 73,
        // pyramid13 -> 27, linear cells 10-14, others 71-74: FixedVtkTypeFor).
        const auto vtkType = static_cast<std::uint8_t>(
            FixedVtkTypeFor(CellKind{kind->shape, kind->order, kind->family}));
        fileNodes.resize(nodes);
        cellNodes.resize(nodes);
        mesh_.connectivity.reserve(mesh_.connectivity.size() + count * nodes);
        for (std::uint64_t e = 0; e < count; ++e) {
            const std::uint64_t tag = Size("an element tag");
            const std::size_t tagPos = last_;
            for (int k = 0; k < nodes; ++k) {
                const std::uint64_t nodeTag = Size("a node tag");
                const std::int64_t index = NodeIndex(nodeTag);
                if (index < 0)
                    FailAt(tagPos, "element " + std::to_string(tag) +
                                       " references undefined node tag " +
                                       std::to_string(nodeTag));
                fileNodes[k] = index;
            }
            for (int k = 0; k < nodes; ++k) cellNodes[k] = fileNodes[perm[k]];
            mesh_.AddCell(kind->shape, kind->order, kind->family, cellNodes.data(),
                          nodes);
            mesh_.vtkType.push_back(vtkType);
            cellTags_.push_back(tag);
        }
    }
    if (total != numElements)
        Fail("element blocks hold " + std::to_string(total) +
             " elements, the header declares " + std::to_string(numElements));
    Expect("$EndElements");
}

void MshParser::ParseData(const std::string& section) {
    const std::size_t sectionPos = last_;
    const bool isNode = section == "NodeData";
    const bool isElementNode = section == "ElementNodeData";
    const gmsh::DataHeader header = gmsh::ReadDataHeader(*this);
    const std::string& name = header.name;
    const long long timeStep = header.timeStep;
    const long long components = header.components;
    const long long count = header.count;
    if (binary_) EndOfTextLine();
    const std::uint64_t itemBytes =
        binary_ ? 4 + 8ull * components : 2ull * (1 + components);

    if (!haveNodes_ || (!isNode && !haveElements_))
        FailAt(sectionPos, "$" + section + " before the " +
                               (isNode ? "$Nodes" : "$Elements") + " it refers to");
    if (isElementNode) {
        if (options_.fields && options_.Wants(name))
            FailAt(sectionPos, "field '" + name +
                                   "' is $ElementNodeData, which hpray does not read; "
                                   "write it as $NodeData");
        log::Warn(path_ + ": skipping $ElementNodeData '" + name +
                  "' (element-node data is not read)");
        SkipSection(section, sectionPos);
        return;
    }
    CheckCount(static_cast<std::uint64_t>(count), itemBytes, "data entry");
    const bool wanted = options_.Wants(name);
    if (!wanted) {
        if (binary_) {
            pos_ += count * itemBytes;
        } else {
            for (long long i = 0; i < count * (1 + components); ++i) Token("a value");
        }
        Expect(("$End" + section).c_str());
        return;
    }

    auto& fields = isNode ? pointData_ : cellData_;
    const std::int64_t entities = isNode ? mesh_.PointCount() : mesh_.CellCount();
    auto it = fields.find(name);
    if (it != fields.end() && timeStep < it->second.timeStep) {  // an older step: skip
        if (binary_) {
            pos_ += count * itemBytes;
        } else {
            for (long long i = 0; i < count * (1 + components); ++i) Token("a value");
        }
        Expect(("$End" + section).c_str());
        return;
    }
    if (it == fields.end() || timeStep > it->second.timeStep ||
        it->second.components != components) {
        if (it != fields.end() && timeStep == it->second.timeStep)
            FailAt(sectionPos, "'" + name + "' has " + std::to_string(components) +
                                   " components here and " +
                                   std::to_string(it->second.components) + " before");
        PendingField f;
        f.association = isNode ? Association::Point : Association::Cell;
        f.timeStep = timeStep;
        f.components = static_cast<int>(components);
        f.values.assign(entities * components, std::numeric_limits<double>::quiet_NaN());
        f.given.assign(entities, 0);
        it = fields.insert_or_assign(name, std::move(f)).first;
    }
    PendingField& f = it->second;
    f.sectionPos = sectionPos;

    // Element tag -> cell index, built once (lower-dimensional elements are not cells).
    std::unordered_map<std::uint64_t, std::int64_t> cellIndexLocal;
    if (!isNode) {
        cellIndexLocal.reserve(cellTags_.size());
        for (std::size_t c = 0; c < cellTags_.size(); ++c)
            cellIndexLocal.emplace(cellTags_[c], static_cast<std::int64_t>(c));
    }
    for (long long i = 0; i < count; ++i) {
        const long long tag = Int(isNode ? "a node tag" : "an element tag");
        const std::size_t tagPos = last_;
        std::int64_t index = -1;
        if (isNode) {
            if (tag > 0) index = NodeIndex(static_cast<std::uint64_t>(tag));
            if (index < 0)
                FailAt(tagPos, "$NodeData '" + name + "' refers to undefined node tag " +
                                   std::to_string(tag));
        } else if (tag > 0) {
            auto c = cellIndexLocal.find(static_cast<std::uint64_t>(tag));
            if (c != cellIndexLocal.end()) index = c->second;
        }
        for (long long k = 0; k < components; ++k) {
            const double v = Double("a value");
            if (!std::isfinite(v))
                Fail("'" + name + "' has a NaN or infinite value at tag " +
                     std::to_string(tag));
            if (index >= 0) f.values[index * components + k] = v;
        }
        if (index >= 0) f.given[index] = 1;
    }
    Expect(("$End" + section).c_str());
}

void MshParser::SkipSection(const std::string& name, std::size_t headerPos) {
    const std::string end = "$End" + name;
    std::size_t at = pos_;
    while (true) {
        at = buf_.find(end, at);
        if (at == std::string::npos)
            FailAt(headerPos, "section $" + name + " has no " + end);
        const bool startsLine = at == 0 || buf_[at - 1] == '\n';
        const std::size_t after = at + end.size();
        const bool endsToken = after >= buf_.size() || IsSpace(buf_[after]);
        if (startsLine && endsToken) break;
        at = after;
    }
    pos_ = at + end.size();
}

void MshParser::FinishFields() {
    auto finish = [&](std::map<std::string, PendingField>& pending,
                      std::vector<Field>& out, std::int64_t entities, const char* what) {
        for (auto& [name, f] : pending) {
            const std::int64_t given = std::count(f.given.begin(), f.given.end(), 1);
            if (given != entities)
                FailAt(f.sectionPos, "'" + name + "' (time step " +
                                         std::to_string(f.timeStep) +
                                         ") gives values for " + std::to_string(given) +
                                         " of the " + std::to_string(entities) + " " +
                                         what + "; hpray needs a value for each");
            Field field;
            field.name = name;
            field.association = f.association;
            field.components = f.components;
            field.values = std::move(f.values);
            out.push_back(std::move(field));
        }
    };
    finish(pointData_, mesh_.pointFields, mesh_.PointCount(), "nodes");
    finish(cellData_, mesh_.cellFields, mesh_.CellCount(), "3-D elements");
}

Mesh MshParser::Parse() {
    bool first = true;
    while (!AtEnd()) {
        const std::string_view token = Token("a section header");
        const std::size_t headerPos = last_;
        if (first && token != "$MeshFormat")
            Fail("not a gmsh MSH file: it must start with $MeshFormat");
        if (token.empty() || token[0] != '$')
            Fail("expected a section header ($Name), found '" +
                 std::string(token.substr(0, 40)) + "'");
        const std::string name(token.substr(1));
        if (first) {
            gmsh::ParseMeshFormat(*this);
            first = false;
            continue;
        }
        if (name == "MeshFormat")
            Fail("a second $MeshFormat section");
        else if (name == "Nodes")
            ParseNodes();
        else if (name == "Elements")
            ParseElements();
        else if (name == "Entities") {
            if (binary_) EndOfTextLine();
            gmsh::SkipEntities(*this);
        } else if (name == "PartitionedEntities") {
            if (binary_) EndOfTextLine();
            gmsh::SkipPartitionedEntities(*this);
        } else if (name == "NodeData" || name == "ElementData" ||
                   name == "ElementNodeData")
            ParseData(name);
        else if (name.rfind("End", 0) == 0)
            Fail("unexpected " + std::string(token));
        else
            SkipSection(name, headerPos);  // $PhysicalNames, $Periodic, ... : not needed
    }
    if (first) FailAt(0, "empty file: not a gmsh MSH file");
    if (!haveNodes_) FailAt(buf_.size(), "no $Nodes section");
    if (!haveElements_) FailAt(buf_.size(), "no $Elements section");
    if (skippedElements_ > 0)
        log::Warn(path_ + ": skipped " + std::to_string(skippedElements_) +
                  " elements of dimension below 3");
    FinishFields();
    mesh_.Validate(path_);
    return std::move(mesh_);
}

}  // namespace

Mesh ReadGmsh(const std::string& path, const ReadOptions& options) {
    MshParser parser(path, options);
    return parser.Parse();
}

}  // namespace hpray
