// Always-on CHECK macros (internal invariants; failures are bugs) and debug-only DCHECK.
#pragma once

#include <sstream>
#include <string>

#include "util/error.h"

namespace hpray::detail {
[[noreturn]] void CheckFailed(const char* file, int line, const std::string& message);

template <typename A, typename B>
[[noreturn]] void CheckOpFailed(const char* file, int line, const char* expr, const A& a,
                                const B& b) {
    std::ostringstream os;
    os << "CHECK failed: " << expr << " (" << a << " vs " << b << ")";
    CheckFailed(file, line, os.str());
}
}  // namespace hpray::detail

/// Throws hpray::InternalError naming file:line and the expression. Always on.
#define HPRAY_CHECK(cond)                                                              \
    do {                                                                               \
        if (!(cond)) ::hpray::detail::CheckFailed(__FILE__, __LINE__, "CHECK failed: " #cond); \
    } while (0)

#define HPRAY_CHECK_MSG(cond, msg)                                                     \
    do {                                                                               \
        if (!(cond)) {                                                                 \
            std::ostringstream hpray_os_;                                              \
            hpray_os_ << "CHECK failed: " #cond ": " << msg;                           \
            ::hpray::detail::CheckFailed(__FILE__, __LINE__, hpray_os_.str());         \
        }                                                                              \
    } while (0)

#define HPRAY_CHECK_OP_(a, b, op)                                                      \
    do {                                                                               \
        const auto& hpray_a_ = (a);                                                    \
        const auto& hpray_b_ = (b);                                                    \
        if (!(hpray_a_ op hpray_b_))                                                   \
            ::hpray::detail::CheckOpFailed(__FILE__, __LINE__, #a " " #op " " #b,      \
                                           hpray_a_, hpray_b_);                        \
    } while (0)

#define HPRAY_CHECK_EQ(a, b) HPRAY_CHECK_OP_(a, b, ==)
#define HPRAY_CHECK_NE(a, b) HPRAY_CHECK_OP_(a, b, !=)
#define HPRAY_CHECK_LT(a, b) HPRAY_CHECK_OP_(a, b, <)
#define HPRAY_CHECK_LE(a, b) HPRAY_CHECK_OP_(a, b, <=)
#define HPRAY_CHECK_GT(a, b) HPRAY_CHECK_OP_(a, b, >)
#define HPRAY_CHECK_GE(a, b) HPRAY_CHECK_OP_(a, b, >=)

#ifdef NDEBUG
#define HPRAY_DCHECK(cond) do { } while (0)
#else
#define HPRAY_DCHECK(cond) HPRAY_CHECK(cond)
#endif
