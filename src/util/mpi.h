// The one MPI wrapper: threaded init, world rank/size, abort on a fatal error.
#pragma once

#include <string>

namespace hpray::mpi {

/// Initialises MPI at MPI_THREAD_FUNNELED or better (collective over MPI_COMM_WORLD).
/// Throws InternalError if the library cannot provide FUNNELED. Idempotent.
void Init(int* argc, char*** argv);
/// Finalises MPI if Init ran and Abort did not. Idempotent.
void Finalize();
bool Initialized();
/// Whether an MPI launcher (mpirun, mpiexec, srun) started this process: its environment
/// names a rank (OpenMPI, MPICH/Hydra, PMI, PMIx, MVAPICH).
bool LaunchedByMpi();
/// Initialises MPI now if it is not (a one-process job that needs collectives, such as a
/// partition rendered on one process). Must be called from the main thread.
void EnsureInitialized();
int WorldRank();
int WorldSize();
bool Root();
/// Ends the whole job: prints `message` prefixed by the rank, then MPI_Abort(code).
/// Used when one rank fails while others may be waiting in a collective.
[[noreturn]] void Abort(const std::string& message, int code);
/// MPI_Barrier on the world communicator.
void Barrier();

/// RAII: Init in the constructor when an MPI launcher started the process (a plain
/// one-process run starts MPI only if it needs it: EnsureInitialized), Finalize in the
/// destructor. Starting MPI without a launcher (a singleton) costs a few tenths of a
/// second, more than many renders.
class Session {
public:
    Session(int* argc, char*** argv) {
        if (LaunchedByMpi()) Init(argc, argv);
    }
    ~Session() { Finalize(); }
    Session(const Session&) = delete;
    Session& operator=(const Session&) = delete;
};

}  // namespace hpray::mpi
