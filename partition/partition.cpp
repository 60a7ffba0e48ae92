// PartitionMesh: stream the input into spill files, build the k-d tree over cost-weighted
// centroids, distribute cells (with ghost copies) to bricks, write pieces, index and
// manifest atomically.
//
// Memory: with B = the memory limit, the point cache of the scan holds B/4 and its batch
// of cells about B/64 (nodes and their coordinates); the point cache of the distribution,
// which recomputes order-1 cells' boxes, another B/4 after it; stream
// buffers and spill buffers a few MiB (the distribution's brick spill buffers B/8, twice:
// spill writers fill one buffer while a background thread writes the other), the tree
// builder collects at most B/4 of centroids per level (a coordinate, the cost and the
// other two coordinates of each, the latter for a tie-break without another pass) and
// keeps the bounding boxes of blocks of centroids in B/32 (from the scan on, so that its
// passes skip blocks), and one brick is assembled while the one before it is written,
// when both fit (the meshes' arrays are reused); a brick that would need more than B is
// an input error (ask for more bricks). A gmsh input's tag -> index maps take at most B/8
// each (gmsh_stream.h), in the scan only. Everything else lives in DIR/.spill-PID-N/
// (removed at the end, and by the next run if this one dies).
#include "partition.h"

#include <fcntl.h>
#include <sys/file.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <future>
#include <limits>
#include <map>
#include <sstream>

#include "cost_model.h"
#include "elements/basis.h"
#include "elements/bounds.h"
#include "gmsh_stream.h"
#include "io/output_file.h"
#include "io/vtk_cells.h"
#include "io/vtu_writer.h"
#include "kd_tree.h"
#include "renumber.h"
#include "spill.h"
#include "util/check.h"
#include "util/error.h"
#include "util/log.h"
#include "vtu_stream.h"

namespace hpray::partition {
namespace fs = std::filesystem;
namespace {

constexpr const char* kManifest = "manifest.json";
constexpr const char* kIndex = "bricks.pvtu";
constexpr const char* kLock = ".hpray-partition.lock";
/// Test-only: the process _exits after writing this many bricks (simulates a crash).
constexpr const char* kTestExitEnv = "HPRAY_PARTITION_TEST_EXIT_AFTER_BRICKS";
/// Test-only: spill every cell's node ids as int64 (as for ids beyond int32).
constexpr const char* kTestWideIdsEnv = "HPRAY_PARTITION_TEST_WIDE_IDS";
/// Bricks distributed per pass over the cell spill (bounds open files).
constexpr int kBricksPerPass = 256;

/// Fixed part of a cell in the scan's cell spill (stored as its KindCodes byte);
/// followed by the cell's guaranteed
/// geometry box (6 doubles: lo, then hi) when `boxStored`, then nodeCount global point
/// indices (int32 when every one fits, int64 when `wide`) and the cell field values
/// (doubles). Only curved cells (order > 1 or not Lagrange) store their box, whose
/// Bernstein hull is costly; the box of an order-1 Lagrange cell is the bounds of its
/// nodes, which the distribution recomputes from the point spill (CellNodeBox) rather
/// than reading 48 bytes per cell back from disk. The centroid and cost parts of the
/// cell are in the centroid spill, at the same position. `vtkType` is the VTK type the
/// input cell was read as (0 = unknown), for the brick writer to keep. The node count
/// fits 16 bits (at most (kMaxOrder + 1)^3 nodes).
struct CellRecord {
    std::uint8_t shape = 0, order = 1, family = 0, vtkType = 0, boxStored = 0, wide = 0;
    std::uint16_t nodeCount = 0;
    std::size_t NodeBytes() const { return (wide ? 8u : 4u) * std::size_t(nodeCount); }
};
static_assert(sizeof(CellRecord) == 8, "spill record layout");
static_assert((kMaxOrder + 1) * (kMaxOrder + 1) * (kMaxOrder + 1) <= 0xffff,
              "CellRecord::nodeCount holds the node count of any cell");

/// Whether the spilled box of a cell must be stored (see CellRecord).
bool StoresBox(int order, CellFamily family) {
    return order > 1 || family != CellFamily::Lagrange;
}

/// Fixed part of a cell in a brick spill (stored as its KindCodes byte): what the brick
/// writer needs besides the nodes and field values that follow it as in CellRecord.
struct BrickCellRecord {
    std::uint8_t shape = 0, order = 1, family = 0, vtkType = 0, ghost = 0, wide = 0;
    std::uint16_t nodeCount = 0;
    std::size_t NodeBytes() const { return (wide ? 8u : 4u) * std::size_t(nodeCount); }
};
static_assert(sizeof(BrickCellRecord) == 8, "spill record layout");

/// Test-only: the most distinct kinds a KindCodes table holds (else 255), so that
/// escaped records are written and read.
constexpr const char* kTestKindCodesEnv = "HPRAY_PARTITION_TEST_KIND_CODES";

/// The 8-byte fixed parts of cells (CellRecord, BrickCellRecord) spilled as one byte per
/// cell: the code of the record in a table of the distinct records met so far (a mesh has
/// a few cell kinds), or kEscape followed by the record itself once the table is full.
/// One table serves every spill of the record type; it is filled while writing and only
/// read afterwards.
template <class Record>
class KindCodes {
  public:
    static_assert(sizeof(Record) == 8, "spill record layout");
    static constexpr std::uint8_t kEscape = 255;

    KindCodes() {
        if (const char* env = std::getenv(kTestKindCodesEnv))
            capacity_ =
                std::clamp<std::size_t>(std::strtoul(env, nullptr, 10), 0, kEscape);
    }

    void Write(SpillWriter& w, const Record& r) {
        std::uint8_t item[kMaxBytes];
        w.Write(item, Encode(r, item));
    }
    /// The most bytes a record takes in a spill.
    static constexpr std::size_t kMaxBytes = 1 + sizeof(Record);
    /// Stores the spilled form of `r` at `out` (kMaxBytes of room); returns its size.
    std::size_t Encode(const Record& r, std::uint8_t* out) {
        out[0] = Code(r);
        if (out[0] != kEscape) return 1;
        std::memcpy(out + 1, &r, sizeof r);
        return 1 + sizeof r;
    }
    /// The next record; false at a clean end of the spill.
    bool Read(SpillReader& in, Record& r) const {
        const char* p = in.Take(1);
        if (!p) return false;
        const auto code = static_cast<std::uint8_t>(*p);
        if (code == kEscape) {
            if (!in.Read(&r, sizeof r)) throw InternalError("spill ends inside a record");
            return true;
        }
        if (code >= kinds_.size())
            throw InternalError("spill holds an unknown cell kind");
        r = kinds_[code];
        return true;
    }

