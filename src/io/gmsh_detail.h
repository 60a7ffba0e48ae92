// Pieces of Gmsh MSH 4.1 parsing shared by the whole-file reader (gmsh_reader.cpp) and
// the streaming input of the partitioner: field selection, text numbers, section headers
// and the sections both skip, written once over a reader type.
//
// A reader R passed to the templates provides (positions are byte offsets in the file):
//   std::uint64_t Size(const char* what)     size_t value (text, or raw of the data size)
//   long long Int(const char* what)          int value (text, or raw 4 bytes)
//   double Double(const char* what)          double value (text, or raw 8 bytes)
//   long long TextInt / double TextDouble / std::uint64_t TextUnsigned(const char* what)
//   std::string TextString(const char* what) quoted or bare string tag
//   std::string_view Token(const char* what) the next whitespace-separated token
//   void Expect(const char* keyword)         next token must be `keyword`
//   void EndOfTextLine()                     binary data starts after this newline
//   std::uint32_t UnswappedUInt32(const char* what)  4 raw bytes in host order
//   void SetEncoding(bool binary, bool swap, int sizeT)
//   void CheckCount(std::uint64_t count, std::uint64_t minBytes, const char* what)
//   std::uint64_t MinBytes(int sizes, int ints, int doubles) const
//   bool Binary() const
//   std::uint64_t Last() const               where the last value read starts
//   [[noreturn]] void Fail(const std::string&)                at Last()
//   [[noreturn]] void FailAt(std::uint64_t pos, const std::string&)
#pragma once

#include <cstdint>
#include <optional>
#include <sstream>
#include <string>
#include <string_view>
#include <vector>

#include "io/gmsh_nodes.h"
#include "io/mesh_io.h"

