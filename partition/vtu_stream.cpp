// StreamMesh: block-by-block decoding of appended raw / zlib VTU arrays (and .pvtu
// pieces) into a MeshSink; other inputs are read whole and replayed.
#include "vtu_stream.h"

#include <fcntl.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <memory>
#include <optional>
#include <set>
#include <sstream>
#include <type_traits>

#include "io/vtk_cells.h"
#include "io/vtk_xml_detail.h"
#include "util/check.h"
#include "util/error.h"
#include "util/log.h"

namespace hpray::partition {
namespace {

using vtkxml::ArrayDesc;
using vtkxml::Fail;
using vtkxml::ScalarType;
using vtkxml::XmlFile;

/// The XML part of a file we stream must fit in this many bytes (inline data does not).
constexpr std::size_t kMaxXmlBytes = std::size_t(64) << 20;
/// Largest zlib block we accept (VTK writes 32 KiB blocks by default).
constexpr std::uint64_t kMaxBlockBytes = std::uint64_t(64) << 20;
/// More nodes than any supported cell has (hex of order 10 has 1331).
constexpr std::int64_t kMaxCellNodes = 4096;

std::string At(const std::string& where, std::uint64_t offset) {
    std::ostringstream os;
    os << where << " at byte " << offset;
    return os.str();
}

/// An open file descriptor, closed on destruction.
class Fd {
  public:
    explicit Fd(const std::string& path)
        : fd_(::open(path.c_str(), O_RDONLY | O_CLOEXEC)) {
        if (fd_ < 0)
            throw InputError(path, "",
                             std::string("cannot open: ") + std::strerror(errno));
    }
    ~Fd() {
        if (fd_ >= 0) ::close(fd_);
    }
    Fd(const Fd&) = delete;
    Fd& operator=(const Fd&) = delete;
    int get() const { return fd_; }