  private:
    static bool Same(const Record& a, const Record& b) {
        return std::memcmp(&a, &b, sizeof a) == 0;
    }
    std::uint8_t Code(const Record& r) {
        if (last_ < kinds_.size() && Same(kinds_[last_], r))
            return static_cast<std::uint8_t>(last_);
        for (std::size_t i = 0; i < kinds_.size(); ++i)
            if (Same(kinds_[i], r)) {
                last_ = i;
                return static_cast<std::uint8_t>(i);
            }
        if (kinds_.size() >= capacity_) return kEscape;
        kinds_.push_back(r);
        last_ = kinds_.size() - 1;
        return static_cast<std::uint8_t>(last_);
    }
    std::vector<Record> kinds_;
    std::size_t last_ = 0;
    std::size_t capacity_ = kEscape;
};

/// A centroid and the per-segment part of its cost (perSegment * area), as spilled
/// before the root box is known. The setup part takes one of a few values (one per cell
/// class of the cost model), so it is not stored per cell: the scan writes runs of equal
/// setup costs (SetupRun) to a stream of its own, and keeps the distinct values in
/// memory.
struct CentroidRecord {
    double x[3];
    double segmentArea;
};
static_assert(sizeof(CentroidRecord) == 32, "spill record layout");

/// `count` consecutive cells whose setup cost is the distinct value number `value`.
struct SetupRun {
    std::uint32_t count = 0;
    std::uint32_t value = 0;
};
static_assert(sizeof(SetupRun) == 8, "spill record layout");

/// The setup costs of the cells in order, from the run stream of the scan.
class SetupCosts {
  public:
    SetupCosts(const std::string& path, const std::vector<double>& values)
        : runs_(path, std::size_t(64) << 10), values_(values) {}
    /// The setup costs of the next `n` cells into out[0..n).
    void Next(double* out, std::size_t n) {
        while (n > 0) {
            if (left_ == 0) {
                SetupRun run;
                if (!runs_.Read(&run, sizeof run) || run.count == 0 ||
                    run.value >= values_.size())
                    throw InternalError("setup cost spill ends early or is corrupt");
                left_ = run.count;
                value_ = values_[run.value];
            }
            const std::size_t k = std::min<std::size_t>(n, left_);
            std::fill(out, out + k, value_);
            out += k;
            n -= k;
            left_ -= static_cast<std::uint32_t>(k);
        }
    }
    double Next() {
        if (left_ > 0) {
            --left_;
            return value_;
        }
        double v;
        Next(&v, 1);
        return v;
    }
    /// Passes over the setup costs of the next `n` cells.
    void Skip(std::int64_t n) {
        while (n > 0) {
            if (left_ == 0) {
                double v;
                Next(&v, 1);
                --n;
                continue;
            }
            const std::uint32_t k =
                static_cast<std::uint32_t>(std::min<std::int64_t>(n, left_));
            left_ -= k;
            n -= k;
        }
    }

  private:
    SpillReader runs_;
    const std::vector<double>& values_;
    std::uint32_t left_ = 0;
    double value_ = 0;
};

double Diagonal(const Box& b) {
    return std::hypot(b.hi[0] - b.lo[0], b.hi[1] - b.lo[1], b.hi[2] - b.lo[2]);
}

std::string BrickName(int b) {
    char name[32];
    std::snprintf(name, sizeof name, "brick-%04d.vtu", b);
    return name;
}

/// An exclusive advisory lock on DIR/.hpray-partition.lock, released on destruction (and
/// by the kernel if the process dies).
class DirLock {
  public:
    explicit DirLock(const std::string& dir) {
        const std::string path = (fs::path(dir) / kLock).string();
        path_ = path;
        fd_ = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
        if (fd_ < 0)
            throw InputError(
                path, "",
                std::string("cannot create the lock file: ") + std::strerror(errno));
        if (::flock(fd_, LOCK_EX | LOCK_NB) != 0) {
            ::close(fd_);
            throw InputError(dir, "", "another 'hpray partition' is writing this folder");
        }
    }
    ~DirLock() {
        // No lock file is left behind: unlinked while still held, so a run that opened
        // it meanwhile still finds it locked, and a later run creates a new one.
        std::error_code ec;
        fs::remove(path_, ec);
        if (fd_ >= 0) ::close(fd_);
    }
    DirLock(const DirLock&) = delete;
    DirLock& operator=(const DirLock&) = delete;

  private:
    int fd_ = -1;
    std::string path_;
};

/// Removes a folder tree on destruction unless released.
class ScopedDir {
  public:
    explicit ScopedDir(std::string path) : path_(std::move(path)) {}
    ~ScopedDir() {
        std::error_code ec;
        if (!path_.empty()) fs::remove_all(path_, ec);
    }
    ScopedDir(const ScopedDir&) = delete;
    ScopedDir& operator=(const ScopedDir&) = delete;
    const std::string& Path() const { return path_; }

  private:
    std::string path_;
};

bool IsOurOutput(const std::string& name) {
    auto starts = [&](const char* p) { return name.rfind(p, 0) == 0; };
    auto ends = [&](const char* s) {
        const std::size_t n = std::strlen(s);
        return name.size() >= n && name.compare(name.size() - n, n, s) == 0;
    };
    return (starts("brick-") && (ends(".vtu") || ends(".vtu.tmp"))) || name == kIndex ||
           name == std::string(kIndex) + ".tmp" || name == kManifest ||
           name == std::string(kManifest) + ".tmp";
}

/// Removes what earlier runs left: the manifest first (so no reader trusts the rest),
/// then bricks, index, temporaries and spill folders.
void RemovePreviousRun(const std::string& dir, const std::string& keepSpill) {
    std::error_code ec;
    fs::remove(fs::path(dir) / kManifest, ec);
    for (const auto& entry : fs::directory_iterator(dir, ec)) {
        const std::string name = entry.path().filename().string();
        if (IsOurOutput(name)) {
            fs::remove(entry.path(), ec);
        } else if (name.rfind(".spill-", 0) == 0 && entry.path().string() != keepSpill) {
            fs::remove_all(entry.path(), ec);
        }
    }
}

/// Scan: spills points (xyz + point fields) and cells (record + nodes + cell fields),
/// and the centroid/cost stream for the tree builder.
class ScanSink : public MeshSink {
  public:
    ScanSink(const std::string& spill, std::size_t memoryLimit)
        : centroidBlocks(memoryLimit / 32), spill_(spill), memoryLimit_(memoryLimit) {
        const char* wide = std::getenv(kTestWideIdsEnv);
        allWide_ = wide && std::string(wide) == "1";
    }

    void Fields(const std::vector<StreamField>& pf,
                const std::vector<StreamField>& cf) override {
        pointFields = pf;
        cellFields = cf;
        pointStride = 3;
        for (const StreamField& f : pf) pointStride += f.components;
        cellValues = 0;
        for (const StreamField& f : cf) cellValues += f.components;
        const std::size_t buf = std::size_t(1) << 20;
        points_ = std::make_unique<SpillWriter>(PointsPath(), buf);
        cells_ = std::make_unique<SpillWriter>(CellsPath(), buf);
        centroids_ = std::make_unique<SpillWriter>(CentroidsPath(), buf);
        setupRuns_ = std::make_unique<SpillWriter>(SetupsPath(), std::size_t(64) << 10);
        cache_ =
            std::make_unique<RecordCache>(PointsPath(), pointStride, memoryLimit_ / 4);
        batchNodeLimit_ = std::clamp<std::size_t>(
            memoryLimit_ / 64 / (4 * sizeof(double)), 4096, std::size_t(1) << 17);
        batchNodes_.resize(batchNodeLimit_ + kMaxNodes);
        batchXyz_.resize(3 * (batchNodeLimit_ + kMaxNodes));
        pending_.resize(kBatchCells);
        for (int d = 0; d < 3; ++d) {
            root.lo[d] = std::numeric_limits<double>::infinity();
            root.hi[d] = -std::numeric_limits<double>::infinity();
        }
    }

    void Points(std::int64_t count, const double* xyz, const double* values) override {
        const int comps = pointStride - 3;
        std::vector<double> record(pointStride);
        for (std::int64_t i = 0; i < count; ++i) {
            std::copy(xyz + 3 * i, xyz + 3 * i + 3, record.begin());
            std::copy(values + i * comps, values + (i + 1) * comps, record.begin() + 3);
            points_->Write(record.data(), record.size() * sizeof(double));
        }
        points_->Flush();
        cache_->Invalidate();
        points += count;
    }