namespace hpray::gmsh {

/// Whole-token number parsers (MSH text numbers); false if `text` is not one number.
/// ParseDouble accepts out-of-range values as strtod reads them (subnormals, +-inf).
bool ParseUnsigned(std::string_view text, std::uint64_t& value);
bool ParseInt(std::string_view text, long long& value);
bool ParseDouble(std::string_view text, double& value);

/// The next text token of reader `r` parsed as `what` by `parse`, or r.Fail naming what
/// was expected (`kind`) and what was found.
template <class T, class R>
T TextNumber(R& r, const char* what, bool (*parse)(std::string_view, T&), const char* kind) {
    const std::string_view t = r.Token(what);
    T v{};
    if (!parse(t, v))
        r.Fail(std::string("expected ") + what + " (" + kind + "), found '" +
               std::string(t.substr(0, 40)) + "'");
    return v;
}
template <class R>
std::uint64_t TextUnsigned(R& r, const char* what) {
    return TextNumber<std::uint64_t>(r, what, ParseUnsigned, "a non-negative integer");
}
template <class R>
long long TextInt(R& r, const char* what) {
    return TextNumber<long long>(r, what, ParseInt, "an integer");
}
template <class R>
double TextDouble(R& r, const char* what) {
    return TextNumber<double>(r, what, ParseDouble, "a number");
}

/// The message for a 3-D element type hpray does not read.
std::string UnsupportedTypeMessage(long long type, int nodes);

/// After the "$MeshFormat" token: version 4.1, file type, data size and (binary) the
/// endianness check integer; sets the reader's encoding; consumes $EndMeshFormat.
template <class R>
void ParseMeshFormat(R& r) {
    const std::string_view version = r.Token("the MSH version");
    if (version != "4.1") {
        std::string v(version.substr(0, 20));
        r.Fail("MSH version " + v +
               " is not supported; hpray reads MSH 4.1 (write it with "
               "gmsh -format msh41, or Mesh.MshFileVersion = 4.1)");
    }
    const std::uint64_t fileType = r.TextUnsigned("the file type (0 ASCII, 1 binary)");
    if (fileType > 1) r.Fail("file type must be 0 (ASCII) or 1 (binary)");
    const std::uint64_t dataSize = r.TextUnsigned("the data size");
    if (dataSize != 4 && dataSize != 8) r.Fail("data size must be 4 or 8");
    bool swap = false;
    if (fileType == 1) {
        r.EndOfTextLine();
        // From here on positions are byte offsets.
        r.SetEncoding(true, false, static_cast<int>(dataSize));
        const std::uint32_t one = r.UnswappedUInt32("the endianness check integer");
        if (one == 0x01000000u) {
            swap = true;
        } else if (one != 1) {
            std::ostringstream os;
            os << "the endianness check integer is " << one << ", expected 1";
            r.Fail(os.str());
        }
    }
    r.SetEncoding(fileType == 1, swap, static_cast<int>(dataSize));
    r.Expect("$EndMeshFormat");
}

/// The body of $Entities (after the header line), through $EndEntities.
template <class R>
void SkipEntities(R& r) {
    std::uint64_t counts[4];
    for (auto& c : counts) c = r.Size("an entity count");
    for (int dim = 0; dim < 4; ++dim) {
        r.CheckCount(counts[dim], r.MinBytes(1, 1, dim == 0 ? 3 : 6), "entity");
        for (std::uint64_t e = 0; e < counts[dim]; ++e) {
            r.Int("an entity tag");
            for (int i = 0; i < (dim == 0 ? 3 : 6); ++i) r.Double("an entity coordinate");
            const std::uint64_t physicals = r.Size("a physical tag count");
            r.CheckCount(physicals, r.MinBytes(0, 1, 0), "physical tag");
            for (std::uint64_t i = 0; i < physicals; ++i) r.Int("a physical tag");
            if (dim > 0) {
                const std::uint64_t bounding = r.Size("a bounding entity count");
                r.CheckCount(bounding, r.MinBytes(0, 1, 0), "bounding entity");
                for (std::uint64_t i = 0; i < bounding; ++i)
                    r.Int("a bounding entity tag");
            }
        }
    }
    r.Expect("$EndEntities");
}

/// The body of $PartitionedEntities, through $EndPartitionedEntities.
template <class R>
void SkipPartitionedEntities(R& r) {
    r.Size("the partition count");
    const std::uint64_t ghosts = r.Size("the ghost entity count");
    r.CheckCount(ghosts, r.MinBytes(0, 2, 0), "ghost entity");
    for (std::uint64_t i = 0; i < ghosts; ++i) {
        r.Int("a ghost entity tag");
        r.Int("a partition");
    }
    std::uint64_t counts[4];
    for (auto& c : counts) c = r.Size("an entity count");
    for (int dim = 0; dim < 4; ++dim) {
        r.CheckCount(counts[dim], r.MinBytes(2, 3, dim == 0 ? 3 : 6),
                     "partitioned entity");
        for (std::uint64_t e = 0; e < counts[dim]; ++e) {
            r.Int("an entity tag");
            r.Int("a parent dimension");
            r.Int("a parent tag");
            const std::uint64_t parts = r.Size("a partition count");
            r.CheckCount(parts, r.MinBytes(0, 1, 0), "partition tag");
            for (std::uint64_t i = 0; i < parts; ++i) r.Int("a partition tag");
            for (int i = 0; i < (dim == 0 ? 3 : 6); ++i) r.Double("an entity coordinate");
            const std::uint64_t physicals = r.Size("a physical tag count");
            r.CheckCount(physicals, r.MinBytes(0, 1, 0), "physical tag");
            for (std::uint64_t i = 0; i < physicals; ++i) r.Int("a physical tag");
            if (dim > 0) {
                const std::uint64_t bounding = r.Size("a bounding entity count");
                r.CheckCount(bounding, r.MinBytes(0, 1, 0), "bounding entity");
                for (std::uint64_t i = 0; i < bounding; ++i)
                    r.Int("a bounding entity tag");
            }
        }
    }
    r.Expect("$EndPartitionedEntities");
}

/// The header of $Nodes: numBlocks numNodes minTag maxTag.
struct NodesHeader {
    std::uint64_t numBlocks = 0, numNodes = 0, minTag = 0, maxTag = 0;
};

/// Reads and checks the $Nodes header (after the section line; binary: after its
/// newline).
template <class R>
NodesHeader ReadNodesHeader(R& r) {
    NodesHeader h;
    h.numBlocks = r.Size("the entity block count");
    r.CheckCount(h.numBlocks, r.MinBytes(1, 3, 0), "node entity block");
    h.numNodes = r.Size("the node count");
    r.CheckCount(h.numNodes, r.MinBytes(1, 0, 3), "node");
    h.minTag = r.Size("the minimum node tag");
    h.maxTag = r.Size("the maximum node tag");
    if (h.numNodes > 0 && (h.minTag > h.maxTag || h.minTag == 0))
        r.Fail("node tag range [" + std::to_string(h.minTag) + ", " +
               std::to_string(h.maxTag) + "] is invalid");
    return h;
}

/// The header of one node block: its node count and the parametric coordinates per node.
struct NodeBlockHeader {
    std::uint64_t count = 0;
    int extra = 0;  ///< parametric coordinates following x y z
};

/// Reads and checks a node block header; `total` nodes were in the blocks before.
template <class R>
NodeBlockHeader ReadNodeBlockHeader(R& r, const NodesHeader& h, std::uint64_t total) {
    const long long entityDim = r.Int("an entity dimension");
    if (entityDim < 0 || entityDim > 3) r.Fail("entity dimension must be 0..3");
    r.Int("an entity tag");
    const long long parametric = r.Int("the parametric flag");
    if (parametric != 0 && parametric != 1) r.Fail("parametric flag must be 0 or 1");
    NodeBlockHeader b;
    b.count = r.Size("the block's node count");
    const std::uint64_t countPos = r.Last();
    if (b.count > h.numNodes - total)
        r.FailAt(countPos, "node blocks hold more nodes than the declared " +
                               std::to_string(h.numNodes));
    b.extra = parametric ? static_cast<int>(entityDim) : 0;
    r.CheckCount(b.count, r.MinBytes(1, 0, 3 + b.extra), "node");
    return b;
}

/// Checks a node tag against the declared range.
template <class R>
void CheckNodeTag(R& r, const NodesHeader& h, std::uint64_t tag) {
    if (tag < h.minTag || tag > h.maxTag)
        r.Fail("node tag " + std::to_string(tag) + " is outside the declared range [" +
               std::to_string(h.minTag) + ", " + std::to_string(h.maxTag) + "]");
}

/// The header of $Elements: numBlocks numElements minTag maxTag (the tag range is not
/// checked: ReadGmsh does not rely on it).
struct ElementsHeader {
    std::uint64_t numBlocks = 0, numElements = 0, minTag = 0, maxTag = 0;
};

template <class R>
ElementsHeader ReadElementsHeader(R& r) {
    ElementsHeader h;
    h.numBlocks = r.Size("the entity block count");
    r.CheckCount(h.numBlocks, r.MinBytes(1, 3, 0), "element entity block");
    h.numElements = r.Size("the element count");
    r.CheckCount(h.numElements, r.MinBytes(2, 0, 0), "element");
    h.minTag = r.Size("the minimum element tag");
    h.maxTag = r.Size("the maximum element tag");
    return h;
}

/// One element block: its type, node count, dimension and element count; `kind` is set
/// for 3-D blocks (a 3-D type hpray does not read is an error).
struct ElementBlockHeader {
    long long type = 0;
    int nodes = 0;
    int dim = 0;
    std::uint64_t count = 0;
    std::optional<GmshCellType> kind;
};

/// Reads and checks an element block header; `total` elements were in earlier blocks.
template <class R>
ElementBlockHeader ReadElementBlockHeader(R& r, const ElementsHeader& h,
                                          std::uint64_t total) {
    ElementBlockHeader b;
    r.Int("an entity dimension");
    r.Int("an entity tag");
    b.type = r.Int("an element type");
    const std::uint64_t typePos = r.Last();
    b.count = r.Size("the block's element count");
    if (b.count > h.numElements - total)
        r.Fail("element blocks hold more elements than the declared " +
               std::to_string(h.numElements));
    b.nodes = GmshTypeNodeCount(static_cast<int>(b.type));
    b.dim = GmshTypeDimension(static_cast<int>(b.type));
    if (b.nodes <= 0)
        r.FailAt(typePos,
                 "unknown or variable-size gmsh element type " + std::to_string(b.type));
    r.CheckCount(b.count, r.MinBytes(1 + b.nodes, 0, 0), "element");
    if (b.dim == 3) {
        b.kind = ClassifyGmshType(static_cast<int>(b.type));
        if (!b.kind) r.FailAt(typePos, UnsupportedTypeMessage(b.type, b.nodes));
    }
    return b;
}

/// The text header of a $NodeData / $ElementData / $ElementNodeData section.
struct DataHeader {
    std::string name;  ///< the first string tag, "unnamed" without one
    long long timeStep = 0;
    int components = 1;
    long long count = 0;  ///< entries that follow
};

/// Reads the string, real and integer tags (after the section line) and checks them; the
/// reader stands before the data (binary: before the newline that ends the text).
template <class R>
DataHeader ReadDataHeader(R& r) {
    const long long numStrings = r.TextInt("the string tag count");
    if (numStrings < 0 || numStrings > 64) r.Fail("bad string tag count");
    std::vector<std::string> strings;
    for (long long i = 0; i < numStrings; ++i)
        strings.push_back(r.TextString("a string tag"));
    const long long numReals = r.TextInt("the real tag count");
    if (numReals < 0 || numReals > 64) r.Fail("bad real tag count");
    for (long long i = 0; i < numReals; ++i) r.TextDouble("a real tag");
    const long long numInts = r.TextInt("the integer tag count");
    if (numInts < 3 || numInts > 64)
        r.Fail(
            "a data section needs at least 3 integer tags (time step, components, "
            "count)");
    std::vector<long long> ints;
    for (long long i = 0; i < numInts; ++i) ints.push_back(r.TextInt("an integer tag"));
    DataHeader d;
    d.name = strings.empty() ? std::string("unnamed") : strings[0];
    d.timeStep = ints[0];
    const long long components = ints[1];
    d.count = ints[2];
    if (components < 1 || components > 64)
        r.Fail("'" + d.name + "': component count must be 1..64");
    if (d.count < 0) r.Fail("'" + d.name + "': negative entity count");
    d.components = static_cast<int>(components);
    return d;
}

}  // namespace hpray::gmsh
