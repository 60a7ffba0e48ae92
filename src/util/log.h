// Rank-prefixed logging: every line carries "[hpray rank R]"; Info prints on rank 0 only.
#pragma once

#include <sstream>
#include <string>

namespace hpray::log {

enum class Level { Quiet = 0, Error = 1, Warn = 2, Info = 3, Debug = 4 };

/// Set once at start-up (from --verbose / --quiet); default Info.
void SetLevel(Level level);
Level GetLevel();
/// The rank printed in the prefix; set by the MPI wrapper after init (default 0).
void SetRank(int rank);

/// Progress: printed by rank 0 only, to stderr.
void Info(const std::string& message);
/// Progress of long work (rank 0, Info level): on a terminal one line rewritten in place
/// (any other message, or EndProgress, ends it); otherwise a line like Info.
void Progress(const std::string& message);
/// Ends a progress line left open on the terminal.
void EndProgress();
/// Whether stderr is a terminal (progress is then worth updating often).
bool ProgressOnTerminal();
/// Printed by every rank, to stderr.
void Warn(const std::string& message);
void Error(const std::string& message);
void Debug(const std::string& message);

}  // namespace hpray::log
