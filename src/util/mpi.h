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
int WorldRank();
int WorldSize();
bool Root();
/// Ends the whole job: prints `message` prefixed by the rank, then MPI_Abort(code).
/// Used when one rank fails while others may be waiting in a collective.
[[noreturn]] void Abort(const std::string& message, int code);
/// MPI_Barrier on the world communicator.
void Barrier();

/// RAII: Init in the constructor, Finalize in the destructor.
class Session {
public:
    Session(int* argc, char*** argv) { Init(argc, argv); }
    ~Session() { Finalize(); }
    Session(const Session&) = delete;
    Session& operator=(const Session&) = delete;
};

}  // namespace hpray::mpi
