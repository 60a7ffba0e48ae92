// The field of an affine Lagrange hexahedron at many points of one straight line: the
// samples from which the volume integrator builds the field's exact Legendre series along a
// ray segment. Register-blocked sum factorisation with explicit fused multiply-adds.
#pragma once

namespace hpray {

/// Most points one call takes (the exact series of order 10 needs 31).
inline constexpr int kMaxHexLineSamples = 64;

/// f at the points ref0 + t[s] dref (reference coordinates in [0, 1]^3), s < count <=
/// kMaxHexLineSamples, into out[s], for the Lagrange hexahedron of order p with nodal
/// values u in the internal order (i fastest, then j, then k). Returns false, writing
/// nothing, when this build has no kernel for it (orders 1 to 10 on AVX2 with FMA); the
/// caller then uses the library's evaluators (elements/tensor_eval.h), whose results
/// agree to rounding. Where the processor has AVX-512 the kernels use it unless
/// wideKernels is false (for tests: both give the same bits).
bool SampleAffineHexLine(int p, const double* u, const double ref0[3],
                         const double dref[3], const double* t, int count, double* out,
                         bool wideKernels = true);

}  // namespace hpray
