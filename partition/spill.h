// Spill files of the out-of-core partitioner: buffered sequential writers and readers,
// and a bounded LRU cache for random access to fixed-size point records.
#pragma once

#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <limits>
#include <mutex>
#include <string>
#include <vector>

#include "util/check.h"

namespace hpray::partition {

/// Appends bytes to a file through a buffer of `bufferBytes`. A full buffer is written by
/// a background thread (shared by all writers, in submission order) while the caller
/// fills a second buffer of the same size, so at most two buffers per writer are held.
/// Flush() returns once everything written so far is in the file; Close() (or the
/// destructor) flushes and closes. Throws InputError(path) on write errors (disk full),
/// from the Write, Flush or Close after the failed write.
class SpillWriter {
  public:
    SpillWriter(const std::string& path, std::size_t bufferBytes);
    ~SpillWriter();
    SpillWriter(const SpillWriter&) = delete;
    SpillWriter& operator=(const SpillWriter&) = delete;

    void Write(const void* data, std::size_t bytes) {
        if (bytes <= capacity_ - used_) {  // fits the buffer: no call
            std::memcpy(buffer_.data() + used_, data, bytes);
            used_ += bytes;
            return;
        }
        WriteAcross(data, bytes);
    }
    /// Room for the next `bytes` of the file in the buffer (at most its size), for the
    /// caller to fill before the next call.
    char* Append(std::size_t bytes) {
        if (bytes > capacity_ - used_) Ship();
        HPRAY_CHECK_LE(bytes, capacity_ - used_);
        char* p = buffer_.data() + used_;
        used_ += bytes;
        return p;
    }
    std::size_t BufferBytes() const { return capacity_; }
    void Flush();
    void Close();
    std::uint64_t Bytes() const { return written_ + used_; }
    const std::string& Path() const { return path_; }

  private:
    /// Write of more bytes than the buffer has room for: ships full buffers.
    void WriteAcross(const void* data, std::size_t bytes);
    /// Hands the filled buffer to the background thread (after the previous one is
    /// written) and continues in the other buffer.
    void Ship();
    /// Waits until the background thread has written the buffer it was handed; throws
    /// on a write error.
    void Wait();

    std::string path_;
    int fd_ = -1;
    std::vector<char> buffer_, inFlight_;  ///< capacity_ bytes each (while open)
    std::size_t capacity_ = 0;
    std::size_t used_ = 0;           ///< bytes of buffer_ filled
    std::size_t inFlightBytes_ = 0;  ///< bytes of inFlight_ to write
    std::uint64_t written_ = 0;
    std::mutex mutex_;
    std::condition_variable done_;
    bool busy_ = false;  ///< inFlight_ is being written
    int error_ = 0;      ///< errno of a failed background write
};

/// Reads a file sequentially through a buffer of `bufferBytes`.
class SpillReader {
  public:
    /// With `release`, the file's pages are given back to the system as they are read
    /// (a spill read for the last time): the space it read lies in holes of the file.
    SpillReader(const std::string& path, std::size_t bufferBytes, bool release = false);
    ~SpillReader();
    SpillReader(const SpillReader&) = delete;
    SpillReader& operator=(const SpillReader&) = delete;

    /// Copies the next `bytes` into dst; false at a clean end of file; throws InputError
    /// for a file that ends inside the request.
    bool Read(void* dst, std::size_t bytes) {
        const char* p = Take(bytes);
        if (!p) return false;
        std::memcpy(dst, p, bytes);
        return true;
    }
    /// A pointer to the next `bytes` (valid until the next call); nullptr at a clean end.
    const char* Take(std::size_t bytes) {
        if (end_ - begin_ < bytes && !Fill(bytes)) return nullptr;
        const char* p = buffer_.data() + begin_;
        begin_ += bytes;
        return p;
    }

  private:
    bool Fill(std::size_t need);
    std::string path_;
    int fd_ = -1;
    std::vector<char> buffer_;
    std::size_t begin_ = 0, end_ = 0;
    bool eof_ = false;
    bool release_ = false;
    std::uint64_t offset_ = 0;    ///< file offset of the end of the buffered bytes
    std::uint64_t released_ = 0;  ///< bytes at the start of the file given back
};

/// A spill file no longer read, whose space is given back to the system a piece at a time
/// (holes punched from its start) so that files written meanwhile reuse its pages rather
/// than the page cache growing; the file is removed on destruction.
class SpillRelease {
  public:
    explicit SpillRelease(const std::string& path);
    ~SpillRelease();
    SpillRelease(const SpillRelease&) = delete;
    SpillRelease& operator=(const SpillRelease&) = delete;

    /// Gives back about the next `bytes` of the file (whole pages; nothing on a file
    /// system without holes).
    void Release(std::uint64_t bytes);

  private:
    std::string path_;
    int fd_ = -1;
    std::uint64_t released_ = 0;
};

/// Random reads of a spill file (pread), for passes that skip parts of it.
class SpillFile {
  public:
    explicit SpillFile(const std::string& path);
    ~SpillFile();
    SpillFile(const SpillFile&) = delete;
    SpillFile& operator=(const SpillFile&) = delete;

    /// Copies the bytes [offset, offset + bytes) of the file into dst; throws
    /// InternalError when the file ends first, InputError(path) on a read error.
    void Read(void* dst, std::uint64_t offset, std::size_t bytes);

  private:
    std::string path_;
    int fd_ = -1;
};

/// Random access to records of `stride` doubles stored back to back in a file, through an
/// LRU cache of blocks holding at most about `cacheBytes` (a slot per cached block, found
/// through a table indexed by block number).
class RecordCache {
  public:
    RecordCache(const std::string& path, int stride, std::size_t cacheBytes);
    ~RecordCache();
    RecordCache(const RecordCache&) = delete;
    RecordCache& operator=(const RecordCache&) = delete;

    /// Record `index`; the pointer stays valid until the next Get or Invalidate.
    const double* Get(std::int64_t index) {
        const std::int64_t b = index >> blockShift_;
        const std::int64_t within = index & (recordsPerBlock_ - 1);
        if (b == lastBlock_) return last_ + within * stride_;
        if (static_cast<std::uint64_t>(b) < slotOf_.size() && slotOf_[b] >= 0) {
            Slot& slot = slots_[slotOf_[b]];  // a cached block
            slot.lastUse = ++clock_;
            lastBlock_ = b;
            last_ = slot.data.data();
            return last_ + within * stride_;
        }
        return Load(index);
    }
    /// Forgets every cached block (after the file grew).
    void Invalidate();
    std::int64_t Misses() const { return misses_; }

  private:
    /// Get of a record outside the last block used.
    const double* Load(std::int64_t index);
    struct Slot {
        std::int64_t block = -1;  ///< block held, -1: free
        std::uint64_t lastUse = 0;
        std::vector<double> data;
    };
    std::string path_;
    int fd_ = -1;
    int stride_ = 0;
    std::int64_t recordsPerBlock_ = 0;  ///< a power of two: 1 << blockShift_
    int blockShift_ = 0;
    std::size_t maxBlocks_ = 0;
    std::vector<Slot> slots_;
    std::vector<std::int32_t> slotOf_;  ///< per block: its slot, -1 when not cached
    std::uint64_t clock_ = 0;
    /// The block of last_; no index maps to the initial value.
    std::int64_t lastBlock_ = std::numeric_limits<std::int64_t>::min();
    const double* last_ = nullptr;
    std::int64_t misses_ = 0;
};

}  // namespace hpray::partition
