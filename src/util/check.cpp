// Out-of-line failure path of the CHECK macros.
#include "util/check.h"

namespace hpray::detail {
void CheckFailed(const char* file, int line, const std::string& message) {
    std::ostringstream os;
    os << file << ":" << line << ": " << message;
    throw InternalError(os.str());
}
}  // namespace hpray::detail
