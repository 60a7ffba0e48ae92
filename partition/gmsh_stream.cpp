// StreamGmsh: three passes over a MSH 4.1 file (structure and tag maps, field values to
// spill files, delivery of nodes and 3-D elements) in bounded memory.
#include "gmsh_stream.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <functional>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <sstream>
#include <string_view>

#include "io/gmsh_detail.h"
#include "io/gmsh_nodes.h"
#include "io/vtk_cells.h"
#include "spill.h"
#include "util/check.h"
#include "util/error.h"
#include "util/log.h"

namespace hpray::partition {
namespace {

/// Longest text token accepted (numbers and section names are far shorter).
constexpr std::size_t kMaxToken = 4096;
/// Runs a tag map may always keep in memory, whatever its budget (1.5 KiB).
constexpr std::size_t kMinRuns = 64;
/// Widest tag range a table on disk may span (slots of 8 bytes, a sparse file).
constexpr std::uint64_t kMaxTableSlots = std::uint64_t(1) << 36;

bool IsSpace(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n'; }

[[noreturn]] void IoFail(const std::string& path, const char* what) {
    throw InputError(path, "", std::string(what) + ": " + std::strerror(errno));
}

/// Writes all bytes at `offset`; throws InputError (disk full) on failure.
void PwriteAll(int fd, const std::string& path, const void* data, std::size_t n,
               std::uint64_t offset) {
    const char* p = static_cast<const char*>(data);
    while (n > 0) {
        const ssize_t w = ::pwrite(fd, p, n, static_cast<off_t>(offset));
        if (w < 0 && errno == EINTR) continue;
        if (w <= 0) IoFail(path, "cannot write the spill file");
        p += w;
        n -= static_cast<std::size_t>(w);
        offset += static_cast<std::uint64_t>(w);
    }
}

/// Reads up to n bytes at `offset` (fewer at the end of the file); returns the count.
std::size_t PreadSome(int fd, const std::string& path, void* dst, std::size_t n,
                      std::uint64_t offset) {
    char* p = static_cast<char*>(dst);
    std::size_t got = 0;
    while (got < n) {
        const ssize_t r = ::pread(fd, p + got, n - got, static_cast<off_t>(offset + got));
        if (r < 0 && errno == EINTR) continue;
        if (r < 0) IoFail(path, "read error");
        if (r == 0) break;
        got += static_cast<std::size_t>(r);
    }
    return got;
}

/// A unique spill file name inside `dir`.
std::string SpillName(const std::string& dir, const std::string& what) {
    static int serial = 0;
    const std::filesystem::path folder =
        dir.empty() ? std::filesystem::temp_directory_path() : std::filesystem::path(dir);
    return (folder / ("gmsh-" + std::to_string(::getpid()) + "-" +
                      std::to_string(serial++) + "-" + what + ".bin"))
        .string();
}

// ------------------------------------------------------------------ the file reader

/// A buffered reader of a MSH file, with the interface the templates of io/gmsh_detail.h
/// expect: text tokens and raw binary values, positions as byte offsets, seeking.
class MshCursor {
  public:
    MshCursor(const std::string& path, std::size_t bufferBytes) : path_(path) {
        fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
        if (fd_ < 0)
            throw InputError(path, "",
                             std::string("cannot open: ") + std::strerror(errno));
        struct stat st {};
        if (::fstat(fd_, &st) != 0) {
            ::close(fd_);
            throw InputError(path, "", "cannot determine the file size");
        }
        size_ = static_cast<std::uint64_t>(st.st_size);
        buf_.resize(std::max<std::size_t>(bufferBytes, 64 << 10));
    }
    ~MshCursor() { ::close(fd_); }
    MshCursor(const MshCursor&) = delete;
    MshCursor& operator=(const MshCursor&) = delete;

    const std::string& Path() const { return path_; }
    std::uint64_t FileSize() const { return size_; }
    std::uint64_t Pos() const { return bufStart_ + bufPos_; }
    void Seek(std::uint64_t pos) {
        if (pos >= bufStart_ && pos <= bufStart_ + bufEnd_) {
            bufPos_ = static_cast<std::size_t>(pos - bufStart_);
            return;
        }
        bufStart_ = pos;
        bufPos_ = bufEnd_ = 0;
    }
    /// Skips bytes the caller has checked are in the file.
    void Skip(std::uint64_t bytes) { Seek(Pos() + bytes); }
    int SizeT() const { return sizeT_; }

    // ---- the reader interface of io/gmsh_detail.h ----
    std::uint64_t Last() const { return last_; }
    bool Binary() const { return binary_; }
    void SetEncoding(bool binary, bool swap, int sizeT) {
        binary_ = binary;
        swap_ = swap;
        sizeT_ = sizeT;
    }
    /// "byte N" in a binary file, "line N" in an ASCII file (counted on demand).
    std::string Where(std::uint64_t pos) const {
        if (binary_) return "byte " + std::to_string(pos);
        std::uint64_t lines = 1, at = 0;
        const std::uint64_t end = std::min(pos, size_);
        std::vector<char> chunk(1 << 16);
        while (at < end) {
            const std::size_t n = PreadSome(
                fd_, path_, chunk.data(),
                static_cast<std::size_t>(std::min<std::uint64_t>(chunk.size(), end - at)),
                at);
            if (n == 0) break;
            lines += static_cast<std::uint64_t>(std::count(
                chunk.begin(), chunk.begin() + static_cast<std::ptrdiff_t>(n), '\n'));
            at += n;
        }
        return "line " + std::to_string(lines);
    }
    [[noreturn]] void FailAt(std::uint64_t pos, const std::string& message) const {
        throw InputError(path_, Where(pos), message);
    }
    [[noreturn]] void Fail(const std::string& message) const { FailAt(last_, message); }

    bool AtEnd() {
        SkipSpace();
        return !Fill(1);
    }
    std::string_view Token(const char* what) {
        SkipSpace();
        last_ = Pos();
        if (!Fill(1)) Fail(std::string("unexpected end of file, expected ") + what);
        std::size_t len = 0;
        while (true) {
            while (bufPos_ + len < bufEnd_ && !IsSpace(buf_[bufPos_ + len])) ++len;
            if (bufPos_ + len < bufEnd_) break;
            if (len >= kMaxToken)
                Fail(std::string("a token longer than ") + std::to_string(kMaxToken) +
                     " bytes where " + what + " was expected");
            if (!Fill(len + 1)) break;  // the token ends the file
        }
        const std::string_view t(buf_.data() + bufPos_, len);
        bufPos_ += len;
        return t;
    }
    std::uint64_t TextUnsigned(const char* what) { return gmsh::TextUnsigned(*this, what); }
    long long TextInt(const char* what) { return gmsh::TextInt(*this, what); }
    double TextDouble(const char* what) { return gmsh::TextDouble(*this, what); }
    std::string TextString(const char* what) {
        SkipSpace();
        last_ = Pos();
        if (!Fill(1) || buf_[bufPos_] != '"') return std::string(Token(what));
        std::size_t len = 1;
        while (true) {
            while (bufPos_ + len < bufEnd_ && buf_[bufPos_ + len] != '"' &&
                   buf_[bufPos_ + len] != '\n')
                ++len;
            if (bufPos_ + len < bufEnd_ || len >= kMaxToken || !Fill(len + 1)) break;
        }
        if (bufPos_ + len >= bufEnd_ || buf_[bufPos_ + len] != '"')
            Fail(std::string("unterminated quoted ") + what);
        std::string s(buf_.data() + bufPos_ + 1, len - 1);
        bufPos_ += len + 1;
        return s;
    }
    void Expect(const char* keyword) {
        if (AtEnd())
            FailAt(size_, std::string("unexpected end of file, expected ") + keyword);
        const std::string_view t = Token(keyword);
        if (t != keyword)
            Fail(std::string("expected ") + keyword + ", found '" +
                 std::string(t.substr(0, 40)) + "'");
    }
    void EndOfTextLine() {
        while (Fill(1) &&
               (buf_[bufPos_] == ' ' || buf_[bufPos_] == '\t' || buf_[bufPos_] == '\r'))
            ++bufPos_;
        last_ = Pos();
        if (!Fill(1) || buf_[bufPos_] != '\n') Fail("expected the end of the line");
        ++bufPos_;
    }
    void Need(std::uint64_t bytes, const char* what) {
        last_ = Pos();
        const std::uint64_t left = size_ - std::min(Pos(), size_);
        if (left < bytes) {
            std::ostringstream os;
            os << "binary data cut short: " << what << " needs " << bytes << " bytes, "
               << left << " left in the file";
            Fail(os.str());
        }
    }
    std::uint32_t UnswappedUInt32(const char* what) {
        Need(4, what);
        if (!Fill(4)) Fail("read error");
        std::uint32_t v;
        std::memcpy(&v, buf_.data() + bufPos_, 4);
        bufPos_ += 4;
        return v;
    }
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
    void CheckCount(std::uint64_t count, std::uint64_t minBytes, const char* what) {
        const std::uint64_t left = size_ - std::min(Pos(), size_);
        if (minBytes > 0 && count > left / minBytes) {
            std::ostringstream os;
            os << "declared " << what << " count " << count << " is more than the "
               << left << " bytes left in the file can hold";
            Fail(os.str());
        }
    }
    std::uint64_t MinBytes(int sizes, int ints, int doubles) const {
        return binary_ ? std::uint64_t(sizes) * sizeT_ + 4ull * ints + 8ull * doubles
                       : 2ull * (sizes + ints + doubles);
    }

    // ---- skipping ----
    /// Skips `count` size_t values (binary) or tokens (ASCII).
    void SkipSizes(std::uint64_t count, const char* what) {
        if (binary_) {
            CheckCount(count, sizeT_, what);
            Skip(count * sizeT_);
        } else {
            SkipTokens(count, what);
        }
    }
    void SkipTokens(std::uint64_t count, const char* what) {
        for (std::uint64_t i = 0; i < count; ++i) Token(what);
    }
    /// Moves past the "$End<name>" that starts a line and ends a token (ReadGmsh's rule).
    void SkipSection(const std::string& name, std::uint64_t headerPos) {
        const std::string end = "$End" + name;
        char prev = '\n';
        if (Pos() > 0 && PreadSome(fd_, path_, &prev, 1, Pos() - 1) != 1) prev = '\n';
        while (true) {
            if (!Fill(1)) FailAt(headerPos, "section $" + name + " has no " + end);
            const char* b = buf_.data() + bufPos_;
            const std::size_t n = bufEnd_ - bufPos_;
            const void* hit = std::memchr(b, '$', n);
            if (!hit) {
                prev = b[n - 1];
                bufPos_ = bufEnd_;
                continue;
            }
            const std::size_t off =
                static_cast<std::size_t>(static_cast<const char*>(hit) - b);
            if (off > 0) prev = b[off - 1];
            bufPos_ += off;
            if (prev == '\n') {
                Fill(end.size() + 1);
                const std::size_t avail = bufEnd_ - bufPos_;
                if (avail >= end.size() &&
                    std::memcmp(buf_.data() + bufPos_, end.data(), end.size()) == 0 &&
                    (avail == end.size() || IsSpace(buf_[bufPos_ + end.size()]))) {
                    bufPos_ += end.size();
                    return;
                }
            }
            prev = '$';
            ++bufPos_;
        }
    }

  private:
    template <typename T>
    T Raw() {
        if (!Fill(sizeof(T))) Fail("read error");
        unsigned char b[sizeof(T)];
        std::memcpy(b, buf_.data() + bufPos_, sizeof(T));
        if (swap_) std::reverse(b, b + sizeof(T));
        T v;
        std::memcpy(&v, b, sizeof(T));
        bufPos_ += sizeof(T);
        return v;
    }
    void SkipSpace() {
        while (true) {
            while (bufPos_ < bufEnd_ && IsSpace(buf_[bufPos_])) ++bufPos_;
            if (bufPos_ < bufEnd_ || !Fill(1)) return;
        }
    }
    /// Makes at least `need` bytes from the position available; false at the end of the
    /// file (the buffer then holds what is left).
    bool Fill(std::size_t need) {
        if (bufEnd_ - bufPos_ >= need) return true;
        const std::size_t rest = bufEnd_ - bufPos_;
        std::memmove(buf_.data(), buf_.data() + bufPos_, rest);
        bufStart_ += bufPos_;
        bufPos_ = 0;
        bufEnd_ = rest;
        if (need > buf_.size()) buf_.resize(need);
        while (bufEnd_ < buf_.size()) {
            const std::uint64_t at = bufStart_ + bufEnd_;
            if (at >= size_) break;
            const std::size_t n =
                PreadSome(fd_, path_, buf_.data() + bufEnd_,
                          static_cast<std::size_t>(
                              std::min<std::uint64_t>(buf_.size() - bufEnd_, size_ - at)),
                          at);
            if (n == 0) break;
            bufEnd_ += n;
        }
        return bufEnd_ >= need;
    }

    std::string path_;
    int fd_ = -1;
    std::uint64_t size_ = 0;
    std::vector<char> buf_;
    std::uint64_t bufStart_ = 0;  ///< file offset of buf_[0]
    std::size_t bufPos_ = 0, bufEnd_ = 0;
    std::uint64_t last_ = 0;  ///< start of the last value read: where errors point
    bool binary_ = false, swap_ = false;
    int sizeT_ = 8;
};

// ------------------------------------------------------------------ spill structures

/// A spill file of `components` doubles per entity, all NaN at first. Put writes one
/// entity's values; runs of consecutive entities are combined into one write.
class ValueFile {
  public:
    ValueFile(std::string path, std::int64_t entities, int components,
              std::size_t bufferBytes)
        : path_(std::move(path)), entities_(entities), components_(components) {
        fd_ = ::open(path_.c_str(), O_RDWR | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
        if (fd_ < 0) IoFail(path_, "cannot create a spill file");
        capacity_ = std::max<std::size_t>(
            1, bufferBytes / (sizeof(double) * static_cast<std::size_t>(components)));
        // NaN marks an entity without a value (input values are finite).
        std::vector<double> nan(
            std::min<std::uint64_t>(capacity_ * components,
                                    static_cast<std::uint64_t>(entities) * components),
            std::numeric_limits<double>::quiet_NaN());
        const std::uint64_t total = static_cast<std::uint64_t>(entities) * components;
        for (std::uint64_t at = 0; at < total; at += nan.size())
            PwriteAll(fd_, path_, nan.data(),
                      sizeof(double) * std::min<std::uint64_t>(nan.size(), total - at),
                      sizeof(double) * at);
    }
    ~ValueFile() {
        if (fd_ >= 0) ::close(fd_);
        ::unlink(path_.c_str());
    }
    ValueFile(const ValueFile&) = delete;
    ValueFile& operator=(const ValueFile&) = delete;

    void Put(std::int64_t index, const double* values) {
        const std::int64_t n = static_cast<std::int64_t>(pending_.size()) / components_;
        if (n > 0 && (index != first_ + n || static_cast<std::size_t>(n) >= capacity_))
            Flush();
        if (pending_.empty()) first_ = index;
        pending_.insert(pending_.end(), values, values + components_);
    }
    void Flush() {
        if (pending_.empty()) return;
        PwriteAll(fd_, path_, pending_.data(), sizeof(double) * pending_.size(),
                  sizeof(double) * static_cast<std::uint64_t>(first_) * components_);
        pending_.clear();
    }
    /// Entities that have values (one sequential pass); releases the write buffer.
    std::int64_t CountGiven(std::size_t bufferBytes) {
        Flush();
        std::vector<double>().swap(pending_);
        std::vector<double> chunk(std::max<std::size_t>(
            components_, bufferBytes / sizeof(double) / components_ * components_));
        const std::uint64_t total = static_cast<std::uint64_t>(entities_) * components_;
        std::int64_t given = 0;
        for (std::uint64_t at = 0; at < total;) {
            const std::size_t want = static_cast<std::size_t>(
                std::min<std::uint64_t>(chunk.size(), total - at));
            if (PreadSome(fd_, path_, chunk.data(), sizeof(double) * want,
                          sizeof(double) * at) != sizeof(double) * want)
                throw InternalError("spill file " + path_ + " is shorter than written");
            for (std::size_t i = 0; i < want; i += components_)
                given += !std::isnan(chunk[i]);
            at += want;
        }
        return given;
    }
    const std::string& Path() const { return path_; }
    int Components() const { return components_; }

  private:
    std::string path_;
    int fd_ = -1;
    std::int64_t entities_ = 0;
    int components_ = 1;
    std::size_t capacity_ = 1;  ///< entities per combined write
    std::vector<double> pending_;
    std::int64_t first_ = 0;
};

/// tag -> index: runs of consecutive tags with consecutive indices while they fit in the
/// budget, else a table on disk (see gmsh_stream.h). Indices are added in increasing
/// order; Finish() ends insertion.
class TagIndexMap {
  public:
    using FailFn = std::function<void(const std::string&)>;
    TagIndexMap(std::string tablePath, const char* what, std::uint64_t minTag,
                std::uint64_t maxTag, std::size_t budget, std::size_t bufferBytes,
                FailFn fail)
        : path_(std::move(tablePath)),
          what_(what),
          minTag_(minTag),
          maxTag_(maxTag),
          budget_(budget),
          bufferBytes_(bufferBytes),
          fail_(std::move(fail)),
          maxRuns_(std::max<std::size_t>(kMinRuns, budget / sizeof(Run))) {}
    ~TagIndexMap() {
        cache_.reset();
        if (fd_ >= 0) {
            ::close(fd_);
            ::unlink(path_.c_str());
        }
    }
    TagIndexMap(const TagIndexMap&) = delete;
    TagIndexMap& operator=(const TagIndexMap&) = delete;

    void Add(std::uint64_t tag, std::int64_t index) {
        if (fd_ >= 0) return TablePut(tag, index);
        if (!runs_.empty()) {
            Run& r = runs_.back();
            if (tag == r.tag + r.length &&
                index == r.index + static_cast<std::int64_t>(r.length)) {
                ++r.length;
                return;
            }
        }
        if (runs_.size() >= maxRuns_) {
            ToTable();
            return TablePut(tag, index);
        }
        if (runs_.size() == runs_.capacity())
            runs_.reserve(
                std::min(maxRuns_, std::max<std::size_t>(64, 2 * runs_.size())));
        runs_.push_back({tag, index, 1});
    }

    /// Ends insertion; returns a tag that was added twice, if any.
    std::optional<std::uint64_t> Finish() {
        if (fd_ >= 0) {
            TableFlush();
            std::vector<double>().swap(pending_);
            cache_ = std::make_unique<RecordCache>(path_, 1, budget_);
            return duplicate_;
        }
        std::sort(runs_.begin(), runs_.end(),
                  [](const Run& a, const Run& b) { return a.tag < b.tag; });
        for (std::size_t k = 1; k < runs_.size(); ++k)
            if (runs_[k].tag < runs_[k - 1].tag + runs_[k - 1].length)
                return runs_[k].tag;
        return std::nullopt;
    }

    /// The index of `tag`, or -1.
    std::int64_t Find(std::uint64_t tag) {
        if (cache_) {
            if (tag < minTag_ || tag > maxTag_) return -1;
            const double v = cache_->Get(static_cast<std::int64_t>(tag - minTag_))[0];
            return v == 0 ? -1 : static_cast<std::int64_t>(v) - 1;
        }
        if (runs_.empty()) return -1;
        // Lookups mostly walk the runs in order: try the last run hit and the next first.
        for (std::size_t k = hint_; k < std::min(hint_ + 2, runs_.size()); ++k)
            if (tag >= runs_[k].tag && tag - runs_[k].tag < runs_[k].length) {
                hint_ = k;
                return runs_[k].index + static_cast<std::int64_t>(tag - runs_[k].tag);
            }
        auto it =
            std::upper_bound(runs_.begin(), runs_.end(), tag,
                             [](std::uint64_t t, const Run& r) { return t < r.tag; });
        if (it == runs_.begin()) return -1;
        --it;
        if (tag - it->tag >= it->length) return -1;
        hint_ = static_cast<std::size_t>(it - runs_.begin());
        return it->index + static_cast<std::int64_t>(tag - it->tag);
    }

    bool OnDisk() const { return fd_ >= 0; }

  private:
    struct Run {
        std::uint64_t tag;
        std::int64_t index;
        std::uint64_t length;
    };

    void ToTable() {
        if (minTag_ > maxTag_ || maxTag_ - minTag_ >= kMaxTableSlots)
            Fail(std::string(what_) + " tags are too scattered to keep in " +
                 std::to_string(budget_ >> 10) + " KiB, and their declared range [" +
                 std::to_string(minTag_) + ", " + std::to_string(maxTag_) +
                 "] is too wide for a table on disk: renumber the mesh (gmsh -renumber) "
                 "or raise --memory-limit");
        fd_ = ::open(path_.c_str(), O_RDWR | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
        if (fd_ < 0) IoFail(path_, "cannot create a spill file");
        const std::uint64_t slots = maxTag_ - minTag_ + 1;
        if (::ftruncate(fd_, static_cast<off_t>(slots * sizeof(double))) != 0)
            IoFail(path_, "cannot size the tag table");
        capacity_ = std::max<std::size_t>(1, bufferBytes_ / sizeof(double));
        std::vector<Run> runs;
        runs.swap(runs_);
        for (const Run& r : runs)
            for (std::uint64_t k = 0; k < r.length; ++k)
                TablePut(r.tag + k, r.index + static_cast<std::int64_t>(k));
    }
    void TablePut(std::uint64_t tag, std::int64_t index) {
        if (tag < minTag_ || tag > maxTag_)
            Fail(std::string(what_) + " tag " + std::to_string(tag) +
                 " is outside the declared range [" + std::to_string(minTag_) + ", " +
                 std::to_string(maxTag_) + "]");
        const std::uint64_t slot = tag - minTag_;
        if (!pending_.empty() &&
            (slot != first_ + pending_.size() || pending_.size() >= capacity_))
            TableFlush();
        if (pending_.empty()) first_ = slot;
        // index + 1: a zero slot (a hole of the sparse file) means "no such tag".
        pending_.push_back(static_cast<double>(index) + 1.0);
    }
    void TableFlush() {
        if (pending_.empty()) return;
        // A slot written before is a tag defined twice.
        check_.resize(pending_.size());
        const std::size_t bytes = sizeof(double) * pending_.size();
        if (PreadSome(fd_, path_, check_.data(), bytes, sizeof(double) * first_) != bytes)
            throw InternalError("tag table " + path_ + " is shorter than its range");
        for (std::size_t k = 0; k < check_.size() && !duplicate_; ++k)
            if (check_[k] != 0) duplicate_ = minTag_ + first_ + k;
        PwriteAll(fd_, path_, pending_.data(), bytes, sizeof(double) * first_);
        pending_.clear();
    }
    void Fail(const std::string& message) {
        fail_(message);
        throw InternalError("TagIndexMap: the failure callback returned");
    }

    std::string path_;
    const char* what_;
    std::uint64_t minTag_, maxTag_;
    std::size_t budget_, bufferBytes_;
    FailFn fail_;
    std::size_t maxRuns_;
    std::vector<Run> runs_;
    std::size_t hint_ = 0;
    int fd_ = -1;  ///< the table, once the runs outgrow the budget
    std::size_t capacity_ = 1;
    std::vector<double> pending_, check_;
    std::uint64_t first_ = 0;
    std::optional<std::uint64_t> duplicate_;
    std::unique_ptr<RecordCache> cache_;
};

// ------------------------------------------------------------------ the streamer

/// One data section: its header, where it starts and where its entries start.
struct DataSection {
    gmsh::DataHeader header;
    std::uint64_t sectionPos = 0;
    std::uint64_t dataPos = 0;
};

/// A field as ReadGmsh would build it: the sections of its latest time step.
struct FieldPlan {
    std::string name;
    bool point = true;
    long long timeStep = 0;
    int components = 1;
    std::vector<DataSection> sections;
};

class GmshStreamer {
  public:
    GmshStreamer(const std::string& path, const ReadOptions& options,
                 const GmshStreamOptions& o, MeshSink& sink)
        : in_(path, o.bufferBytes),
          options_(options),
          o_(o),
          buffer_(std::max<std::size_t>(o.bufferBytes, 64 << 10)),
          sink_(sink) {}

    StreamStats Run() {
        ScanStructure();
        SelectFields();
        FillFields();
        DeliverPoints();
        DeliverCells();
        if (lowerElements_ > 0)
            log::Warn(in_.Path() + ": skipped " + std::to_string(lowerElements_) +
                      " elements of dimension below 3");
        return stats_;
    }

  private:
    // ---- pass 1: structure ----
    void ScanStructure() {
        bool first = true;
        while (!in_.AtEnd()) {
            const std::string token(in_.Token("a section header"));
            const std::uint64_t headerPos = in_.Last();
            if (first && token != "$MeshFormat")
                in_.Fail("not a gmsh MSH file: it must start with $MeshFormat");
            if (token.empty() || token[0] != '$')
                in_.Fail("expected a section header ($Name), found '" +
                         token.substr(0, 40) + "'");
            const std::string name = token.substr(1);
            if (first) {
                gmsh::ParseMeshFormat(in_);
                first = false;
                continue;
            }
            if (name == "MeshFormat") {
                in_.Fail("a second $MeshFormat section");
            } else if (name == "Nodes") {
                ScanNodes();
            } else if (name == "Elements") {
                ScanElements();
            } else if (name == "Entities") {
                if (in_.Binary()) in_.EndOfTextLine();
                gmsh::SkipEntities(in_);
            } else if (name == "PartitionedEntities") {
                if (in_.Binary()) in_.EndOfTextLine();
                gmsh::SkipPartitionedEntities(in_);
            } else if (name == "NodeData" || name == "ElementData" ||
                       name == "ElementNodeData") {
                ScanData(name, headerPos);
            } else if (name.rfind("End", 0) == 0) {
                in_.Fail("unexpected " + token);
            } else {
                in_.SkipSection(name, headerPos);  // $PhysicalNames, $Periodic, ...
            }
        }
        if (first) in_.FailAt(0, "empty file: not a gmsh MSH file");
        if (!haveNodes_) in_.FailAt(in_.FileSize(), "no $Nodes section");
        if (!haveElements_) in_.FailAt(in_.FileSize(), "no $Elements section");
    }

    void ScanNodes() {
        if (haveNodes_) in_.Fail("a second $Nodes section");
        haveNodes_ = true;
        if (in_.Binary()) in_.EndOfTextLine();
        nodesPos_ = in_.Pos();
        nodes_ = gmsh::ReadNodesHeader(in_);
        nodeMap_ = std::make_unique<TagIndexMap>(
            SpillName(o_.spillDir, "node-tags"), "node", nodes_.minTag, nodes_.maxTag,
            o_.mapBytes, buffer_, [this](const std::string& m) { in_.Fail(m); });
        std::uint64_t total = 0;
        for (std::uint64_t b = 0; b < nodes_.numBlocks; ++b) {
            const gmsh::NodeBlockHeader block =
                gmsh::ReadNodeBlockHeader(in_, nodes_, total);
            for (std::uint64_t i = 0; i < block.count; ++i) {
                const std::uint64_t tag = in_.Size("a node tag");
                gmsh::CheckNodeTag(in_, nodes_, tag);
                nodeMap_->Add(tag, static_cast<std::int64_t>(total + i));
            }
            const std::uint64_t values = block.count * (3 + block.extra);
            if (in_.Binary())
                in_.Skip(values * 8);  // ReadNodeBlockHeader checked the file holds them
            else
                in_.SkipTokens(values, "a node coordinate");
            total += block.count;
        }
        if (total != nodes_.numNodes)
            in_.Fail("node blocks hold " + std::to_string(total) +
                     " nodes, the header declares " + std::to_string(nodes_.numNodes));
        in_.Expect("$EndNodes");
        if (const auto dup = nodeMap_->Finish()) FailDuplicateNode(*dup);
    }

    /// Reports a node tag defined twice at its second definition (as ReadGmsh does).
    [[noreturn]] void FailDuplicateNode(std::uint64_t tag) {
        in_.Seek(nodesPos_);
        const gmsh::NodesHeader h = gmsh::ReadNodesHeader(in_);
        std::uint64_t total = 0;
        bool seen = false;
        for (std::uint64_t b = 0; b < h.numBlocks; ++b) {
            const gmsh::NodeBlockHeader block = gmsh::ReadNodeBlockHeader(in_, h, total);
            for (std::uint64_t i = 0; i < block.count; ++i)
                if (in_.Size("a node tag") == tag) {
                    if (seen)
                        in_.Fail("node tag " + std::to_string(tag) + " is defined twice");
                    seen = true;
                }
            const std::uint64_t values = block.count * (3 + block.extra);
            if (in_.Binary())
                in_.Skip(values * 8);
            else
                in_.SkipTokens(values, "a node coordinate");
            total += block.count;
        }
        in_.FailAt(nodesPos_, "node tag " + std::to_string(tag) + " is defined twice");
    }

    void ScanElements() {
        if (!haveNodes_) in_.Fail("$Elements before $Nodes");
        if (haveElements_) in_.Fail("a second $Elements section");
        haveElements_ = true;
        if (in_.Binary()) in_.EndOfTextLine();
        elementsPos_ = in_.Pos();
        elements_ = gmsh::ReadElementsHeader(in_);
        std::uint64_t total = 0;
        for (std::uint64_t b = 0; b < elements_.numBlocks; ++b) {
            const gmsh::ElementBlockHeader block =
                gmsh::ReadElementBlockHeader(in_, elements_, total);
            total += block.count;
            in_.SkipSizes(block.count * (1 + block.nodes), "an element tag or node tag");
            if (block.dim == 3)
                cells_ += static_cast<std::int64_t>(block.count);
            else
                lowerElements_ += block.count;
        }
        if (total != elements_.numElements)
            in_.Fail("element blocks hold " + std::to_string(total) +
                     " elements, the header declares " +
                     std::to_string(elements_.numElements));
        in_.Expect("$EndElements");
    }

    void ScanData(const std::string& section, std::uint64_t sectionPos) {
        const bool isNode = section == "NodeData";
        const gmsh::DataHeader header = gmsh::ReadDataHeader(in_);
        if (in_.Binary()) in_.EndOfTextLine();
        const std::uint64_t itemBytes =
            in_.Binary() ? 4 + 8ull * header.components : 2ull * (1 + header.components);
        if (!haveNodes_ || (!isNode && !haveElements_))
            in_.FailAt(sectionPos, "$" + section + " before the " +
                                       (isNode ? "$Nodes" : "$Elements") +
                                       " it refers to");
        if (section == "ElementNodeData") {
            if (options_.fields && options_.Wants(header.name))
                in_.FailAt(sectionPos,
                           "field '" + header.name +
                               "' is $ElementNodeData, which hpray does not read; "
                               "write it as $NodeData");
            log::Warn(in_.Path() + ": skipping $ElementNodeData '" + header.name +
                      "' (element-node data is not read)");
            in_.SkipSection(section, sectionPos);
            return;
        }
        const auto count = static_cast<std::uint64_t>(header.count);
        in_.CheckCount(count, itemBytes, "data entry");
        const DataSection data{header, sectionPos, in_.Pos()};
        if (in_.Binary())
            in_.Skip(count * itemBytes);
        else
            in_.SkipTokens(count * (1 + header.components), "a value");
        in_.Expect(("$End" + section).c_str());
        (isNode ? pointNames_ : cellNames_).insert(header.name);
        if (!options_.Wants(header.name)) return;
        // ReadGmsh's rule: the latest time step wins, sections of one step are merged.
        auto& plans = isNode ? pointPlans_ : cellPlans_;
        auto it = plans.find(header.name);
        if (it != plans.end() && header.timeStep < it->second.timeStep) return;
        if (it == plans.end() || header.timeStep > it->second.timeStep ||
            it->second.components != header.components) {
            if (it != plans.end() && header.timeStep == it->second.timeStep)
                in_.FailAt(sectionPos, "'" + header.name + "' has " +
                                           std::to_string(header.components) +
                                           " components here and " +
                                           std::to_string(it->second.components) +
                                           " before");
            FieldPlan plan;
            plan.name = header.name;
            plan.point = isNode;
            plan.timeStep = header.timeStep;
            plan.components = header.components;
            it = plans.insert_or_assign(header.name, std::move(plan)).first;
        }
        it->second.sections.push_back(data);
    }

    // ---- field selection ----
    void SelectFields() {
        // Resolve names as the whole-mesh path does (SelectScalar: point fields first),
        // on a mesh that holds only the field descriptions.
        Mesh described;
        for (const auto& [name, plan] : pointPlans_)
            described.pointFields.push_back(
                Field{name, Association::Point, plan.components, {}});
        for (const auto& [name, plan] : cellPlans_)
            described.cellFields.push_back(
                Field{name, Association::Cell, plan.components, {}});
        auto selected = [&](const FieldPlan& plan) {
            if (!options_.fields) return true;
            for (const std::string& want : *options_.fields) {
                const std::optional<ScalarSelector> sel = SelectScalar(described, want);
                if (sel && sel->field->name == plan.name &&
                    (sel->field->association == Association::Point) == plan.point)
                    return true;
            }
            return false;
        };
        if (options_.fields)
            for (const std::string& want : *options_.fields)
                if (!SelectScalar(described, want)) {
                    std::string list;  // every field in the file, wanted or not
                    for (const auto* names : {&pointNames_, &cellNames_})
                        for (const std::string& name : *names)
                            list += (list.empty() ? "" : ", ") + name;
                    throw InputError(in_.Path(), "",
                                     "field '" + want + "' does not exist; available: " +
                                         (list.empty() ? std::string("(none)") : list));
                }
        for (auto& [name, plan] : pointPlans_)
            if (selected(plan)) pointSelected_.push_back(&plan);
        for (auto& [name, plan] : cellPlans_)
            if (selected(plan)) cellSelected_.push_back(&plan);
    }

    // ---- pass 2: field values to spill files ----
    void FillFields() {
        if (!cellSelected_.empty()) BuildElementMap();
        for (FieldPlan* plan : pointSelected_)
            pointFiles_.push_back(
                Fill(*plan, static_cast<std::int64_t>(nodes_.numNodes)));
        for (FieldPlan* plan : cellSelected_) cellFiles_.push_back(Fill(*plan, cells_));
        elementMap_.reset();
    }

    void BuildElementMap() {
        elementMap_ = std::make_unique<TagIndexMap>(
            SpillName(o_.spillDir, "element-tags"), "element", elements_.minTag,
            elements_.maxTag, o_.mapBytes, buffer_,
            [this](const std::string& m) { in_.Fail(m); });
        in_.Seek(elementsPos_);
        const gmsh::ElementsHeader h = gmsh::ReadElementsHeader(in_);
        std::uint64_t total = 0;
        std::int64_t cell = 0;
        for (std::uint64_t b = 0; b < h.numBlocks; ++b) {
            const gmsh::ElementBlockHeader block =
                gmsh::ReadElementBlockHeader(in_, h, total);
            total += block.count;
            if (block.dim < 3) {
                in_.SkipSizes(block.count * (1 + block.nodes), "an element tag");
                continue;
            }
            for (std::uint64_t e = 0; e < block.count; ++e) {
                elementMap_->Add(in_.Size("an element tag"), cell++);
                in_.SkipSizes(block.nodes, "a node tag");
            }
        }
        if (const auto dup = elementMap_->Finish())
            in_.FailAt(elementsPos_, "element tag " + std::to_string(*dup) +
                                         " is defined twice among the 3-D elements");
    }

    std::unique_ptr<ValueFile> Fill(const FieldPlan& plan, std::int64_t entities) {
        auto file = std::make_unique<ValueFile>(SpillName(o_.spillDir, "field"), entities,
                                                plan.components, buffer_);
        std::vector<double> values(plan.components);
        for (const DataSection& s : plan.sections) {
            in_.Seek(s.dataPos);
            for (long long i = 0; i < s.header.count; ++i) {
                const long long tag =
                    in_.Int(plan.point ? "a node tag" : "an element tag");
                const std::uint64_t tagPos = in_.Last();
                std::int64_t index = -1;
                if (plan.point) {
                    if (tag > 0) index = nodeMap_->Find(static_cast<std::uint64_t>(tag));
                    if (index < 0)
                        in_.FailAt(tagPos, "$NodeData '" + plan.name +
                                               "' refers to undefined node tag " +
                                               std::to_string(tag));
                } else if (tag > 0) {
                    index = elementMap_->Find(static_cast<std::uint64_t>(tag));
                }
                for (int k = 0; k < plan.components; ++k) {
                    values[k] = in_.Double("a value");
                    if (!std::isfinite(values[k]))
                        in_.Fail("'" + plan.name +
                                 "' has a NaN or infinite value at tag " +
                                 std::to_string(tag));
                }
                if (index >= 0) file->Put(index, values.data());
            }
        }
        const std::int64_t given = file->CountGiven(buffer_);
        if (given != entities)
            in_.FailAt(plan.sections.back().sectionPos,
                       "'" + plan.name + "' (time step " + std::to_string(plan.timeStep) +
                           ") gives values for " + std::to_string(given) + " of the " +
                           std::to_string(entities) + " " +
                           (plan.point ? "nodes" : "3-D elements") +
                           "; hpray needs a value for each");
        return file;
    }

    // ---- pass 3: delivery ----
    std::vector<std::unique_ptr<SpillReader>> OpenReaders(
        const std::vector<std::unique_ptr<ValueFile>>& files) const {
        std::vector<std::unique_ptr<SpillReader>> readers;
        const std::size_t each = std::max<std::size_t>(
            64 << 10, buffer_ / std::max<std::size_t>(1, files.size()));
        for (const auto& f : files)
            readers.push_back(std::make_unique<SpillReader>(f->Path(), each));
        return readers;
    }

    /// Reads one entity's values of every field, interleaved, into `out`.
    static void ReadValues(std::vector<std::unique_ptr<SpillReader>>& readers,
                           const std::vector<std::unique_ptr<ValueFile>>& files,
                           double* out) {
        for (std::size_t k = 0; k < readers.size(); ++k) {
            const int n = files[k]->Components();
            if (!readers[k]->Read(out, sizeof(double) * n))
                throw InternalError("field spill " + files[k]->Path() + " ends early");
            out += n;
        }
    }

    void SendFields() {
        std::vector<StreamField> pf, cf;
        for (const FieldPlan* p : pointSelected_) pf.push_back({p->name, p->components});
        for (const FieldPlan* p : cellSelected_) cf.push_back({p->name, p->components});
        for (const StreamField& f : pf) pointComps_ += f.components;
        for (const StreamField& f : cf) cellComps_ += f.components;
        sink_.Fields(pf, cf);
    }

    void DeliverPoints() {
        SendFields();
        stats_.streamed = true;
        auto readers = OpenReaders(pointFiles_);
        const std::size_t stride = 3 + static_cast<std::size_t>(pointComps_);
        const std::size_t batch =
            std::max<std::size_t>(1, buffer_ / (sizeof(double) * stride));
        std::vector<double> xyz, values;
        xyz.reserve(3 * batch);
        values.reserve(batch * pointComps_);
        std::vector<double> one(pointComps_);
        auto flush = [&]() {
            const std::int64_t n = static_cast<std::int64_t>(xyz.size() / 3);
            if (n == 0) return;
            sink_.Points(n, xyz.data(), values.data());
            stats_.points += n;
            xyz.clear();
            values.clear();
        };
        in_.Seek(nodesPos_);
        const gmsh::NodesHeader h = gmsh::ReadNodesHeader(in_);
        std::uint64_t total = 0;
        for (std::uint64_t b = 0; b < h.numBlocks; ++b) {
            const gmsh::NodeBlockHeader block = gmsh::ReadNodeBlockHeader(in_, h, total);
            const std::uint64_t tagsPos = in_.Pos();
            in_.SkipSizes(block.count, "a node tag");
            for (std::uint64_t i = 0; i < block.count; ++i) {
                for (int c = 0; c < 3; ++c) {
                    const double x = in_.Double("a node coordinate");
                    if (!std::isfinite(x)) FailCoordinate(tagsPos, i, in_.Last());
                    xyz.push_back(x);
                }
                for (int c = 0; c < block.extra; ++c)
                    in_.Double("a parametric coordinate");
                ReadValues(readers, pointFiles_, one.data());
                values.insert(values.end(), one.begin(), one.end());
                if (xyz.size() / 3 >= batch) flush();
            }
            total += block.count;
        }
        flush();
    }

    /// A non-finite coordinate of node `i` of the block whose tags start at `tagsPos`.
    [[noreturn]] void FailCoordinate(std::uint64_t tagsPos, std::uint64_t i,
                                     std::uint64_t where) {
        in_.Seek(tagsPos);
        in_.SkipSizes(i, "a node tag");
        const std::uint64_t tag = in_.Size("a node tag");
        in_.FailAt(where, "node tag " + std::to_string(tag) +
                              " has a NaN or infinite coordinate");
    }

    void DeliverCells() {
        auto readers = OpenReaders(cellFiles_);
        std::vector<double> values(cellComps_);
        std::vector<std::int64_t> fileNodes, cellNodes;
        in_.Seek(elementsPos_);
        const gmsh::ElementsHeader h = gmsh::ReadElementsHeader(in_);
        std::uint64_t total = 0;
        for (std::uint64_t b = 0; b < h.numBlocks; ++b) {
            const gmsh::ElementBlockHeader block =
                gmsh::ReadElementBlockHeader(in_, h, total);
            total += block.count;
            if (block.dim < 3) {
                in_.SkipSizes(block.count * (1 + block.nodes), "an element tag");
                stats_.skippedCells += static_cast<std::int64_t>(block.count);
                continue;
            }
            const GmshCellType& kind = *block.kind;
            const std::vector<int>& perm = GmshToInternal(kind.type);
            // The VTK type ReadGmsh records (the one a gmsh user expects in a .vtu:
            // tet10 -> 24, hex27 -> 29, prism18 -> 73, ...; see FixedVtkTypeFor).
            const auto vtkType = static_cast<std::uint8_t>(
                FixedVtkTypeFor(CellKind{kind.shape, kind.order, kind.family}));
            fileNodes.resize(block.nodes);
            cellNodes.resize(block.nodes);
            for (std::uint64_t e = 0; e < block.count; ++e) {
                const std::uint64_t tag = in_.Size("an element tag");
                const std::uint64_t tagPos = in_.Last();
                for (int k = 0; k < block.nodes; ++k) {
                    const std::uint64_t nodeTag = in_.Size("a node tag");
                    const std::int64_t index = nodeMap_->Find(nodeTag);
                    if (index < 0)
                        in_.FailAt(tagPos, "element " + std::to_string(tag) +
                                               " references undefined node tag " +
                                               std::to_string(nodeTag));
                    fileNodes[k] = index;
                }
                for (int k = 0; k < block.nodes; ++k) cellNodes[k] = fileNodes[perm[k]];
                ReadValues(readers, cellFiles_, values.data());
                sink_.Cell(kind.shape, kind.order, kind.family, cellNodes.data(),
                           block.nodes, values.data(), vtkType);
                ++stats_.cells;
            }
        }
    }

    MshCursor in_;
    const ReadOptions& options_;
    const GmshStreamOptions& o_;
    std::size_t buffer_;
    MeshSink& sink_;
    StreamStats stats_;

    bool haveNodes_ = false, haveElements_ = false;
    std::uint64_t nodesPos_ = 0, elementsPos_ = 0;  ///< first byte after the headers
    gmsh::NodesHeader nodes_;
    gmsh::ElementsHeader elements_;
    std::int64_t cells_ = 0;
    std::uint64_t lowerElements_ = 0;
    std::map<std::string, FieldPlan> pointPlans_, cellPlans_;
    std::set<std::string> pointNames_, cellNames_;  ///< of every data section
    std::vector<FieldPlan*> pointSelected_, cellSelected_;
    std::unique_ptr<TagIndexMap> nodeMap_, elementMap_;
    std::vector<std::unique_ptr<ValueFile>> pointFiles_, cellFiles_;
    int pointComps_ = 0, cellComps_ = 0;
};

}  // namespace

bool IsGmshPath(const std::string& path) {
    if (path.size() < 4) return false;
    std::string ext = path.substr(path.size() - 4);
    for (char& c : ext)
        c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    return ext == ".msh";
}

StreamStats StreamGmsh(const std::string& path, const ReadOptions& options,
                       const GmshStreamOptions& streamOptions, MeshSink& sink) {
    GmshStreamer streamer(path, options, streamOptions, sink);
    return streamer.Run();
}

}  // namespace hpray::partition
