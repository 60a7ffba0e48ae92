// MPI smoke test: threaded init, rank/size, a collective, rank-aware logging.
#include <gtest/gtest.h>
#include <mpi.h>

#include "util/log.h"
#include "util/mpi.h"

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

int main(int argc, char** argv) {
    hpray::mpi::Session session(&argc, &argv);
    ::testing::InitGoogleTest(&argc, argv);
    // Only rank 0 prints gtest's report; every rank runs the tests.
    if (hpray::mpi::WorldRank() != 0) {
        auto& listeners = ::testing::UnitTest::GetInstance()->listeners();
        delete listeners.Release(listeners.default_result_printer());
    }
    int failed = RUN_ALL_TESTS();
    int anyFailed = 0;
    MPI_Allreduce(&failed, &anyFailed, 1, MPI_INT, MPI_MAX, MPI_COMM_WORLD);
    return anyFailed;
}