  private:
    int fd_ = -1;
};

/// Reads exactly n bytes at `offset`; false at end of file.
bool PreadAll(int fd, void* dst, std::size_t n, std::uint64_t offset) {
    auto* p = static_cast<char*>(dst);
    while (n > 0) {
        const ssize_t got = ::pread(fd, p, n, static_cast<off_t>(offset));
        if (got < 0 && errno == EINTR) continue;
        if (got <= 0) return false;
        p += got;
        n -= static_cast<std::size_t>(got);
        offset += static_cast<std::uint64_t>(got);
    }
    return true;
}

/// A .vtu whose XML part is parsed and whose appended data stays on disk.
struct StreamFile {
    std::unique_ptr<XmlFile> xml;
    std::unique_ptr<Fd> fd;
    std::uint64_t size = 0;
};

/// Loads the XML part of `path` if its data is appended raw (possibly zlib); nullptr when
/// the file has to be read whole instead (inline data, base64 appended data).
std::unique_ptr<StreamFile> LoadStreamFile(const std::string& path) {
    auto sf = std::make_unique<StreamFile>();
    sf->fd = std::make_unique<Fd>(path);
    const off_t end = ::lseek(sf->fd->get(), 0, SEEK_END);
    if (end < 0) throw InputError(path, "", "cannot determine the file size");
    sf->size = static_cast<std::uint64_t>(end);

    // Read until the '_' marker of the appended data.
    std::string prefix;
    std::size_t marker = std::string::npos, searchFrom = 0;
    constexpr std::size_t kChunk = std::size_t(1) << 20;
    while (marker == std::string::npos) {
        if (prefix.size() >= kMaxXmlBytes || prefix.size() >= sf->size) return nullptr;
        const std::size_t n = static_cast<std::size_t>(
            std::min<std::uint64_t>(kChunk, sf->size - prefix.size()));
        const std::size_t old = prefix.size();
        prefix.resize(old + n);
        if (!PreadAll(sf->fd->get(), prefix.data() + old, n, old))
            throw InputError(path, "", "read error");
        const std::size_t tag = prefix.find("<AppendedData", searchFrom);
        if (tag == std::string::npos) {
            searchFrom = prefix.size() > 16 ? prefix.size() - 16 : 0;
            continue;
        }
        const std::size_t close = prefix.find('>', tag);
        if (close == std::string::npos) continue;
        const std::size_t m = prefix.find_first_not_of(" \t\r\n", close + 1);
        if (m == std::string::npos) continue;
        if (prefix[m] != '_')
            throw InputError(path, At("<AppendedData>", tag),
                             "the appended data does not start with the '_' marker");
        marker = m;
    }
    auto xml = std::make_unique<XmlFile>();
    XmlFile& f = *xml;
    f.path = path;
    f.xmlCopy.assign(prefix, 0, marker);
    f.xmlCopy += "</AppendedData></VTKFile>";
    vtkxml::ParseHeader(f, f.xmlCopy.data(), f.xmlCopy.size());
    const std::string encoding =
        f.root.child("AppendedData").attribute("encoding").value();
    if (encoding == "base64") return nullptr;
    if (!encoding.empty() && encoding != "raw")
        Fail(f, "<AppendedData>",
             "encoding '" + encoding + "' is neither raw nor base64");
    f.hasAppended = true;
    f.appendedBegin = marker + 1;
    f.appendedEnd = static_cast<std::size_t>(sf->size);
    sf->xml = std::move(xml);
    return sf;
}


/// A sequential reader of one appended array: decodes raw bytes or zlib blocks on demand,
/// holding one block (or one chunk of raw data) at a time.
class ArrayCursor {
  public:
    ArrayCursor(const StreamFile& sf, const ArrayDesc& a, std::size_t chunkBytes)
        : sf_(sf), a_(a), valueSize_(vtkxml::ScalarSize(a.type)) {
        const XmlFile& f = *sf.xml;
        if (a.format != ArrayDesc::Format::Appended)
            Fail(f, a.where, "is not appended data");  // filtered out before
        if (a.type == ScalarType::NonNumeric)
            Fail(f, a.where, "type '" + a.typeName + "' is not a numeric type");
        const std::uint64_t available = sf.size - f.appendedBegin;
        if (a.offset >= available)
            Fail(f, a.where,
                 "appended offset " + std::to_string(a.offset) +
                     " is beyond the end of the file");
        pos_ = f.appendedBegin + a.offset;
        headerSize_ = f.headerUInt64 ? 8 : 4;
        chunk_ =
            std::max<std::size_t>(chunkBytes / valueSize_ * valueSize_, 64 * valueSize_);
        std::uint64_t totalBytes = 0;
        if (!f.zlib) {
            totalBytes = Word("the size header");
            if (totalBytes > sf.size - pos_)
                Fail(f, At(a.where, pos_),
                     "declares " + std::to_string(totalBytes) +
                         " bytes but the file ends first (truncated?)");
            rawLeft_ = totalBytes;
        } else {
            const std::uint64_t headerAt = pos_;
            const std::uint64_t blocks = Word("the compression header");
            blockSize_ = Word("the compression header");
            lastSize_ = Word("the compression header");
            if (blocks > (sf.size - pos_) / headerSize_)
                Fail(f, At(a.where, headerAt),
                     "compression header declares " + std::to_string(blocks) +
                         " blocks, more than the file holds");
            if (lastSize_ > blockSize_ || (blocks > 0 && blockSize_ == 0) ||
                blockSize_ > kMaxBlockBytes)
                Fail(f, At(a.where, headerAt),
                     "compression header has block size " + std::to_string(blockSize_) +
                         " and last block size " + std::to_string(lastSize_));
            compressed_.resize(blocks);
            std::uint64_t compressedTotal = 0;
            for (auto& c : compressed_) {
                c = Word("the compression header");
                if (c > kMaxBlockBytes + kMaxBlockBytes / 8 + 1024)
                    Fail(f, At(a.where, headerAt), "a compressed block is too large");
                compressedTotal += c;
            }
            if (compressedTotal > sf.size - pos_)
                Fail(f, At(a.where, pos_),
                     "the compressed blocks need " + std::to_string(compressedTotal) +
                         " bytes but the file ends first (truncated?)");
            if (blocks > 0)
                totalBytes =
                    (blocks - 1) * blockSize_ + (lastSize_ ? lastSize_ : blockSize_);
        }
        const std::uint64_t tupleBytes =
            valueSize_ * static_cast<std::uint64_t>(a.components);
        if (totalBytes % tupleBytes != 0)
            Fail(f, a.where,
                 "holds " + std::to_string(totalBytes) +
                     " bytes, not a whole number of " + std::to_string(a.components) +
                     "-component " + a.typeName + " tuples");
        values_ = totalBytes / valueSize_;
    }

    /// Values in the array (tuples * components).
    std::uint64_t Values() const { return values_; }
    std::uint64_t Remaining() const { return values_ - consumed_; }
    const ArrayDesc& Desc() const { return a_; }

    /// Decodes the next n values into dst; an integer Dst requires an integer array.
    template <typename Dst>
    void Read(Dst* dst, std::size_t n) {
        const XmlFile& f = *sf_.xml;
        if (std::is_integral_v<Dst> && !vtkxml::IsIntegerType(a_.type))
            Fail(f, a_.where, "type " + a_.typeName + " is not an integer type");
        if (n > Remaining())
            Fail(f, a_.where,
                 "holds " + std::to_string(values_) + " values, fewer than the " +
                     std::to_string(consumed_ + n) + " needed");
        while (n > 0) {
            if (bufPos_ + valueSize_ > buf_.size()) Refill();
            const std::size_t have = (buf_.size() - bufPos_) / valueSize_;
            const std::size_t take = std::min(have, n);
            Convert(buf_.data() + bufPos_, take, dst);
            bufPos_ += take * valueSize_;
            dst += take;
            n -= take;
            consumed_ += take;
        }
    }

