// Buffered spill-file writers and readers, and the LRU record cache over a spill file.
#include "spill.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <deque>
#include <functional>
#include <thread>

#include "util/check.h"
#include "util/error.h"

namespace hpray::partition {
namespace {

[[noreturn]] void IoFail(const std::string& path, const char* what) {
    throw InputError(path, "", std::string(what) + ": " + std::strerror(errno));
}

}  // namespace

namespace {

/// One thread that runs submitted jobs in order, started on first use and joined at
/// exit.
class BackgroundQueue {
  public:
    static BackgroundQueue& Get() {
        static BackgroundQueue queue;
        return queue;
    }
    void Submit(std::function<void()> job) {
        {
            std::lock_guard<std::mutex> lock(mutex_);
            if (!thread_.joinable()) thread_ = std::thread([this] { Run(); });
            jobs_.push_back(std::move(job));
        }
        wake_.notify_one();
    }
    ~BackgroundQueue() {
        {
            std::lock_guard<std::mutex> lock(mutex_);
            stop_ = true;
        }
        wake_.notify_one();
        if (thread_.joinable()) thread_.join();
    }

  private:
    void Run() {
        std::unique_lock<std::mutex> lock(mutex_);
        while (true) {
            wake_.wait(lock, [this] { return stop_ || !jobs_.empty(); });
            if (jobs_.empty()) return;
            std::function<void()> job = std::move(jobs_.front());
            jobs_.pop_front();
            lock.unlock();
            job();
            lock.lock();
        }
    }
    std::mutex mutex_;
    std::condition_variable wake_;
    std::deque<std::function<void()>> jobs_;
    std::thread thread_;
    bool stop_ = false;
};

/// Writes all of [p, p + left) to fd; 0 or the errno of the failure.
int WriteAll(int fd, const char* p, std::size_t left) {
    while (left > 0) {
        const ssize_t n = ::write(fd, p, left);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) return n < 0 ? errno : EIO;
        p += n;
        left -= static_cast<std::size_t>(n);
    }
    return 0;
}

}  // namespace

SpillWriter::SpillWriter(const std::string& path, std::size_t bufferBytes)
    : path_(path), capacity_(std::max<std::size_t>(bufferBytes, 4096)) {
    fd_ = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    if (fd_ < 0) IoFail(path, "cannot create the spill file");
    buffer_.resize(capacity_);
}

SpillWriter::~SpillWriter() {
    try {
        Close();
    } catch (...) {
        // Destructors must not throw; Close() reports errors when called explicitly.
    }
    // A failed Close() may leave the background thread writing inFlight_.
    std::unique_lock<std::mutex> lock(mutex_);
    done_.wait(lock, [this] { return !busy_; });
    if (fd_ >= 0) ::close(fd_);
}

void SpillWriter::WriteAcross(const void* data, std::size_t bytes) {
    const char* p = static_cast<const char*>(data);
    while (bytes > 0) {
        if (used_ == capacity_) Ship();
        const std::size_t n = std::min(bytes, capacity_ - used_);
        std::memcpy(buffer_.data() + used_, p, n);
        used_ += n;
        p += n;
        bytes -= n;
    }
}

void SpillWriter::Wait() {
    std::unique_lock<std::mutex> lock(mutex_);
    done_.wait(lock, [this] { return !busy_; });
    if (error_ != 0) {
        errno = error_;
        IoFail(path_, "cannot write the spill file");
    }
}

void SpillWriter::Ship() {
    HPRAY_CHECK(fd_ >= 0);
    Wait();
    if (used_ == 0) return;
    written_ += used_;
    std::swap(buffer_, inFlight_);
    inFlightBytes_ = used_;
    used_ = 0;
    buffer_.resize(capacity_);
    {
        std::lock_guard<std::mutex> lock(mutex_);
        busy_ = true;
    }
    BackgroundQueue::Get().Submit([this] {
        const int error = WriteAll(fd_, inFlight_.data(), inFlightBytes_);
        {
            std::lock_guard<std::mutex> lock(mutex_);
            if (error != 0) error_ = error;
            busy_ = false;
        }
        done_.notify_all();
    });
}

void SpillWriter::Flush() {
    Ship();
    Wait();
}

void SpillWriter::Close() {
    if (fd_ < 0) return;
    Flush();
    ::close(fd_);
    fd_ = -1;
    std::vector<char>().swap(buffer_);
    std::vector<char>().swap(inFlight_);
    used_ = 0;
    capacity_ = 0;  // a Write after Close reaches Ship's check
}

SpillReader::SpillReader(const std::string& path, std::size_t bufferBytes, bool release)
    : path_(path), buffer_(std::max<std::size_t>(bufferBytes, 4096)), release_(release) {
    if (release_) fd_ = ::open(path.c_str(), O_RDWR | O_CLOEXEC);
    if (fd_ < 0) {
        release_ = false;
        fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    }
    if (fd_ < 0) IoFail(path, "cannot open the spill file");
}

SpillReader::~SpillReader() {
    if (fd_ >= 0) ::close(fd_);
}

