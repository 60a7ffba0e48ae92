// MPI smoke test: threaded init, rank/size, a collective, rank-aware logging.
#include <gtest/gtest.h>
#include <mpi.h>

#include "util/log.h"
#include "util/mpi.h"
#include "mpi/mpi_test_main.h"

namespace {

TEST(MpiSmoke, RanksSumAndThreadLevel) {
    const int rank = hpray::mpi::WorldRank(), size = hpray::mpi::WorldSize();
    ASSERT_GE(size, 2) << "run this test with mpiexec -n 2 or more";
    int provided = 0;
    MPI_Query_thread(&provided);
    EXPECT_GE(provided, MPI_THREAD_FUNNELED);
    long long mine = rank + 1, total = 0;
    MPI_Allreduce(&mine, &total, 1, MPI_LONG_LONG, MPI_SUM, MPI_COMM_WORLD);
    EXPECT_EQ(total, static_cast<long long>(size) * (size + 1) / 2);
    EXPECT_EQ(hpray::mpi::Root(), rank == 0);
}

}  // namespace