  private:
    std::uint64_t Word(const char* what) {
        std::uint8_t b[8];
        if (!PreadAll(sf_.fd->get(), b, headerSize_, pos_))
            Fail(*sf_.xml, At(a_.where, pos_),
                 std::string(what) + " is cut off (truncated?)");
        pos_ += headerSize_;
        if (headerSize_ == 8) {
            std::uint64_t v;
            std::memcpy(&v, b, 8);
            return sf_.xml->swapBytes ? vtkxml::ByteSwap(v) : v;
        }
        std::uint32_t v;
        std::memcpy(&v, b, 4);
        return sf_.xml->swapBytes ? vtkxml::ByteSwap(v) : v;
    }

    /// Keeps the partial value at the end of the buffer and appends the next chunk/block.
    void Refill() {
        const XmlFile& f = *sf_.xml;
        std::vector<std::uint8_t> keep(
            buf_.begin() + static_cast<std::ptrdiff_t>(bufPos_), buf_.end());
        if (!f.zlib) {
            const std::size_t n =
                static_cast<std::size_t>(std::min<std::uint64_t>(chunk_, rawLeft_));
            HPRAY_CHECK_GT(n, 0u);
            buf_.resize(keep.size() + n);
            std::copy(keep.begin(), keep.end(), buf_.begin());
            if (!PreadAll(sf_.fd->get(), buf_.data() + keep.size(), n, pos_))
                Fail(f, At(a_.where, pos_), "the data ends early (file truncated?)");
            pos_ += n;
            rawLeft_ -= n;
        } else {
            HPRAY_CHECK_LT(block_, compressed_.size());
            const std::uint64_t len =
                (block_ + 1 == compressed_.size() && lastSize_) ? lastSize_ : blockSize_;
            const std::uint64_t clen = compressed_[block_];
            if (len / 1032 > clen + 1)
                Fail(f, At(a_.where, pos_),
                     "block " + std::to_string(block_) + " claims " +
                         std::to_string(len) + " bytes from " + std::to_string(clen) +
                         " compressed bytes, more than zlib can produce");
            scratch_.resize(clen);
            if (!PreadAll(sf_.fd->get(), scratch_.data(), clen, pos_))
                Fail(f, At(a_.where, pos_), "a compressed block is cut off (truncated?)");
            buf_.resize(keep.size() + len);
            std::copy(keep.begin(), keep.end(), buf_.begin());
            uLongf produced = static_cast<uLongf>(len);
            const int rc = uncompress(buf_.data() + keep.size(), &produced,
                                      scratch_.data(), static_cast<uLong>(clen));
            if (rc != Z_OK || produced != len)
                Fail(f, At(a_.where, pos_),
                     "zlib block " + std::to_string(block_) + " of " +
                         std::to_string(compressed_.size()) +
                         (rc == Z_OK ? ": inflates to the wrong size"
                                     : ": corrupt compressed data"));
            pos_ += clen;
            ++block_;
        }
        bufPos_ = 0;
    }

    template <typename Dst>
    void Convert(const std::uint8_t* src, std::size_t n, Dst* dst) const {
        vtkxml::Convert(src, a_.type, n, sf_.xml->swapBytes, dst);
    }