    /// Gathers the cell's node coordinates (the point cache is sequential) and queues it;
    /// a full batch is processed by FlushBatch.
    void Cell(CellShape shape, int order, CellFamily family, const std::int64_t* nodes,
              int nodeCount, const double* values, std::uint8_t vtkType) override {
        HPRAY_CHECK(nodeCount > 0 && nodeCount <= kMaxNodes);
        Pending& c = pending_[pendingCount_++];  // every field set here or in FlushBatch
        c.r.shape = static_cast<std::uint8_t>(shape);
        c.r.order = static_cast<std::uint8_t>(order);
        c.r.family = static_cast<std::uint8_t>(family);
        c.r.vtkType = vtkType;
        c.r.nodeCount = static_cast<std::uint16_t>(nodeCount);
        c.r.wide = allWide_ ? 1 : 0;
        c.r.boxStored = StoresBox(order, family) ? 1 : 0;
        c.first = batchNodeCount_;
        c.firstValue = batchValues_.size();
        // The batch arrays have room for one more cell than the batch limit.
        std::int64_t* batchNodes = batchNodes_.data() + batchNodeCount_;
        double* xyz = batchXyz_.data() + 3 * batchNodeCount_;
        for (int k = 0; k < nodeCount; ++k) {
            const std::int64_t id = nodes[k];
            HPRAY_CHECK_LT(id, points);
            if (id > std::numeric_limits<std::int32_t>::max()) c.r.wide = 1;
            const double* p = cache_->Get(id);
            xyz[3 * k] = p[0];
            xyz[3 * k + 1] = p[1];
            xyz[3 * k + 2] = p[2];
            batchNodes[k] = id;
        }
        batchNodeCount_ += static_cast<std::size_t>(nodeCount);
        if (cellValues > 0)
            batchValues_.insert(batchValues_.end(), values, values + cellValues);
        // Every brick carries HigherOrderDegrees when any cell is written as a Lagrange
        // type, so the pieces agree with the arrays bricks.pvtu declares.
        if (shape != lastShape_ || order != lastOrder_ || family != lastFamily_ ||
            vtkType != lastVtkType_) {
            higherOrderDegrees |= VtkTypeNeedsDegrees(
                VtkTypeToWrite(CellKind{shape, order, family}, vtkType));
            lastShape_ = shape;
            lastOrder_ = order;
            lastFamily_ = family;
            lastVtkType_ = vtkType;
        }
        ++cells;
        if (batchNodeCount_ >= batchNodeLimit_ || pendingCount_ >= kBatchCells)
            FlushBatch();
    }

    void Close() {
        FlushBatch();
        if (points_) points_->Close();
        if (cells_) cells_->Close();
        if (centroids_) centroids_->Close();
        if (setupRuns_) {
            if (run_.count > 0) setupRuns_->Write(&run_, sizeof run_);
            run_ = SetupRun{};
            setupRuns_->Close();
        }
        cache_.reset();
    }

    std::string PointsPath() const { return spill_ + "/points.bin"; }
    std::string CellsPath() const { return spill_ + "/cells.bin"; }
    std::string CentroidsPath() const { return spill_ + "/centroids.bin"; }
    std::string SetupsPath() const { return spill_ + "/setups.bin"; }

    std::vector<StreamField> pointFields, cellFields;
    int pointStride = 3;
    int cellValues = 0;
    std::int64_t points = 0, cells = 0;
    Box root;
    bool higherOrderDegrees = false;  ///< some cell is written as VTK 71-74
    /// The codes of the cell records in the cell spill.
    KindCodes<CellRecord> cellKinds;
    /// The distinct setup costs of the cells (SetupRun::value indexes them); at most one
    /// per cell class of the cost model.
    std::vector<double> setupValues;
    /// Bounding boxes of blocks of the centroid spill, for passes that skip blocks.
    CentroidBlocks centroidBlocks;

  private:
    /// A queued cell: its record, where its nodes (and their coordinates, 3 per node) and
    /// field values are in the batch, and what FlushBatch computes from them.
    struct Pending {
        CellRecord r;
        std::size_t first = 0, firstValue = 0;
        double lo[3], hi[3], centroid[3];
        CellCostInput cost;
    };
    static constexpr std::size_t kBatchCells = 16384;
    /// The most nodes of a cell.
    static constexpr int kMaxNodes = (kMaxOrder + 1) * (kMaxOrder + 1) * (kMaxOrder + 1);

    /// A cell's node bounds and centroid (the nodes' mean, clamped into their bounds)
    /// from its nodeCount nodes; with N > 0 the count is N, known at compile time
    /// (order-1 tets, the most common cells of large meshes: the loops unroll), the same
    /// operations in the same order.
    template <int N = 0>
    static void NodeBounds(Pending& c, const double* xyz, int nodeCount) {
        const int n = N > 0 ? N : nodeCount;
        double sum[3] = {0, 0, 0};
        for (int d = 0; d < 3; ++d) {
            c.lo[d] = std::numeric_limits<double>::infinity();
            c.hi[d] = -c.lo[d];
        }
        for (int k = 0; k < n; ++k)
            for (int d = 0; d < 3; ++d) {
                const double v = xyz[3 * k + d];
                sum[d] += v;
                c.lo[d] = std::min(c.lo[d], v);
                c.hi[d] = std::max(c.hi[d], v);
            }
        for (int d = 0; d < 3; ++d)
            c.centroid[d] = std::clamp(sum[d] / n, c.lo[d], c.hi[d]);
    }

    /// The cells' geometry (node bounds, centroid, the Bernstein hull of curved cells)
    /// and cost parts, in parallel (each cell on its own, so the same doubles as one at a
    /// time); then the records, in input order.
    void FlushBatch() {
        if (pendingCount_ == 0) return;
        tbb::parallel_for(
            tbb::blocked_range<std::size_t>(0, pendingCount_, 1024),
            [&](const tbb::blocked_range<std::size_t>& range) {
                // Order-1 tets get their costs a group at a time.
                constexpr std::size_t kTets = 256;
                const double* tetXyz[kTets] = {};
                Pending* tets[kTets];
                CellCostInput tetCosts[kTets];
                std::size_t nTets = 0;
                auto costTets = [&] {
                    LinearTetCosts(tetXyz, nTets, tetCosts);
                    for (std::size_t k = 0; k < nTets; ++k) tets[k]->cost = tetCosts[k];
                    nTets = 0;
                };
                for (std::size_t i = range.begin(); i < range.end(); ++i) {
                    Pending& c = pending_[i];
                    const int nodeCount = c.r.nodeCount;
                    const double* xyz = batchXyz_.data() + 3 * c.first;
                    const auto shape = static_cast<CellShape>(c.r.shape);
                    const auto family = static_cast<CellFamily>(c.r.family);
                    if (shape == CellShape::Tet && c.r.order == 1 &&
                        family == CellFamily::Lagrange) {
                        NodeBounds<4>(c, xyz, 4);  // its cost: LinearTetCosts
                        tetXyz[nTets] = xyz;
                        tets[nTets] = &c;
                        if (++nTets == kTets) costTets();
                        continue;
                    }
                    NodeBounds(c, xyz, nodeCount);
                    if (c.r.boxStored) {
                        // Curved cells may bulge beyond their nodes: the guaranteed
                        // Bernstein hull.
                        const Box g =
                            GeometryBox(GetBasis(shape, c.r.order, family), xyz);
                        for (int d = 0; d < 3; ++d) {
                            c.lo[d] = std::min(c.lo[d], g.lo[d]);
                            c.hi[d] = std::max(c.hi[d], g.hi[d]);
                        }
                    }
                    c.cost = CellCostFromNodes(shape, c.r.order, family, xyz);
                }
                costTets();
            });
        for (std::size_t i = 0; i < pendingCount_; ++i) {
            const Pending& c = pending_[i];
            for (int d = 0; d < 3; ++d) {
                root.lo[d] = std::min(root.lo[d], c.lo[d]);
                root.hi[d] = std::max(root.hi[d], c.hi[d]);
            }
            const int nodeCount = c.r.nodeCount;
            const std::int64_t* nodes = batchNodes_.data() + c.first;
            // The record (see CellRecord) is composed in the spill's buffer.
            std::uint8_t kind[KindCodes<CellRecord>::kMaxBytes];
            const std::size_t kindBytes = cellKinds.Encode(c.r, kind);
            const std::size_t boxBytes = c.r.boxStored ? 6 * sizeof(double) : 0;
            const std::size_t valueBytes = sizeof(double) * cellValues;
            const std::size_t bytes = kindBytes + boxBytes + c.r.NodeBytes() + valueBytes;
            std::vector<char> large;  // a record beyond a quarter of the buffer
            char* out;
            if (bytes <= cells_->BufferBytes() / 4) {
                out = cells_->Append(bytes);
            } else {
                large.resize(bytes);
                out = large.data();
            }
            std::memcpy(out, kind, kindBytes);
            out += kindBytes;
            if (c.r.boxStored) {
                const double box[6] = {c.lo[0], c.lo[1], c.lo[2],
                                       c.hi[0], c.hi[1], c.hi[2]};
                std::memcpy(out, box, sizeof box);
                out += sizeof box;
            }
            if (c.r.wide) {
                std::memcpy(out, nodes, sizeof(std::int64_t) * nodeCount);
            } else {
                for (int k = 0; k < nodeCount; ++k) {
                    const auto id = static_cast<std::int32_t>(nodes[k]);
                    std::memcpy(out + sizeof id * k, &id, sizeof id);
                }
            }
            out += c.r.NodeBytes();
            if (valueBytes > 0)
                std::memcpy(out, batchValues_.data() + c.firstValue, valueBytes);
            if (!large.empty()) cells_->Write(large.data(), large.size());
            // perSegment * area: CellRenderSeconds with an area of 1 multiplies by 1.0,
            // so the tree sees the same doubles as from the parts and the area.
            const CentroidRecord w{{c.centroid[0], c.centroid[1], c.centroid[2]},
                                   c.cost.parts.perSegment * c.cost.area};
            centroids_->Write(&w, sizeof w);
            centroidBlocks.Add(c.centroid);
            AddSetup(c.cost.parts.setup);
        }
        pendingCount_ = 0;
        batchNodeCount_ = 0;
        batchValues_.clear();
    }

