// The processor's vector width, asked once (see lanes.h).
#include "util/lanes.h"

namespace hpray {

bool CpuHasAvx512() {
#if defined(__x86_64__) && defined(__GNUC__)
    static const bool has = [] {
        __builtin_cpu_init();  // idempotent; needed if asked before constructors ran
        return __builtin_cpu_supports("avx512f") != 0;
    }();
    return has;
#else
    return false;
#endif
}

}  // namespace hpray