    const StreamFile& sf_;
    ArrayDesc a_;
    std::uint64_t valueSize_ = 1;
    std::uint64_t headerSize_ = 4;
    std::uint64_t pos_ = 0;  ///< file offset of the next undecoded byte
    std::size_t chunk_ = 0;
    std::uint64_t rawLeft_ = 0;
    std::vector<std::uint64_t> compressed_;
    std::uint64_t blockSize_ = 0, lastSize_ = 0;
    std::size_t block_ = 0;
    std::vector<std::uint8_t> buf_, scratch_;
    std::size_t bufPos_ = 0;
    std::uint64_t values_ = 0, consumed_ = 0;
};

/// The arrays of one unstructured piece, selected by the read options.
struct PieceArrays {
    std::int64_t points = 0, cells = 0;
    std::optional<ArrayDesc> pointsArray, offsets, types, connectivity, ghost, degrees;
    std::vector<ArrayDesc> pointFields, cellFields;
    bool allAppended = true;
};

PieceArrays DescribePiece(const XmlFile& f, pugi::xml_node piece, int index,
                          const ReadOptions& options) {
    const std::string where = "<Piece> " + std::to_string(index);
    PieceArrays p;
    p.points = vtkxml::RequireCount(f, piece, "NumberOfPoints", where);
    p.cells = vtkxml::RequireCount(f, piece, "NumberOfCells", where);
    auto note = [&](const ArrayDesc& a) {
        p.allAppended &= a.format == ArrayDesc::Format::Appended;
    };
    if (pugi::xml_node n = piece.child("Points").child("DataArray")) {
        p.pointsArray = vtkxml::DescribeArray(f, n, where + " <Points>");
        if (p.pointsArray->components != 3)
            Fail(f, p.pointsArray->where, "points must have 3 components");
        note(*p.pointsArray);
    } else if (p.points > 0) {
        Fail(f, where, "has no <Points> <DataArray>");
    }
    for (pugi::xml_node n : piece.child("Cells").children("DataArray")) {
        ArrayDesc a = vtkxml::DescribeArray(f, n, where + " <Cells>");
        if (a.components != 1) Fail(f, a.where, "cell arrays must have 1 component");
        note(a);
        if (a.name == "offsets") p.offsets = a;
        if (a.name == "types") p.types = a;
        if (a.name == "connectivity") p.connectivity = a;
    }
    if (p.cells > 0)
        for (const auto& [arr, name] :
             {std::pair{&p.offsets, "offsets"}, std::pair{&p.types, "types"},
              std::pair{&p.connectivity, "connectivity"}})
            if (!*arr)
                Fail(f, where + " <Cells>",
                     std::string("has no DataArray named '") + name + "'");
    vtkxml::PieceArrays fields = vtkxml::CollectArrays(f, piece, where, options);
    p.pointFields = std::move(fields.pointFields);
    p.cellFields = std::move(fields.cellFields);
    p.ghost = std::move(fields.ghost);
    p.degrees = std::move(fields.degrees);
    if (p.ghost) note(*p.ghost);
    if (p.degrees) note(*p.degrees);
    for (const ArrayDesc& a : p.pointFields) note(a);
    for (const ArrayDesc& a : p.cellFields) note(a);
    return p;
}

/// Shared state of one StreamMesh call: global point numbering and the field layout.
struct StreamState {
    StreamState(MeshSink& s, const ReadOptions& o, std::size_t b)
        : sink(s), options(o), bufferBytes(b) {}
    MeshSink& sink;
    const ReadOptions& options;
    std::size_t bufferBytes = 0;
    bool fieldsSent = false;
    std::vector<StreamField> pointFields, cellFields;
    std::int64_t pointBase = 0;
    StreamStats stats;