    /// Appends a cell's setup cost to the runs (values compared bit for bit).
    void AddSetup(double setup) {
        if (run_.count > 0 && run_.count < std::numeric_limits<std::uint32_t>::max() &&
            std::memcmp(&setupValues[run_.value], &setup, sizeof setup) == 0) {
            ++run_.count;
            return;
        }
        if (run_.count > 0) setupRuns_->Write(&run_, sizeof run_);
        std::size_t v = 0;
        while (v < setupValues.size() &&
               std::memcmp(&setupValues[v], &setup, sizeof setup) != 0)
            ++v;
        if (v == setupValues.size()) setupValues.push_back(setup);
        run_.value = static_cast<std::uint32_t>(v);
        run_.count = 1;
    }

    std::string spill_;
    std::size_t memoryLimit_;
    std::unique_ptr<SpillWriter> points_, cells_, centroids_, setupRuns_;
    SetupRun run_;
    std::unique_ptr<RecordCache> cache_;
    /// The batch: the first pendingCount_ of kBatchCells entries.
    std::vector<Pending> pending_;
    std::size_t pendingCount_ = 0;
    /// The nodes of the batch's cells (and their coordinates, 3 per node): the first
    /// batchNodeCount_ of arrays sized for the batch limit plus one cell.
    std::vector<std::int64_t> batchNodes_;
    std::vector<double> batchXyz_, batchValues_;
    std::size_t batchNodeCount_ = 0;
    /// Nodes per batch: about B/64 of nodes and coordinates, at least 4096.
    std::size_t batchNodeLimit_ = 4096;
    bool allWide_ = false;
    /// The last cell kind whose written VTK type was checked for HigherOrderDegrees.
    CellShape lastShape_ = CellShape::Tet;
    int lastOrder_ = -1;
    CellFamily lastFamily_ = CellFamily::Lagrange;
    std::uint8_t lastVtkType_ = 0;
};

/// The bounds of a cell's nodes, from the point spill: the box the scan computed for an
/// order-1 Lagrange cell (the same minima and maxima in the same order, so the same
/// doubles). `stored` holds nodeCount ids, int64 when `wide`, else int32.
Box CellNodeBox(RecordCache& points, const char* stored, int nodeCount, bool wide) {
    // Six scalars rather than a Box, so that they stay in registers.
    const double inf = std::numeric_limits<double>::infinity();
    double lo0 = inf, lo1 = inf, lo2 = inf, hi0 = -inf, hi1 = -inf, hi2 = -inf;
    for (int k = 0; k < nodeCount; ++k) {
        std::int64_t id;
        if (wide) {
            std::memcpy(&id, stored + sizeof(std::int64_t) * k, sizeof id);
        } else {
            std::int32_t id32;
            std::memcpy(&id32, stored + sizeof id32 * k, sizeof id32);
            id = id32;
        }
        const double* p = points.Get(id);
        lo0 = std::min(lo0, p[0]);
        hi0 = std::max(hi0, p[0]);
        lo1 = std::min(lo1, p[1]);
        hi1 = std::max(hi1, p[1]);
        lo2 = std::min(lo2, p[2]);
        hi2 = std::max(hi2, p[2]);
    }
    return Box{{lo0, lo1, lo2}, {hi0, hi1, hi2}};
}

/// Per-brick tallies of the distribution pass.
struct BrickTally {
    std::int64_t cells = 0, ghosts = 0, nodes = 0;
    double cost = 0, ghostCost = 0;
    std::uint64_t spillBytes = 0;
};

/// Bytes a mesh's arrays hold (their capacities).
std::uint64_t MeshCapacityBytes(const Mesh& m) {
    std::uint64_t bytes =
        sizeof(double) * m.points.capacity() +
        sizeof(std::int64_t) * (m.cellOffsets.capacity() + m.connectivity.capacity()) +
        m.cellShape.capacity() + m.cellOrder.capacity() + m.cellFamily.capacity() +
        m.ghost.capacity() + m.vtkType.capacity();
    for (const std::vector<Field>* fields : {&m.pointFields, &m.cellFields})
        for (const Field& f : *fields) bytes += sizeof(double) * f.values.capacity();
    return bytes;
}

/// Guaranteed ranges of the fields over all cells of a brick mesh. Every point of a brick
/// is a node of one of its cells.
nlohmann::json BrickRanges(const Mesh& mesh) {
    nlohmann::json ranges = nlohmann::json::object();
    const double inf = std::numeric_limits<double>::infinity();
    std::vector<double> coeffs;
    auto add = [&](const std::string& name, const Interval& i) {
        if (!ranges.contains(name)) {
            ranges[name] = {i.lo, i.hi};
        } else {
            ranges[name][0] = std::min(ranges[name][0].get<double>(), i.lo);
            ranges[name][1] = std::max(ranges[name][1].get<double>(), i.hi);
        }
    };
    auto magnitude = [inf](const std::vector<Interval>& comps) {
        double lo2 = 0, hi2 = 0;
        for (const Interval& c : comps) {
            const double far = std::max(std::abs(c.lo), std::abs(c.hi));
            const double near =
                (c.lo <= 0 && c.hi >= 0) ? 0.0 : std::min(std::abs(c.lo), std::abs(c.hi));
            hi2 += far * far;
            lo2 += near * near;
        }
        // Outward rounding of the square roots.
        return Interval{std::nextafter(std::sqrt(lo2), 0.0) * (1 - 4e-16),
                        std::nextafter(std::sqrt(hi2), inf) * (1 + 4e-16)};
    };
    // When every cell is linear, a scalar field's range over the cells is its range over
    // the points (each cell's range is that of its nodes, and every point is a node).
    // Taken so when the extremes are finite and nonzero: then the same doubles as the
    // cell by cell minima and maxima, whose results for -0 and +0 depend on the order.
    bool allLinear = true;
    for (std::int64_t c = 0; c < mesh.CellCount() && allLinear; ++c)
        allLinear = mesh.cellOrder[c] == 1 && mesh.cellFamily[c] == CellFamily::Lagrange;
    auto pointRange = [inf](const Field& f, Interval& range) {
        double lo = inf, hi = -inf;
        bool finite = true;
        for (const double v : f.values) {
            finite &= std::isfinite(v);
            lo = std::min(lo, v);
            hi = std::max(hi, v);
        }
        range = Interval{lo, hi};
        return finite && lo != 0 && hi != 0 && lo <= hi;
    };
    for (const Field& f : mesh.pointFields) {
        Interval all{inf, -inf};
        std::vector<Interval> comps(f.components, all), cell(f.components);
        Interval points;
        if (mesh.CellCount() > 0 && allLinear && f.components == 1 &&
            pointRange(f, points)) {
            add(f.name, points);
            continue;
        }
        for (std::int64_t c = 0; c < mesh.CellCount(); ++c) {
            const std::int64_t* nodes = mesh.CellNodes(c);
            const int n = mesh.CellNodeCount(c);
            const bool linear =
                mesh.cellOrder[c] == 1 && mesh.cellFamily[c] == CellFamily::Lagrange;
            coeffs.resize(n);
            for (int k = 0; k < f.components; ++k) {
                for (int m = 0; m < n; ++m)
                    coeffs[m] = f.values[nodes[m] * f.components + k];
                if (linear) {
                    const auto [lo, hi] =
                        std::minmax_element(coeffs.begin(), coeffs.end());
                    cell[k] = Interval{*lo, *hi};
                } else {
                    cell[k] = FieldBounds(GetBasis(mesh.cellShape[c], mesh.cellOrder[c],
                                                   mesh.cellFamily[c]),
                                          coeffs.data());
                }
                comps[k].lo = std::min(comps[k].lo, cell[k].lo);
                comps[k].hi = std::max(comps[k].hi, cell[k].hi);
            }
            if (f.components > 1) {
                const Interval m = magnitude(cell);
                all.lo = std::min(all.lo, m.lo);
                all.hi = std::max(all.hi, m.hi);
            }
        }
        if (mesh.CellCount() == 0) continue;
        if (f.components == 1) {
            add(f.name, comps[0]);
        } else {
            add(f.name, all);
            for (int k = 0; k < f.components; ++k)
                add(f.name + "[" + std::to_string(k) + "]", comps[k]);
        }
    }
    for (const Field& f : mesh.cellFields) {
        if (mesh.CellCount() == 0) continue;
        for (int k = 0; k < f.components; ++k) {
            const auto r = f.Range(k);
            add(f.components == 1 ? f.name : f.name + "[" + std::to_string(k) + "]",
                Interval{r[0], r[1]});
        }
        if (f.components > 1) {
            const auto r = f.Range(-1);
            add(f.name, Interval{r[0], r[1]});
        }
    }
    return ranges;
}

nlohmann::json TreeJson(const std::vector<KdNode>& nodes, int n) {
    const KdNode& node = nodes[n];
    if (node.axis < 0) return {{"brick", node.leaf}};
    nlohmann::json j = {{"axis", node.axis},
                        {"split", node.split},
                        {"low", TreeJson(nodes, node.low)},
                        {"high", TreeJson(nodes, node.high)}};
    if (node.tieBreak) j["tie"] = {node.tie[0], node.tie[1]};
    return j;
}

nlohmann::json BoxJson(const Box& b) {
    return {{b.lo[0], b.lo[1], b.lo[2]}, {b.hi[0], b.hi[1], b.hi[2]}};
}

/// Writes `text` to path atomically.
void WriteTextAtomically(const std::string& path, const std::string& text) {
    const std::string tmp = detail::BeginOutputFile(path);
    {
        std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
        out << text;
        out.flush();
        if (!out) {
            detail::AbandonOutputFile(tmp);
            throw InputError(path, "", "cannot write the file");
        }
    }
    detail::CommitOutputFile(tmp, path);
}

std::string PvtuText(const std::vector<StreamField>& pf,
                     const std::vector<StreamField>& cf, bool higherOrderDegrees,
                     int bricks) {
    std::ostringstream x;
    auto array = [&](const char* type, const std::string& name, int comps) {
        x << "      <PDataArray type=\"" << type << "\" Name=\"" << XmlEscape(name)
          << "\"";
        if (comps != 1) x << " NumberOfComponents=\"" << comps << "\"";
        x << "/>\n";
    };
    x << "<?xml version=\"1.0\"?>\n"
      << "<VTKFile type=\"PUnstructuredGrid\" version=\"2.2\" "
         "byte_order=\"LittleEndian\" "
         "header_type=\"UInt64\">\n"
      << "  <PUnstructuredGrid GhostLevel=\"1\">\n    <PPointData>\n";
    for (const StreamField& f : pf) array("Float64", f.name, f.components);
    x << "    </PPointData>\n    <PCellData>\n";
    for (const StreamField& f : cf) array("Float64", f.name, f.components);
    if (higherOrderDegrees) array("Float64", "HigherOrderDegrees", 3);
    array("UInt8", "vtkGhostType", 1);
    x << "    </PCellData>\n    <PPoints>\n";
    array("Float64", "Points", 3);
    x << "    </PPoints>\n";
    for (int b = 0; b < bricks; ++b)
        x << "    <Piece Source=\"" << BrickName(b) << "\"/>\n";
    x << "  </PUnstructuredGrid>\n</VTKFile>\n";
    return x.str();
}

}  // namespace

std::size_t DefaultMemoryLimit() {
    const long pages = ::sysconf(_SC_PHYS_PAGES);
    const long size = ::sysconf(_SC_PAGE_SIZE);
    if (pages <= 0 || size <= 0) return std::size_t(1) << 30;
    return static_cast<std::size_t>(pages) * static_cast<std::size_t>(size) / 4;
}

std::size_t ParseMemorySize(const std::string& text) {
    auto bad = [&](const std::string& why) -> std::size_t {
        throw InputError("command line", "--memory-limit",
                         "'" + text + "' " + why +
                             " (expected a size such as 512M, 4G or 1.5G; at least 4M)");
    };
    std::size_t i = 0;
    while (i < text.size() &&
           (std::isdigit(static_cast<unsigned char>(text[i])) || text[i] == '.'))
        ++i;
    if (i == 0) return bad("is not a size");
    const std::string number = text.substr(0, i);
    if (std::count(number.begin(), number.end(), '.') > 1) return bad("is not a size");
    char* end = nullptr;
    const double value = std::strtod(number.c_str(), &end);
    if (end != number.c_str() + number.size() || !std::isfinite(value))
        return bad("is not a size");
    std::string unit = text.substr(i);
    for (char& c : unit)
        c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
    double scale = 1;
    if (unit.empty() || unit == "B") {
        scale = 1;
    } else {
        static const std::string kUnits = "KMGT";
        const auto u = kUnits.find(unit[0]);
        const std::string rest = unit.substr(1);
        if (u == std::string::npos || !(rest.empty() || rest == "B" || rest == "IB"))
            return bad("has an unknown unit");
        scale = std::pow(1024.0, static_cast<double>(u + 1));
    }
    const double bytes = value * scale;
    if (bytes < 4.0 * 1024 * 1024) return bad("is too small");
    if (bytes > 1e18) return bad("is too large");
    return static_cast<std::size_t>(bytes);
}

PartitionReport PartitionMesh(const std::string& meshPath,
                              const PartitionOptions& options) {
    const auto start = std::chrono::steady_clock::now();
    if (options.bricks < 1)
        throw InputError(
            "command line", "--bricks",
            std::to_string(options.bricks) + " is not a positive number of bricks");
    if (options.outDir.empty()) throw InputError("command line", "--out", "is empty");
    const std::size_t budget =
        options.memoryLimitBytes ? options.memoryLimitBytes : DefaultMemoryLimit();
    const std::string dir = options.outDir;
    {
        // Never write into a folder of other files (a configs folder, a home folder)
        // unless told to: only an empty folder, an earlier partition or its leftovers.
        std::error_code ec;
        if (!options.force && fs::is_directory(dir, ec))
            for (const auto& entry : fs::directory_iterator(dir, ec)) {
                const std::string name = entry.path().filename().string();
                if (IsOurOutput(name) || name == kLock || name.rfind(".spill-", 0) == 0)
                    continue;
                throw InputError(dir, "",
                                 "is a folder that holds other files ('" + name +
                                     "'), not a partition directory; give an empty or new "
                                     "folder, or --force to write into it anyway");
            }
        fs::create_directories(dir, ec);
        if (ec || !fs::is_directory(dir))
            throw InputError(dir, "",
                             "cannot create the output folder" +
                                 (ec ? ": " + ec.message() : std::string()));
    }
    DirLock lock(dir);
    static int serial = 0;
    ScopedDir spill((fs::path(dir) / (".spill-" + std::to_string(::getpid()) + "-" +
                                      std::to_string(serial++)))
                        .string());
    fs::create_directories(spill.Path());

    // 1. Scan: stream the input into spill files.
    ReadOptions readOptions;
    if (options.fields)
        readOptions.fields =
            std::set<std::string>(options.fields->begin(), options.fields->end());
    ScanSink scan(spill.Path(), budget);
    const std::size_t streamBuffer =
        std::clamp<std::size_t>(budget / 64, 64 << 10, 4 << 20);
    StreamStats stats;
    if (IsGmshPath(meshPath)) {
        // Gmsh: its own streaming reader; the tag maps take a budget of B/8 each.
        GmshStreamOptions gmshOptions;
        gmshOptions.bufferBytes = streamBuffer;
        gmshOptions.mapBytes = budget / 8;
        gmshOptions.spillDir = spill.Path();
        stats = StreamGmsh(meshPath, readOptions, gmshOptions, scan);
    } else {
        stats = StreamMesh(meshPath, readOptions, streamBuffer, scan);
    }
    scan.Close();
    if (stats.wholeMeshBytes > budget)
        log::Warn(meshPath + ": this format is read whole (" +
                  std::to_string(stats.wholeMeshBytes >> 20) +
                  " MiB), more than --memory-limit; convert it to an appended .vtu to "
                  "stream it");
    if (scan.cells == 0) throw InputError(meshPath, "", "has no 3-D cells to partition");
    if (options.bricks > scan.cells)
        throw InputError("command line", "--bricks",
                         std::to_string(options.bricks) + " bricks for " +
                             std::to_string(scan.cells) +
                             " cells: at most one brick per cell");
    // The input and arguments are good: now remove what earlier runs left (the manifest
    // first; we hold the lock, so the owners of other spill folders are gone).
    RemovePreviousRun(dir, spill.Path());
    log::Info("partition: scanned " + std::to_string(scan.cells) + " cells, " +
              std::to_string(scan.points) + " points");

    auto phase = [&start](const char* what) {
        const double t =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        char line[96];
        std::snprintf(line, sizeof line, "partition: %s done at %.2f s", what, t);
        log::Debug(line);
    };
    phase("scan");

    // 2. The k-d tree over the centroids.
    const std::string centroidsPath = scan.CentroidsPath();
    const double rootDiagonal = Diagonal(scan.root);
    // A pass reads the centroid records straight into WeightedPoints (the same layout,
    // the per-segment cost in place of the cost), chunk by chunk, and turns them into
    // costs; blocks the tree builder does not want are not read (nor their setup costs).
    static_assert(
        sizeof(CentroidRecord) == sizeof(WeightedPoint) &&
            offsetof(CentroidRecord, segmentArea) == offsetof(WeightedPoint, cost),
        "centroid records are read as WeightedPoints");
    const CentroidPass pass =
        [&](const BlockFilter& wanted,
            const std::function<void(const WeightedPoint*, std::size_t)>& visit) {
            SpillFile file(centroidsPath);
            SetupCosts setups(scan.SetupsPath(), scan.setupValues);
            const CentroidBlocks& blocks = scan.centroidBlocks;
            HPRAY_CHECK_EQ(blocks.Count(), scan.cells);
            constexpr std::size_t kChunk = 8192;  // points per visit (256 KiB)
            std::vector<WeightedPoint> chunk(kChunk);
            std::vector<double> setup(kChunk);
            std::size_t filled = 0;
            // Turns the records of the chunk from `from` on into points; visits a full
            // chunk.
            auto flush = [&](std::size_t from) {
                setups.Next(setup.data() + from, filled - from);
                for (std::size_t i = from; i < filled; ++i)
                    chunk[i].cost =
                        CellRenderSeconds({setup[i], chunk[i].cost}, 1.0, rootDiagonal);
            };
            std::int64_t next = 0;     // the cell of the next setup cost
            std::int64_t skipped = 0;  // cells left out before `next`
            const std::size_t nBlocks = blocks.Blocks();
            for (std::size_t b = 0; b < nBlocks;) {
                if (wanted && !wanted(blocks.BlockBox(b))) {
                    ++b;
                    continue;
                }
                // A run of wanted blocks: cells [first, end).
                std::size_t e = b + 1;
                while (e < nBlocks && (!wanted || wanted(blocks.BlockBox(e)))) ++e;
                const std::int64_t first = static_cast<std::int64_t>(b) << blocks.Shift();
                const std::int64_t end =
                    std::min(scan.cells, static_cast<std::int64_t>(e) << blocks.Shift());
                setups.Skip(first - next);
                skipped += first - next;
                next = end;
                for (std::int64_t c = first; c < end;) {
                    const std::size_t n = static_cast<std::size_t>(std::min<std::int64_t>(
                        end - c, static_cast<std::int64_t>(kChunk - filled)));
                    file.Read(chunk.data() + filled,
                              static_cast<std::uint64_t>(c) * sizeof(CentroidRecord),
                              n * sizeof(CentroidRecord));
                    const std::size_t from = filled;
                    filled += n;
                    flush(from);
                    c += static_cast<std::int64_t>(n);
                    if (filled == kChunk) {
                        visit(chunk.data(), filled);
                        filled = 0;
                    }
                }
                b = e;
            }
            if (filled > 0) visit(chunk.data(), filled);
            log::Debug("partition: tree pass over " + std::to_string(next - skipped) +
                       " of " + std::to_string(scan.cells) + " centroids");
        };
    const std::size_t collectLimit = std::clamp<std::size_t>(
        budget / 8 / (2 * sizeof(double)) / static_cast<std::size_t>(options.bricks), 256,
        std::size_t(1) << 20);
    const KdTree tree = BuildKdTree(scan.root, options.bricks, pass, collectLimit);
    const std::vector<Box> leafBoxes = tree.LeafBoxes();
    phase("tree");

    // 3. Distribute cells to brick spills (owner + ghost copies).
    const int nBricks = options.bricks;
    std::vector<BrickTally> tally(nBricks);
    KindCodes<BrickCellRecord> brickKinds;  // the records in the brick spills
    const std::size_t recordTail = sizeof(double) * scan.cellValues;
    // Each leaf's region without its faces on split planes (faces on the root box open to
    // infinity): a cell box strictly inside its owner's touches no other leaf, as
    // TouchedLeaves would find.
    std::vector<Box> interior = leafBoxes;
    for (Box& b : interior)
        for (int d = 0; d < 3; ++d) {
            if (!b.InnerLo(d)) b.lo[d] = -std::numeric_limits<double>::infinity();
            if (!b.InnerHi(d)) b.hi[d] = std::numeric_limits<double>::infinity();
        }
    for (int first = 0; first < nBricks; first += kBricksPerPass) {
        const int last = std::min(nBricks, first + kBricksPerPass);
        const std::size_t buffer = std::clamp<std::size_t>(
            budget / 8 / static_cast<std::size_t>(last - first), 16 << 10, 1 << 20);
        std::vector<std::unique_ptr<SpillWriter>> writers;
        for (int b = first; b < last; ++b)
            writers.push_back(std::make_unique<SpillWriter>(
                spill.Path() + "/brick-" + std::to_string(b) + ".bin", buffer));
        // The last pass over the cell spill gives its pages back as it goes, for the
        // brick spills to reuse (the centroid spill's serve the brick files, below).
        const bool lastPass = last == nBricks;
        SpillReader reader(scan.CellsPath(), std::size_t(1) << 20, lastPass);
        SpillReader centroids(centroidsPath, std::size_t(1) << 20);
        SetupCosts setups(scan.SetupsPath(), scan.setupValues);
        // Order-1 cells' boxes from their nodes (see CellRecord).
        RecordCache points(scan.PointsPath(), scan.pointStride, budget / 4);
        CellRecord r;
        CentroidRecord c;
        std::vector<int> hits, stack;
        int lastOwner = -1;
        while (scan.cellKinds.Read(reader, r)) {
            Box box;
            if (r.boxStored) {
                double stored[6];
                if (!reader.Read(stored, sizeof stored))
                    throw InternalError("cell spill ends inside a record");
                box = Box{{stored[0], stored[1], stored[2]},
                          {stored[3], stored[4], stored[5]}};
            }
            const std::size_t restBytes = r.NodeBytes() + recordTail;
            const char* rest = reader.Take(restBytes);
            if (!rest || !centroids.Read(&c, sizeof c))
                throw InternalError("cell spill ends inside a record");
            if (!r.boxStored) box = CellNodeBox(points, rest, r.nodeCount, r.wide != 0);
            // A box strictly inside the interior of the last cell's owner (neighbouring
            // cells tend to share it) holds the centroid too: the same owner, no other
            // brick touched.
            auto inside = [&box](const Box& in) {
                return box.lo[0] > in.lo[0] && box.lo[1] > in.lo[1] &&
                       box.lo[2] > in.lo[2] && box.hi[0] < in.hi[0] &&
                       box.hi[1] < in.hi[1] && box.hi[2] < in.hi[2];
            };
            hits.clear();
            int owner = lastOwner;
            if (owner < 0 || !inside(interior[owner])) {
                owner = OwnerBrick(tree, c.x);
                if (!inside(interior[owner])) {
                    tree.TouchedLeaves(box, hits, stack);
                    HPRAY_CHECK(std::find(hits.begin(), hits.end(), owner) != hits.end());
                }
                lastOwner = owner;
            }
            if (hits.empty()) hits.push_back(owner);
            const double cost =
                CellRenderSeconds({setups.Next(), c.segmentArea}, 1.0, rootDiagonal);
            BrickCellRecord h;
            h.shape = r.shape;
            h.order = r.order;
            h.family = r.family;
            h.vtkType = r.vtkType;
            h.nodeCount = r.nodeCount;
            h.wide = static_cast<std::uint8_t>(r.wide);
            for (int b : hits) {
                if (b < first || b >= last) continue;
                h.ghost = b == owner ? 0 : 1;
                SpillWriter& w = *writers[b - first];
                std::uint8_t kind[KindCodes<BrickCellRecord>::kMaxBytes];
                const std::size_t kindBytes = brickKinds.Encode(h, kind);
                if (kindBytes + restBytes <= w.BufferBytes() / 4) {
                    char* out = w.Append(kindBytes + restBytes);
                    std::memcpy(out, kind, kindBytes);
                    std::memcpy(out + kindBytes, rest, restBytes);
                } else {
                    w.Write(kind, kindBytes);
                    w.Write(rest, restBytes);
                }
                BrickTally& t = tally[b];
                ++t.cells;
                t.nodes += r.nodeCount;
                if (h.ghost) {
                    ++t.ghosts;
                    t.ghostCost += cost;
                } else {
                    t.cost += cost;
                }
            }
        }
        for (int b = first; b < last; ++b) {
            writers[b - first]->Close();
            tally[b].spillBytes = writers[b - first]->Bytes();
        }
    }
    {
        std::error_code ec;
        fs::remove(scan.CellsPath(), ec);
        fs::remove(scan.SetupsPath(), ec);
    }

    phase("distribution");

    // 4. Check every brick fits the memory limit before writing anything.
    const std::size_t pointBytes = sizeof(double) * scan.pointStride;
    auto brickBytes = [&](const BrickTally& t, std::int64_t points) {
        // Peak of the assembly, an upper bound: two copies of the connectivity (the
        // brick's and the sorted ids of a renumbering without bitmap; the writer derives
        // its arrays a chunk at a time), per-cell arrays (offsets twice, kinds, ghost,
        // source and written VTK types, degrees, field values twice) and the point
        // records.
        return static_cast<std::uint64_t>(t.nodes) * 16 +
               static_cast<std::uint64_t>(points) * pointBytes +
               static_cast<std::uint64_t>(t.cells) * (16 + 6 + 24 + 2 * recordTail);
    };
    auto tooLarge = [&](int b, std::uint64_t bytes) {
        return InputError("command line", "--memory-limit",
                          "brick " + std::to_string(b) + " needs about " +
                              std::to_string(bytes >> 20) +
                              " MiB to assemble, more than the " + "limit of " +
                              std::to_string(budget >> 20) +
                              " MiB: ask for more bricks or a larger limit");
    };
    // Fail early when a brick cannot fit even before its points are counted.
    for (int b = 0; b < nBricks; ++b)
        if (brickBytes(tally[b], 0) > budget) throw tooLarge(b, brickBytes(tally[b], 0));

    // 5. Brick files: brick b is written (with its field ranges) by a background task
    // while brick b + 1 is assembled, when both fit the limit together (the one in flight
    // at its assembled size, the next at a bound with one point per node); otherwise one
    // at a time.
    int exitAfter = -1;
    if (const char* env = std::getenv(kTestExitEnv)) exitAfter = std::atoi(env);
    nlohmann::json bricksJson = nlohmann::json::array();
    std::uint64_t bytesWritten = 0;
    std::int64_t storedCells = 0;
    {
        // The centroid spill is given back as the bricks are written, about a brick's
        // size at a time, so that their pages are reused.
        SpillRelease centroidSpace(centroidsPath);
        RecordCache pointsCache(scan.PointsPath(), scan.pointStride,
                                std::size_t(4) << 20);
        // The mesh of the last brick written, kept for the next one's arrays.
        std::shared_ptr<Mesh> spare;
        struct InFlight {
            int brick = -1;
            std::shared_ptr<Mesh> mesh;
            std::size_t points = 0;
            /// brickBytes of the assembled brick, or the mesh's capacity if larger
            std::uint64_t bytes = 0;
            /// The field ranges and the checksum, after the file is written.
            std::future<std::pair<nlohmann::json, std::string>> written;
        } inFlight;
        // Waits for the brick in flight, then records it.
        auto finish = [&] {
            if (inFlight.brick < 0) return;
            const auto [ranges, sha256] = inFlight.written.get();
            const int b = inFlight.brick;
            const BrickTally& t = tally[b];
            const std::string file = BrickName(b);
            const std::string path = (fs::path(dir) / file).string();
            const std::uint64_t bytes = fs::file_size(path);
            bytesWritten += bytes;
            storedCells += inFlight.mesh->CellCount();
            bricksJson.push_back({{"file", file},
                                  {"box", BoxJson(leafBoxes[b])},
                                  {"cells", inFlight.mesh->CellCount()},
                                  {"ghosts", t.ghosts},
                                  {"points", static_cast<std::int64_t>(inFlight.points)},
                                  {"cost", t.cost},
                                  {"cost_with_ghosts", t.cost + t.ghostCost},
                                  {"ranges", ranges},
                                  {"sha256", sha256},
                                  {"bytes", bytes}});
            std::shared_ptr<Mesh> written = std::move(inFlight.mesh);
            inFlight = InFlight{};
            // The next brick reuses the mesh's arrays (no fresh pages to fault in).
            if (written.use_count() == 1) spare = std::move(written);
            if (exitAfter >= 0 && b + 1 >= exitAfter) {
                std::fflush(nullptr);
                ::_exit(75);  // test hook: die like a killed process, spills left behind
            }
        };
        // A failed assembly must not leave the write in flight behind.
        struct WaitInFlight {
            InFlight& f;
            ~WaitInFlight() {
                if (f.written.valid()) f.written.wait();
            }
        } waitInFlight{inFlight};
        for (int b = 0; b < nBricks; ++b) {
            const BrickTally& t = tally[b];
            if (inFlight.brick >= 0 &&
                inFlight.bytes + std::max(brickBytes(t, std::min<std::int64_t>(
                                                            t.nodes, scan.points)),
                                          spare ? MeshCapacityBytes(*spare) : 0) >
                    budget)
                finish();
            std::shared_ptr<Mesh> assembled = std::move(spare);
            if (!assembled) assembled = std::make_shared<Mesh>();
            Mesh& mesh = *assembled;
            // The arrays are sized from the tallies and filled in place (a reused mesh's
            // are overwritten, not cleared first).
            const auto nCells = static_cast<std::size_t>(t.cells);
            const auto nNodes = static_cast<std::size_t>(t.nodes);
            mesh.cellOffsets.resize(nCells + 1);
            mesh.cellOffsets[0] = 0;
            mesh.connectivity.resize(nNodes);
            mesh.cellShape.resize(nCells);
            mesh.cellOrder.resize(nCells);
            mesh.cellFamily.resize(nCells);
            mesh.ghost.resize(nCells);
            mesh.vtkType.resize(nCells);
            std::vector<double> cellValues(nCells * scan.cellValues);
            {
                const std::string path =
                    spill.Path() + "/brick-" + std::to_string(b) + ".bin";
                SpillReader reader(path, std::size_t(1) << 20);
                BrickCellRecord r;
                // The node count of the last kind seen, checked once per run of cells of
                // one kind (Mesh::AddCell checks it for every cell).
                std::uint8_t lastKind[3] = {0xff, 0xff, 0xff};
                std::size_t c = 0, at = 0;  // cells and nodes filled
                while (brickKinds.Read(reader, r)) {
                    const char* stored = reader.Take(r.NodeBytes() + recordTail);
                    if (!stored || c == nCells || nNodes - at < r.nodeCount)
                        throw InternalError("brick spill does not match its tally");
                    if (r.shape != lastKind[0] || r.order != lastKind[1] ||
                        r.family != lastKind[2]) {
                        HPRAY_CHECK_EQ(static_cast<int>(r.nodeCount),
                                       NodeCount(static_cast<CellShape>(r.shape), r.order,
                                                 static_cast<CellFamily>(r.family)));
                        lastKind[0] = r.shape;
                        lastKind[1] = r.order;
                        lastKind[2] = r.family;
                    }
                    std::int64_t* nodes = mesh.connectivity.data() + at;
                    if (r.wide) {
                        std::memcpy(nodes, stored, r.NodeBytes());
                    } else {
                        for (int k = 0; k < r.nodeCount; ++k) {
                            std::int32_t id;
                            std::memcpy(&id, stored + sizeof id * k, sizeof id);
                            nodes[k] = id;
                        }
                    }
                    at += r.nodeCount;
                    mesh.cellOffsets[c + 1] = static_cast<std::int64_t>(at);
                    mesh.cellShape[c] = static_cast<CellShape>(r.shape);
                    mesh.cellOrder[c] = r.order;
                    mesh.cellFamily[c] = static_cast<CellFamily>(r.family);
                    mesh.ghost[c] = r.ghost;
                    mesh.vtkType[c] = r.vtkType;
                    if (recordTail > 0)
                        std::memcpy(cellValues.data() + c * scan.cellValues,
                                    stored + r.NodeBytes(), recordTail);
                    ++c;
                }
                if (c != nCells || at != nNodes)
                    throw InternalError("brick spill does not match its tally");
                std::error_code ec;
                fs::remove(path, ec);
            }
            // Renumber points: sorted unique global ids become local 0..n-1.
            std::vector<std::int64_t> ids;
            RenumberPoints(mesh.connectivity, ids, budget / 16);
            const std::size_t nPoints = ids.size();
            if (brickBytes(t, static_cast<std::int64_t>(nPoints)) > budget)
                throw tooLarge(b, brickBytes(t, static_cast<std::int64_t>(nPoints)));
            mesh.points.resize(3 * nPoints);
            mesh.pointFields.resize(scan.pointFields.size());
            for (std::size_t k = 0; k < scan.pointFields.size(); ++k) {
                Field& field = mesh.pointFields[k];
                field.name = scan.pointFields[k].name;
                field.association = Association::Point;
                field.components = scan.pointFields[k].components;
                field.values.resize(nPoints * field.components);
            }
            for (std::size_t i = 0; i < nPoints; ++i) {
                const double* rec = pointsCache.Get(ids[i]);
                std::copy(rec, rec + 3, mesh.points.begin() + 3 * i);
                int offset = 3;
                for (Field& field : mesh.pointFields) {
                    std::copy(rec + offset, rec + offset + field.components,
                              field.values.begin() + i * field.components);
                    offset += field.components;
                }
            }
            std::vector<std::int64_t>().swap(ids);
            {
                int offset = 0;
                mesh.cellFields.resize(scan.cellFields.size());
                for (std::size_t j = 0; j < scan.cellFields.size(); ++j) {
                    const StreamField& f = scan.cellFields[j];
                    Field& field = mesh.cellFields[j];
                    field.name = f.name;
                    field.association = Association::Cell;
                    field.components = f.components;
                    field.values.resize(nCells * f.components);
                    for (std::size_t c = 0; c < nCells; ++c)
                        for (int k = 0; k < f.components; ++k)
                            field.values[c * f.components + k] =
                                cellValues[c * scan.cellValues + offset + k];
                    offset += f.components;
                }
                std::vector<double>().swap(cellValues);
            }
            finish();
            // The field ranges are computed while the file is written and checksummed,
            // while the next brick is assembled.
            const std::string path = (fs::path(dir) / BrickName(b)).string();
            const bool degrees = scan.higherOrderDegrees;
            centroidSpace.Release(
                sizeof(std::int64_t) *
                    (mesh.connectivity.size() + mesh.cellOffsets.size()) +
                2 * nCells +
                sizeof(double) * (mesh.points.size() + nPoints * (scan.pointStride - 3) +
                                  nCells * scan.cellValues));
            inFlight.brick = b;
            inFlight.mesh = assembled;
            inFlight.points = nPoints;
            inFlight.bytes = std::max(brickBytes(t, static_cast<std::int64_t>(nPoints)),
                                      MeshCapacityBytes(mesh));
            inFlight.written = std::async(std::launch::async, [assembled, path, degrees] {
                std::future<nlohmann::json> ranges = std::async(
                    std::launch::async, [assembled] { return BrickRanges(*assembled); });
                Sha256
                    sha;  // of the bytes as they are written: the file is not read back
                try {
                    WriteVtu(path, *assembled, degrees,
                             [&sha](const char* data, std::size_t bytes) {
                                 sha.Update(data, bytes);
                             });
                } catch (...) {
                    ranges.wait();
                    throw;
                }
                return std::make_pair(ranges.get(), sha.HexDigest());
            });
        }
        finish();
        log::Debug("partition: point cache of the bricks: " +
                   std::to_string(pointsCache.Misses()) + " blocks read");
    }

    phase("bricks");

    // 6. Index, then the manifest last.
    const std::string index = (fs::path(dir) / kIndex).string();
    const std::string indexText =
        PvtuText(scan.pointFields, scan.cellFields, scan.higherOrderDegrees, nBricks);
    WriteTextAtomically(index, indexText);
    bytesWritten += indexText.size();

    double maxCost = 0, sumCost = 0;
    for (const BrickTally& t : tally) {
        maxCost = std::max(maxCost, t.cost);
        sumCost += t.cost;
    }
    const double balance = sumCost > 0 ? maxCost / (sumCost / nBricks) : 1.0;
    nlohmann::json fields = nlohmann::json::object();
    for (const StreamField& f : scan.pointFields)
        fields[f.name] = {{"association", "point"}, {"components", f.components}};
    for (const StreamField& f : scan.cellFields)
        fields[f.name] = {{"association", "cell"}, {"components", f.components}};
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    nlohmann::json manifest;
    manifest["format"] = "hpray-partition";
    manifest["version"] = 1;
    manifest["source"] = meshPath;
    manifest["root_box"] = BoxJson(scan.root);
    manifest["fields"] = fields;
    manifest["bricks"] = bricksJson;
    manifest["tree"] = TreeJson(tree.nodes, tree.root);
    manifest["cost_model"] =
        "estimated render cost, 1 = one linear tet (partition/cost_model.h)";
    manifest["stats"] = {{"input_cells", scan.cells},
                         {"input_points", scan.points},
                         {"skipped_cells", stats.skippedCells},
                         {"stored_cells", storedCells},
                         {"balance", balance},
                         {"streamed", stats.streamed},
                         {"memory_limit_bytes", budget},
                         {"seconds", seconds}};
    const std::string manifestText = manifest.dump(1) + "\n";
    WriteTextAtomically((fs::path(dir) / kManifest).string(), manifestText);
    bytesWritten += manifestText.size();

    PartitionReport report;
    report.inputCells = scan.cells;
    report.inputPoints = scan.points;
    report.storedCells = storedCells;
    report.bytesWritten = bytesWritten;
    report.balance = balance;
    report.seconds = seconds;
    report.streamed = stats.streamed;
    return report;
}

}  // namespace hpray::partition
