// Dealing image tiles to ranks as they become free.
#pragma once

#include <mpi.h>

#include <algorithm>

#include "util/mpi.h"

namespace hpray::job {

/// Deals the tiles of an image out to ranks as they become free: a counter on rank 0
/// that every rank advances with an atomic one-sided fetch-and-add (MPI-3 passive target),
/// so no rank waits for another to hand out work. Collective to create and to destroy.
class TileDealer {
  public:
    TileDealer(int tiles, int chunk) : tiles_(tiles), chunk_(chunk) {
        MPI_Win_allocate(mpi::Root() ? sizeof(long long) : 0, sizeof(long long),
                         MPI_INFO_NULL, MPI_COMM_WORLD, &counter_, &window_);
        MPI_Win_lock_all(0, window_);
        if (mpi::Root()) {
            *counter_ = 0;
            MPI_Win_sync(window_);
        }
        MPI_Barrier(MPI_COMM_WORLD);
    }
    ~TileDealer() {
        MPI_Win_unlock_all(window_);
        MPI_Win_free(&window_);
    }
    TileDealer(const TileDealer&) = delete;
    TileDealer& operator=(const TileDealer&) = delete;

    /// The next chunk [begin, end) of tiles for this rank; false when all are dealt.
    bool Next(int& begin, int& end) {
        const long long add = chunk_;
        long long got = 0;
        MPI_Fetch_and_op(&add, &got, MPI_LONG_LONG, 0, 0, MPI_SUM, window_);
        MPI_Win_flush(0, window_);
        if (got >= tiles_) return false;
        begin = static_cast<int>(got);
        end = static_cast<int>(std::min<long long>(got + chunk_, tiles_));
        ++chunks_;
        return true;
    }
    int Chunks() const { return chunks_; }

  private:
    int tiles_, chunk_, chunks_ = 0;
    long long* counter_ = nullptr;
    MPI_Win window_ = MPI_WIN_NULL;
};

}  // namespace hpray::job
