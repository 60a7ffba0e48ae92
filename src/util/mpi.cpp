// MPI wrapper implementation (the only file in src/util that includes <mpi.h>).
#include "util/mpi.h"

#include <mpi.h>

#include <cstdio>
#include <cstdlib>

#include "util/error.h"
#include "util/log.h"

namespace hpray::mpi {
namespace {
bool gInitializedHere = false;
}

void Init(int* argc, char*** argv) {
    int already = 0;
    MPI_Initialized(&already);
    if (already) return;
    int provided = MPI_THREAD_SINGLE;
    MPI_Init_thread(argc, argv, MPI_THREAD_FUNNELED, &provided);
    gInitializedHere = true;
    if (provided < MPI_THREAD_FUNNELED)
        Abort("MPI library provides less than MPI_THREAD_FUNNELED", 1);
    log::SetRank(WorldRank());
}

bool LaunchedByMpi() {
    for (const char* name : {"OMPI_COMM_WORLD_SIZE", "PMI_RANK", "PMI_SIZE", "PMIX_RANK",
                             "MPI_LOCALNRANKS", "MV2_COMM_WORLD_SIZE"})
        if (std::getenv(name) != nullptr) return true;
    return false;
}

void EnsureInitialized() {
    if (!Initialized()) Init(nullptr, nullptr);
}

void Finalize() {
    int finalized = 0;
    MPI_Finalized(&finalized);
    if (gInitializedHere && !finalized) MPI_Finalize();
    gInitializedHere = false;
}

bool Initialized() {
    int init = 0, fin = 0;
    MPI_Initialized(&init);
    MPI_Finalized(&fin);
    return init && !fin;
}

int WorldRank() {
    if (!Initialized()) return 0;
    int r = 0;
    MPI_Comm_rank(MPI_COMM_WORLD, &r);
    return r;
}

int WorldSize() {
    if (!Initialized()) return 1;
    int s = 1;
    MPI_Comm_size(MPI_COMM_WORLD, &s);
    return s;
}

bool Root() { return WorldRank() == 0; }

void Abort(const std::string& message, int code) {
    std::fprintf(stderr, "[hpray rank %d] fatal: %s\n", WorldRank(), message.c_str());
    std::fflush(stderr);
    if (Initialized() && WorldSize() > 1) MPI_Abort(MPI_COMM_WORLD, code);
    std::exit(code);
}

void Barrier() {
    if (Initialized()) MPI_Barrier(MPI_COMM_WORLD);
}

}  // namespace hpray::mpi