bool SpillReader::Fill(std::size_t need) {
    if (end_ - begin_ >= need) return true;
    if (need > buffer_.size()) buffer_.resize(need);
    std::memmove(buffer_.data(), buffer_.data() + begin_, end_ - begin_);
    end_ -= begin_;
    begin_ = 0;
    if (release_) {
        // Everything before the buffered bytes has been read: punch it out of the file in
        // steps of at least 4 MiB (on a file system without holes, the pages stay).
        const std::uint64_t upTo = (offset_ - end_) & ~std::uint64_t(4095);
        if (upTo >= released_ + (std::uint64_t(4) << 20)) {
            if (::fallocate(fd_, FALLOC_FL_PUNCH_HOLE | FALLOC_FL_KEEP_SIZE,
                            static_cast<off_t>(released_),
                            static_cast<off_t>(upTo - released_)) == 0) {
                released_ = upTo;
            } else {
                release_ = false;
            }
        }
    }
    while (end_ < need && !eof_) {
        const ssize_t n = ::read(fd_, buffer_.data() + end_, buffer_.size() - end_);
        if (n < 0 && errno == EINTR) continue;
        if (n < 0) IoFail(path_, "cannot read the spill file");
        if (n == 0) eof_ = true;
        end_ += static_cast<std::size_t>(n);
        offset_ += static_cast<std::uint64_t>(n);
    }
    if (end_ >= need) return true;
    if (end_ == 0) return false;
    throw InternalError("spill file " + path_ + " ends inside a record");
}

SpillRelease::SpillRelease(const std::string& path) : path_(path) {
    fd_ = ::open(path.c_str(), O_RDWR | O_CLOEXEC);
}

SpillRelease::~SpillRelease() {
    if (fd_ >= 0) ::close(fd_);
    ::unlink(path_.c_str());
}

void SpillRelease::Release(std::uint64_t bytes) {
    if (fd_ < 0) return;
    const std::uint64_t upTo = (released_ + bytes) & ~std::uint64_t(4095);
    if (upTo <= released_) return;
    if (::fallocate(fd_, FALLOC_FL_PUNCH_HOLE | FALLOC_FL_KEEP_SIZE,
                    static_cast<off_t>(released_),
                    static_cast<off_t>(upTo - released_)) != 0) {
        ::close(fd_);  // no holes here: the space comes back when the file is removed
        fd_ = -1;
        return;
    }
    released_ = upTo;
}

SpillFile::SpillFile(const std::string& path) : path_(path) {
    fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd_ < 0) IoFail(path, "cannot open the spill file");
}

SpillFile::~SpillFile() {
    if (fd_ >= 0) ::close(fd_);
}

void SpillFile::Read(void* dst, std::uint64_t offset, std::size_t bytes) {
    auto* p = static_cast<char*>(dst);
    while (bytes > 0) {
        const ssize_t n = ::pread(fd_, p, bytes, static_cast<off_t>(offset));
        if (n < 0 && errno == EINTR) continue;
        if (n < 0) IoFail(path_, "cannot read the spill file");
        if (n == 0) throw InternalError("spill file " + path_ + " ends inside a record");
        p += n;
        bytes -= static_cast<std::size_t>(n);
        offset += static_cast<std::uint64_t>(n);
    }
}

RecordCache::RecordCache(const std::string& path, int stride, std::size_t cacheBytes)
    : path_(path), stride_(stride) {
    fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd_ < 0) IoFail(path, "cannot open the spill file");
    // Blocks of at most 64 KiB (a power of two of records, so that finding a record's
    // block is a shift); at least 16 of them.
    const std::size_t recordBytes = sizeof(double) * static_cast<std::size_t>(stride);
    while ((std::size_t(2) << blockShift_) * recordBytes <= 65536) ++blockShift_;
    recordsPerBlock_ = std::int64_t(1) << blockShift_;
    maxBlocks_ =
        std::max<std::size_t>(16, cacheBytes / (recordsPerBlock_ * recordBytes + 96));
}

RecordCache::~RecordCache() {
    if (fd_ >= 0) ::close(fd_);
}

void RecordCache::Invalidate() {
    slots_.clear();
    slotOf_.clear();
    last_ = nullptr;
    lastBlock_ = std::numeric_limits<std::int64_t>::min();
}

const double* RecordCache::Load(std::int64_t index) {
    const std::int64_t b = index >> blockShift_;
    const std::int64_t within = index & (recordsPerBlock_ - 1);
    if (b == lastBlock_ && last_) return last_ + within * stride_;
    if (static_cast<std::size_t>(b) >= slotOf_.size())
        slotOf_.resize(static_cast<std::size_t>(b) + 1, -1);
    std::int32_t s = slotOf_[b];
    if (s < 0) {
        ++misses_;
        if (slots_.size() < maxBlocks_) {
            s = static_cast<std::int32_t>(slots_.size());
            slots_.emplace_back();
            slots_.back().data.resize(static_cast<std::size_t>(recordsPerBlock_) * stride_);
        } else {
            // Evict the least recently used block.
            s = 0;
            for (std::size_t i = 1; i < slots_.size(); ++i)
                if (slots_[i].lastUse < slots_[s].lastUse) s = static_cast<std::int32_t>(i);
            slotOf_[slots_[s].block] = -1;
        }
        Slot& slot = slots_[s];
        slot.block = b;
        slotOf_[b] = s;
        const std::size_t want = slot.data.size() * sizeof(double);
        const off_t offset = static_cast<off_t>(b * recordsPerBlock_ * stride_ * 8);
        std::size_t got = 0;
        while (got < want) {
            const ssize_t n =
                ::pread(fd_, reinterpret_cast<char*>(slot.data.data()) + got, want - got,
                        offset + static_cast<off_t>(got));
            if (n < 0 && errno == EINTR) continue;
            if (n < 0) {
                slotOf_[b] = -1;
                slot.block = -1;
                IoFail(path_, "cannot read the spill file");
            }
            if (n == 0) break;
            got += static_cast<std::size_t>(n);
        }
        if (got < static_cast<std::size_t>(within + 1) * stride_ * 8) {
            slotOf_[b] = -1;
            slot.block = -1;
            HPRAY_CHECK_MSG(false, "record " << index << " is beyond the end of " << path_);
        }
    }
    Slot& slot = slots_[s];
    slot.lastUse = ++clock_;
    lastBlock_ = b;
    last_ = slot.data.data();
    return last_ + within * stride_;
}

}  // namespace hpray::partition
