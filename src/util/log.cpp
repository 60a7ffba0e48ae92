// Rank-prefixed logging to stderr; a mutex keeps lines whole across threads.
#include "util/log.h"

#include <atomic>
#include <cstdio>
#include <mutex>

#include <unistd.h>

namespace hpray::log {
namespace {
std::atomic<int> gLevel{static_cast<int>(Level::Info)};
std::atomic<int> gRank{0};
std::mutex gMutex;
bool gProgressOpen = false;  // a progress line on the terminal awaits its end (gMutex)

void Emit(const char* tag, const std::string& message) {
    std::lock_guard<std::mutex> lock(gMutex);
    if (gProgressOpen) std::fputc('\n', stderr);
    gProgressOpen = false;
    std::fprintf(stderr, "[hpray rank %d] %s%s\n", gRank.load(), tag, message.c_str());
    std::fflush(stderr);
}
}  // namespace

bool ProgressOnTerminal() {
    static const bool terminal = isatty(fileno(stderr)) != 0;
    return terminal;
}

void Progress(const std::string& m) {
    if (gLevel < static_cast<int>(Level::Info) || gRank != 0) return;
    if (!ProgressOnTerminal()) return Emit("", m);
    std::lock_guard<std::mutex> lock(gMutex);
    // One line, rewritten in place: carriage return, the text, clear to its end.
    std::fprintf(stderr, "\r[hpray rank %d] %s\033[K", gRank.load(), m.c_str());
    std::fflush(stderr);
    gProgressOpen = true;
}

void EndProgress() {
    std::lock_guard<std::mutex> lock(gMutex);
    if (gProgressOpen) std::fputc('\n', stderr);
    gProgressOpen = false;
}

void SetLevel(Level level) { gLevel = static_cast<int>(level); }
Level GetLevel() { return static_cast<Level>(gLevel.load()); }
void SetRank(int rank) { gRank = rank; }

void Info(const std::string& m) {
    if (gLevel >= static_cast<int>(Level::Info) && gRank == 0) Emit("", m);
}
void Warn(const std::string& m) {
    if (gLevel >= static_cast<int>(Level::Warn)) Emit("warning: ", m);
}
void Error(const std::string& m) {
    if (gLevel >= static_cast<int>(Level::Error)) Emit("error: ", m);
}
void Debug(const std::string& m) {
    if (gLevel >= static_cast<int>(Level::Debug)) Emit("debug: ", m);
}
}  // namespace hpray::log
