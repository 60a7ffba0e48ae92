// Legendre series at many points in AVX2 registers: the evaluations of the exact field
// series at a volume piece's quadrature nodes.
#pragma once

#include "render/legendre.h"

namespace hpray {

/// EvalPair (render/legendre.h) of p and q at t[s], s < count, into outP[s] and outQ[s],
/// with the points' recurrences in vector registers (eight at a time). Bitwise the same
/// values as EvalPair: the same operations in the same order, each rounded once. Returns
/// false, writing nothing, where this build has no kernel (AVX2 with FMA) or the degree
/// exceeds EvalPair's; the caller then uses EvalPair.
bool EvalPairKernel(const LegendreSeries& p, const LegendreSeries& q, const double* t,
                    int count, double* outP, double* outQ);

/// The same for one series (LegendreSeries::EvalMany).
bool EvalManyKernel(const LegendreSeries& p, const double* t, int count, double* out);

/// EvalPairKernel and EvalManyKernel on whole blocks of eight points: t, outP, outQ and
/// out hold count rounded up to a multiple of 8 entries, all read and written (each
/// point's values depend on it alone: those of the first count are the same).
bool EvalPairKernelWhole(const LegendreSeries& p, const LegendreSeries& q,
                         const double* t, int count, double* outP, double* outQ);
bool EvalManyKernelWhole(const LegendreSeries& p, const double* t, int count,
                         double* out);

}  // namespace hpray
