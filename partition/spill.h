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
    SpillReader(const std::string& path, std::size_t bufferBytes);
    ~SpillReader();
    SpillReader(const SpillReader&) = delete;
    SpillReader& operator=(const SpillReader&) = delete;

    /// Copies the next `bytes` into dst; false at a clean end of file; throws InputError
    /// for a file that ends inside the request.
    bool Read(void* dst, std::size_t bytes);
    /// A pointer to the next `bytes` (valid until the next call); nullptr at a clean end.
    const char* Take(std::size_t bytes);

  private:
    bool Fill(std::size_t need);
    std::string path_;
    int fd_ = -1;
    std::vector<char> buffer_;
    std::size_t begin_ = 0, end_ = 0;
    bool eof_ = false;
};

/// Read-only windows of a file mapped into memory (no copy out of the page cache), one at
/// a time: mapping a window unmaps the previous one, so at most one window is resident
/// through this object.
class SpillMap {
  public:
    explicit SpillMap(const std::string& path);
    ~SpillMap();
    SpillMap(const SpillMap&) = delete;
    SpillMap& operator=(const SpillMap&) = delete;

    /// The bytes [offset, offset + bytes) of the file, valid until the next Map or the
    /// destructor. Throws InputError(path) when they cannot be mapped.
    const char* Map(std::uint64_t offset, std::size_t bytes);

  private:
    void Unmap();
    std::string path_;
    int fd_ = -1;
    void* base_ = nullptr;
    std::size_t length_ = 0;
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
        if ((index >> blockShift_) == lastBlock_)
            return last_ + (index & (recordsPerBlock_ - 1)) * stride_;
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