    void SendFields(const std::vector<StreamField>& pf,
                    const std::vector<StreamField>& cf, const std::string& source) {
        auto same = [](const std::vector<StreamField>& a,
                       const std::vector<StreamField>& b) {
            if (a.size() != b.size()) return false;
            for (std::size_t i = 0; i < a.size(); ++i)
                if (a[i].name != b[i].name || a[i].components != b[i].components)
                    return false;
            return true;
        };
        if (!fieldsSent) {
            pointFields = pf;
            cellFields = cf;
            sink.Fields(pf, cf);
            fieldsSent = true;
        } else if (!same(pf, pointFields) || !same(cf, cellFields)) {
            throw InputError(source, "",
                             "has a different set of fields than the first piece");
        }
    }
};

int SumComponents(const std::vector<StreamField>& v) {
    int n = 0;
    for (const StreamField& f : v) n += f.components;
    return n;
}

/// Streams one piece of a serial .vtu.
void StreamPiece(const StreamFile& sf, const PieceArrays& p, int index, StreamState& st) {
    const XmlFile& f = *sf.xml;
    const std::string where = "<Piece> " + std::to_string(index);
    std::vector<StreamField> pf, cf;
    for (const ArrayDesc& a : p.pointFields) pf.push_back({a.name, a.components});
    for (const ArrayDesc& a : p.cellFields) cf.push_back({a.name, a.components});
    // Pieces of one file may list fields in any order: align them with the first piece.
    std::vector<const ArrayDesc*> pointOrder, cellOrder;
    if (!st.fieldsSent) {
        st.SendFields(pf, cf, f.path + " " + where);
        for (const ArrayDesc& a : p.pointFields) pointOrder.push_back(&a);
        for (const ArrayDesc& a : p.cellFields) cellOrder.push_back(&a);
    } else {
        auto align = [&](const std::vector<StreamField>& want,
                         const std::vector<ArrayDesc>& have,
                         std::vector<const ArrayDesc*>& order) {
            if (want.size() != have.size())
                Fail(f, where, "has a different set of fields than the first piece");
            for (const StreamField& w : want) {
                auto it = std::find_if(have.begin(), have.end(), [&](const ArrayDesc& a) {
                    return a.name == w.name;
                });
                if (it == have.end() || it->components != w.components)
                    Fail(f, where,
                         "field '" + w.name +
                             "' is missing or has a different number of components");
                order.push_back(&*it);
            }
        };
        align(st.pointFields, p.pointFields, pointOrder);
        align(st.cellFields, p.cellFields, cellOrder);
    }
    const std::size_t chunk = std::max<std::size_t>(st.bufferBytes, 4096);

    // Points and point fields, interleaved per point.
    if (p.points > 0) {
        ArrayCursor pts(sf, *p.pointsArray, chunk);
        if (pts.Values() != static_cast<std::uint64_t>(p.points) * 3)
            Fail(f, p.pointsArray->where,
                 "holds " + std::to_string(pts.Values() / 3) + " points, expected " +
                     std::to_string(p.points));
        std::vector<std::unique_ptr<ArrayCursor>> fields;
        for (const ArrayDesc* a : pointOrder) {
            fields.push_back(std::make_unique<ArrayCursor>(sf, *a, chunk));
            if (fields.back()->Values() !=
                static_cast<std::uint64_t>(p.points) * a->components)
                Fail(f, a->where,
                     "holds " + std::to_string(fields.back()->Values() / a->components) +
                         " tuples, expected " + std::to_string(p.points));
        }
        const int comps = SumComponents(st.pointFields);
        const std::int64_t batch = std::max<std::int64_t>(
            1, static_cast<std::int64_t>(chunk / (8 * (3 + comps))));
        std::vector<double> xyz, values, tmp;
        for (std::int64_t first = 0; first < p.points; first += batch) {
            const std::int64_t n = std::min(batch, p.points - first);
            xyz.resize(3 * n);
            pts.Read(xyz.data(), xyz.size());
            for (double v : xyz)
                if (!std::isfinite(v))
                    Fail(f, p.pointsArray->where, "holds a NaN or infinite coordinate");
            values.resize(static_cast<std::size_t>(n) * comps);
            int offset = 0;
            for (std::size_t k = 0; k < fields.size(); ++k) {
                const int nc = pointOrder[k]->components;
                tmp.resize(static_cast<std::size_t>(n) * nc);
                fields[k]->Read(tmp.data(), tmp.size());
                for (std::int64_t i = 0; i < n; ++i)
                    for (int c = 0; c < nc; ++c) {
                        const double v = tmp[i * nc + c];
                        if (!std::isfinite(v))
                            Fail(f, pointOrder[k]->where,
                                 "holds a NaN or infinite value");
                        values[i * comps + offset + c] = v;
                    }
                offset += nc;
            }
            st.sink.Points(n, xyz.data(), values.data());
        }
    }

    // Cells: offsets, types and connectivity in lockstep, plus degrees, ghosts, fields.
    if (p.cells > 0) {
        ArrayCursor offs(sf, *p.offsets, chunk), types(sf, *p.types, chunk),
            conn(sf, *p.connectivity, chunk);
        const auto nCells = static_cast<std::uint64_t>(p.cells);
        if (offs.Values() == nCells + 1) {
            std::int64_t zero = -1;
            offs.Read(&zero, 1);
            if (zero != 0)
                Fail(f, p.offsets->where,
                     "holds NumberOfCells + 1 values but does not start at 0");
        } else if (offs.Values() != nCells) {
            Fail(f, p.offsets->where,
                 "holds " + std::to_string(offs.Values()) +
                     " values, expected NumberOfCells = " + std::to_string(p.cells));
        }
        if (types.Values() != nCells)
            Fail(f, p.types->where,
                 "holds " + std::to_string(types.Values()) + " values, expected " +
                     std::to_string(p.cells));
        std::unique_ptr<ArrayCursor> degrees, ghost;
        if (p.degrees) {
            if (p.degrees->components != 3)
                Fail(f, p.degrees->where, "must have 3 components");
            degrees = std::make_unique<ArrayCursor>(sf, *p.degrees, chunk);
            if (degrees->Values() != nCells * 3)
                Fail(f, p.degrees->where, "does not hold 3 values per cell");
        }
        if (p.ghost) {
            if (p.ghost->components != 1)
                Fail(f, p.ghost->where, "must have 1 component");
            ghost = std::make_unique<ArrayCursor>(sf, *p.ghost, chunk);
            if (ghost->Values() != nCells)
                Fail(f, p.ghost->where, "does not hold 1 value per cell");
        }
        std::vector<std::unique_ptr<ArrayCursor>> fields;
        for (const ArrayDesc* a : cellOrder) {
            fields.push_back(std::make_unique<ArrayCursor>(sf, *a, chunk));
            if (fields.back()->Values() != nCells * a->components)
                Fail(f, a->where,
                     "holds " + std::to_string(fields.back()->Values() / a->components) +
                         " tuples, expected " + std::to_string(p.cells));
        }
        const int comps = SumComponents(st.cellFields);
        const bool legacyHex = VtkXmlHasLegacyLagrangeHex(f.versionMajor, f.versionMinor);
        std::vector<std::int64_t> fileNodes(kMaxCellNodes), nodes(kMaxCellNodes);
        std::vector<double> values(comps);
        struct Cached {
            std::int64_t type = -1, nodes = -1;
            int degree[3] = {-1, -1, -1};
            CellKind kind;
            const std::vector<int>* perm = nullptr;
            bool skip = false;
        } cached;
        std::int64_t previous = 0;
        // Offsets, types and ghost flags decoded for a batch of cells at a time (their
        // sizes are checked above, so a batch never reads past an array).
        constexpr std::int64_t kBatch = 4096;
        std::vector<std::int64_t> batchEnd(kBatch), batchType(kBatch), batchGhost(kBatch);
        std::int64_t batchFirst = 0, batchCount = 0;
        // The batch's connectivity is decoded in one read too when its offsets ascend, it
        // holds at most kBatchNodes values and the array has them all (otherwise cell by
        // cell, which reports a broken array at the cell that finds it): values from
        // batchNodeBase on.
        constexpr std::int64_t kBatchNodes = std::int64_t(1) << 17;
        std::vector<std::int64_t> batchNodes;
        bool nodesBatched = false;
        std::int64_t batchNodeBase = 0;
        for (std::int64_t c = 0; c < p.cells; ++c) {
            if (c == batchFirst + batchCount) {
                batchFirst = c;
                batchCount = std::min(kBatch, p.cells - c);
                const auto n = static_cast<std::size_t>(batchCount);
                offs.Read(batchEnd.data(), n);
                types.Read(batchType.data(), n);
                if (ghost) ghost->Read(batchGhost.data(), n);
                std::int64_t last = previous;
                bool ascending = true;
                for (std::size_t i = 0; i < n && ascending; ++i) {
                    ascending = batchEnd[i] >= last;
                    last = batchEnd[i];
                }
                const std::int64_t values = last - previous;
                nodesBatched = ascending && values <= kBatchNodes &&
                               static_cast<std::uint64_t>(values) <= conn.Remaining();
                if (nodesBatched) {
                    batchNodes.resize(static_cast<std::size_t>(values));
                    conn.Read(batchNodes.data(), batchNodes.size());
                    batchNodeBase = previous;
                }
            }
            const std::int64_t end = batchEnd[c - batchFirst];
            const std::int64_t type = batchType[c - batchFirst];
            const std::int64_t count = end - previous;
            if (count < 0)
                Fail(f, p.offsets->where,
                     "offset of cell " + std::to_string(c) + " (" + std::to_string(end) +
                         ") is smaller than the previous one (" +
                         std::to_string(previous) + ")");
            previous = end;
            int degree[3] = {-1, -1, -1};
            if (degrees) {
                double d[3];
                degrees->Read(d, 3);
                for (int k = 0; k < 3; ++k) {
                    if (!(d[k] >= 0 && d[k] <= 1000) || d[k] != std::floor(d[k]))
                        Fail(f, p.degrees->where,
                             "value of cell " + std::to_string(c) +
                                 " is not a valid degree");
                    degree[k] = static_cast<int>(d[k]);
                }
            }
            const std::int64_t g = ghost ? batchGhost[c - batchFirst] : 0;
            // Cell field values: read every field (consumed even for skipped cells).
            {
                int offset = 0;
                for (std::size_t k = 0; k < fields.size(); ++k) {
                    const int nc = cellOrder[k]->components;
                    fields[k]->Read(values.data() + offset, nc);
                    for (int i = 0; i < nc; ++i)
                        if (!std::isfinite(values[offset + i]))
                            Fail(f, cellOrder[k]->where,
                                 "value of cell " + std::to_string(c) +
                                     " is NaN or infinite");
                    offset += nc;
                }
            }
            if (type != cached.type || count != cached.nodes ||
                !std::equal(degree, degree + 3, cached.degree)) {
                std::string why;
                cached.skip = false;
                const bool lower =
                    type == 0 || (type >= 1 && type <= 9) || (type >= 21 && type <= 23) ||
                    type == 28 || type == 30 || (type >= 34 && type <= 36) ||
                    (type >= 51 && type <= 54) || (type >= 60 && type <= 63) ||
                    (type >= 68 && type <= 70) || (type >= 75 && type <= 77);
                std::optional<CellKind> kind;
                if (!lower && type > 0 && type < 256)
                    kind = ClassifyVtkCell(static_cast<int>(type), count,
                                           degrees ? degree : nullptr, &why);
                if (lower) {
                    cached.skip = true;
                } else if (kind) {
                    cached.kind = *kind;
                    cached.perm =
                        &VtkToInternal(static_cast<int>(type), *kind, legacyHex);
                } else if (type == kVtkVoxel &&
                           count == 8) {  // voxel: internal linear hex order
                    static const std::vector<int> kVoxel{0, 1, 2, 3, 4, 5, 6, 7};
                    cached.kind = CellKind{CellShape::Hex, 1, CellFamily::Lagrange};
                    cached.perm = &kVoxel;
                } else {
                    std::ostringstream os;
                    os << "cell " << c << " (VTK cell type " << type << ", " << count
                       << " nodes): " << (why.empty() ? "not a supported 3-D cell" : why);
                    Fail(f, where, os.str());
                }
                cached.type = type;
                cached.nodes = count;
                std::copy(degree, degree + 3, cached.degree);
            }
            if (cached.skip) {
                // Consume the connectivity of a lower-dimensional cell.
                std::int64_t left = nodesBatched ? 0 : count;
                while (left > 0) {
                    const std::int64_t n = std::min<std::int64_t>(left, kMaxCellNodes);
                    conn.Read(fileNodes.data(), static_cast<std::size_t>(n));
                    left -= n;
                }
                ++st.stats.skippedCells;
                continue;
            }
            const std::int64_t* cellNodes = fileNodes.data();
            if (nodesBatched) {
                cellNodes = batchNodes.data() + (end - count - batchNodeBase);
            } else {
                conn.Read(fileNodes.data(), static_cast<std::size_t>(count));
            }
            if (g & 1) {  // a duplicate cell of an earlier decomposition
                ++st.stats.skippedCells;
                continue;
            }
            const std::vector<int>& perm = *cached.perm;
            for (std::int64_t k = 0; k < count; ++k) {
                const std::int64_t pt = cellNodes[perm[k]];
                if (pt < 0 || pt >= p.points)
                    Fail(f, p.connectivity->where,
                         "cell " + std::to_string(c) + " refers to point " +
                             std::to_string(pt) + ", outside [0, " +
                             std::to_string(p.points) + ")");
                nodes[k] = pt + st.pointBase;
            }
            st.sink.Cell(cached.kind.shape, cached.kind.order, cached.kind.family,
                         nodes.data(), static_cast<int>(count), values.data(),
                         static_cast<std::uint8_t>(cached.type));  // classified: < 256
            ++st.stats.cells;
        }
        if (conn.Remaining() != 0)
            Fail(f, p.connectivity->where,
                 "holds " + std::to_string(conn.Values()) +
                     " values, the offsets end at " + std::to_string(previous));
    }
    st.pointBase += p.points;
    st.stats.points += p.points;
}

/// Replays an in-memory mesh into the sink (formats that are not streamed).
void ReplayMesh(const Mesh& mesh, StreamState& st, const std::string& source) {
    // Readers that do not select fields (builtins) still must not ignore a bad name, and
    // must not pass on fields nobody asked for.
    std::set<const Field*> wanted;
    if (st.options.fields)
        for (const std::string& name : *st.options.fields) {
            const std::optional<ScalarSelector> sel = SelectScalar(mesh, name);
            if (!sel) {
                std::string list;
                for (const Field& f : mesh.pointFields)
                    list += (list.empty() ? "" : ", ") + f.name;
                for (const Field& f : mesh.cellFields)
                    list += (list.empty() ? "" : ", ") + f.name;
                throw InputError(source, "",
                                 "field '" + name + "' does not exist; available: " +
                                     (list.empty() ? std::string("(none)") : list));
            }
            wanted.insert(sel->field);
        }
    auto keep = [&](const Field& f) {
        return !st.options.fields || wanted.count(&f) > 0;
    };
    std::vector<StreamField> pf, cf;
    for (const Field& fld : mesh.pointFields)
        if (keep(fld)) pf.push_back({fld.name, fld.components});
    for (const Field& fld : mesh.cellFields)
        if (keep(fld)) cf.push_back({fld.name, fld.components});
    st.SendFields(pf, cf, source);
    // Align with the layout announced by the first piece.
    std::vector<const Field*> pointOrder, cellOrder;
    for (const StreamField& w : st.pointFields)
        pointOrder.push_back(mesh.FindPointField(w.name));
    for (const StreamField& w : st.cellFields)
        cellOrder.push_back(mesh.FindCellField(w.name));
    const int pc = SumComponents(st.pointFields), cc = SumComponents(st.cellFields);
    const std::int64_t batch = 65536;
    std::vector<double> values;
    for (std::int64_t first = 0; first < mesh.PointCount(); first += batch) {
        const std::int64_t n = std::min(batch, mesh.PointCount() - first);
        values.assign(static_cast<std::size_t>(n) * pc, 0.0);
        int offset = 0;
        for (const Field* fld : pointOrder) {
            for (std::int64_t i = 0; i < n; ++i)
                for (int c = 0; c < fld->components; ++c)
                    values[i * pc + offset + c] =
                        fld->values[(first + i) * fld->components + c];
            offset += fld->components;
        }
        st.sink.Points(n, mesh.points.data() + 3 * first, values.data());
    }
    std::vector<std::int64_t> nodes;
    std::vector<double> cellValues(cc);
    for (std::int64_t c = 0; c < mesh.CellCount(); ++c) {
        if (!mesh.ghost.empty() && (mesh.ghost[c] & 1)) {
            ++st.stats.skippedCells;
            continue;
        }
        int offset = 0;
        for (const Field* fld : cellOrder) {
            for (int k = 0; k < fld->components; ++k)
                cellValues[offset + k] = fld->values[c * fld->components + k];
            offset += fld->components;
        }
        const int count = mesh.CellNodeCount(c);
        nodes.assign(mesh.CellNodes(c), mesh.CellNodes(c) + count);
        for (auto& n : nodes) n += st.pointBase;
        st.sink.Cell(mesh.cellShape[c], mesh.cellOrder[c], mesh.cellFamily[c],
                     nodes.data(), count, cellValues.data(),
                     mesh.vtkType.empty() ? 0 : mesh.vtkType[c]);
        ++st.stats.cells;
    }
    st.pointBase += mesh.PointCount();
    st.stats.points += mesh.PointCount();
    st.stats.wholeMeshBytes = std::max(st.stats.wholeMeshBytes, mesh.MemoryBytes());
}

/// Streams one serial .vtu (or replays it when it cannot be streamed).
void StreamSerial(const std::string& path, StreamState& st) {
    std::unique_ptr<StreamFile> sf = LoadStreamFile(path);
    std::vector<PieceArrays> pieces;
    if (sf) {
        const XmlFile& f = *sf->xml;
        if (f.type != "UnstructuredGrid") {
            sf.reset();
        } else {
            const pugi::xml_node grid = f.root.child("UnstructuredGrid");
            if (!grid) Fail(f, "<VTKFile>", "has no <UnstructuredGrid> element");
            int index = 0;
            for (pugi::xml_node piece : grid.children("Piece"))
                pieces.push_back(DescribePiece(f, piece, index++, st.options));
            if (pieces.empty()) Fail(f, "<UnstructuredGrid>", "has no <Piece>");
            for (const PieceArrays& p : pieces)
                if (!p.allAppended) sf.reset();
        }
    }
    if (!sf) {
        log::Info(path + ": not appended raw data, reading it whole");
        ReplayMesh(ReadMesh(path, st.options), st, path);
        return;
    }
    st.stats.streamed = true;
    for (std::size_t i = 0; i < pieces.size(); ++i)
        StreamPiece(*sf, pieces[i], static_cast<int>(i), st);
}

bool EndsWith(const std::string& s, const std::string& suffix) {
    return s.size() >= suffix.size() &&
           std::equal(suffix.rbegin(), suffix.rend(), s.rbegin(),
                      [](char a, char b) { return std::tolower(a) == b; });
}

}  // namespace

StreamStats StreamMesh(const std::string& path, const ReadOptions& options,
                       std::size_t bufferBytes, MeshSink& sink) {
    StreamState st(sink, options, bufferBytes);
    if (EndsWith(path, ".vtu")) {
        StreamSerial(path, st);
    } else if (EndsWith(path, ".pvtu")) {
        // The index is small: parse it whole, then stream each piece in turn.
        const std::unique_ptr<XmlFile> index = vtkxml::LoadXmlFile(path);
        if (index->type != "PUnstructuredGrid")
            Fail(*index, "<VTKFile>",
                 "type '" + index->type + "' is not PUnstructuredGrid");
        const pugi::xml_node grid = index->root.child("PUnstructuredGrid");
        if (!grid) Fail(*index, "<VTKFile>", "has no <PUnstructuredGrid> element");
        const std::filesystem::path folder = std::filesystem::path(path).parent_path();
        int i = 0;
        bool allStreamed = true;
        for (pugi::xml_node piece : grid.children("Piece")) {
            const std::string where = "<Piece> " + std::to_string(i++);
            const std::string source = piece.attribute("Source").value();
            if (source.empty()) Fail(*index, where, "has no Source attribute");
            const std::string piecePath = (folder / source).lexically_normal().string();
            std::error_code ec;
            if (!std::filesystem::is_regular_file(piecePath, ec))
                Fail(*index, where + " Source=\"" + source + "\"",
                     "no such file: " + piecePath);
            st.stats.streamed = false;
            StreamSerial(piecePath, st);
            allStreamed &= st.stats.streamed;
        }
        if (i == 0) Fail(*index, "<PUnstructuredGrid>", "has no <Piece>");
        st.stats.streamed = allStreamed;
    } else {
        const Mesh mesh = ReadMesh(path, options);
        ReplayMesh(mesh, st, path);
    }
    if (!st.fieldsSent) sink.Fields({}, {});
    return st.stats;
}

}  // namespace hpray::partition
