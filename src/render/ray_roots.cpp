// Non-template parts of the ray root finder.
#include "render/ray_roots.h"

namespace hpray::detail {

double TailExcluded(const LegendreSeries& q, double C) {
    return std::abs(q.c[0] - C) - q.Tail();
}

}  // namespace hpray::detail
