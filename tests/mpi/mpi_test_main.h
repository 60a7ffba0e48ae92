// The main of an MPI test binary: every rank runs every test, only rank 0 prints gtest's
// report, and the exit code is the worst over ranks. Include in exactly one file.
#pragma once

#include <gtest/gtest.h>
#include <mpi.h>

#include "util/mpi.h"

int main(int argc, char** argv) {
    hpray::mpi::Session session(&argc, &argv);
    hpray::mpi::EnsureInitialized();
    ::testing::InitGoogleTest(&argc, argv);
    if (hpray::mpi::WorldRank() != 0) {
        auto& listeners = ::testing::UnitTest::GetInstance()->listeners();
        delete listeners.Release(listeners.default_result_printer());
    }
    const int failed = RUN_ALL_TESTS();
    int anyFailed = 0;
    MPI_Allreduce(&failed, &anyFailed, 1, MPI_INT, MPI_MAX, MPI_COMM_WORLD);
    return anyFailed;
}
