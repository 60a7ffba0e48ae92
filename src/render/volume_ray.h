// Volume integration along one ray: per-cell classification (empty / constant / varying)
// from guaranteed field ranges, transfer-function breakpoints found on the true field,
// closed forms where the fields are linear along the ray; where they are polynomials
// along the ray (affine cells), the optical depth in closed form from the Legendre series
// and the emission by adaptive Gauss-Kronrod pairs to the tolerance; elsewhere adaptive
// Gauss-Kronrod on the true field; a per-pixel error estimate; early ray termination.
#pragma once

#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "elements/bounds.h"
#include "elements/mesh_geometry.h"
#include "render/field_cache.h"
#include "render/ray_field.h"
#include "render/ray_roots.h"
#include "render/stats.h"
#include "render/volume.h"
#include "scene/scene.h"
#include "trace/brick_traverser.h"
#include "trace/ray.h"

namespace hpray {

/// The volume of a scene prepared for one brick; built once, shared read-only by threads.
struct VolumeSetup {
    GlowModel glow = GlowModel::WilliamsMax;
    PiecewiseLinearTf colorTf;       ///< 3 channels: chromaticity or glow per world unit
    PiecewiseLinearTf extinctionTf;  ///< 1 channel: extinction per world unit
    /// The control points of both transfer functions, ascending, without repeats.
    std::vector<double> breakpoints;
    ShortAscending shortBreakpoints;  ///< breakpoints, for fixed-length counts
    /// fields[0] drives colour, fields[1] extinction; sameField: both are fields[0].
    ScalarSelector fields[2];
    bool sameField = true;
    /// Guaranteed range of each field per cell ([field][cell]; one entry when sameField),
    /// shared with the FieldCache.
    std::vector<std::shared_ptr<const std::vector<Interval>>> ranges;
    /// Nodal values of each field gathered per cell (point fields; null for cell
    /// fields), shared with the FieldCache.
    std::vector<std::shared_ptr<const FieldCellData>> data;
    /// Per field and cell, for Lagrange hexahedra of order p (else empty or 0): |c| / |l|
    /// where c is the coefficient of y1^p y2^p y3^p of the field in the Legendre variables
    /// y = 2 ref - 1 of the cell and l the leading coefficient of P_3p. Along a segment
    /// whose y move by dy_d over its Legendre variable, the field's series has the degree
    /// 3p coefficient c dy1^p dy2^p dy3^p / l, the only one of that degree.
    std::vector<std::vector<double>> topCoefficient;
    /// Per field, for Lagrange hexahedra (else empty): degreeTail[f][tailStride * c + m]
    /// for m = 0..3p bounds the sum of |a_ijk| over i + j + k > m, where a_ijk are the
    /// coefficients of the field in the products P_i(y1) P_j(y2) P_k(y3) of Legendre
    /// polynomials in the cell's y = 2 ref - 1 (the long-double transform's rounding
    /// added). Along any segment in the cell the part of the field of total degree above
    /// m is at most that in magnitude (|P_k| <= 1 on [-1, 1]) and the rest is a
    /// polynomial of degree m in t, so interpolation at degree m misses at most (1 + the
    /// Lebesgue constant) times degreeTail: the volume samples a segment at the lowest
    /// degree whose miss fits its share of volume_tolerance.
    std::vector<std::vector<double>> degreeTail;
    int tailStride = 0;
    std::vector<double> fieldScale;  ///< max |value| of each field over the mesh
    /// Per point field: its value at each point of the mesh (data[f]->PointValues()),
    /// for linear tetrahedra integrated from the traversal's face points; null for a cell
    /// field.
    const double* pointValues[2] = {nullptr, nullptr};
    /// Per point field with pointValues and cell, for linear tetrahedra (derived
    /// geometry; else NaN, and empty without such cells): a bound of the Euclidean norm
    /// of the field's gradient (world units), rounded up, or NaN for a tetrahedron too
    /// flat to bound it (|det| <= 1e-6 of the product of its edge rows). It turns how far
    /// a face point lies off the ray into an error of the field value there.
    std::shared_ptr<const std::vector<float>> gradientBound[2];  ///< from the FieldCache

    /// Per cell, from the ranges: nothing to integrate (extinction zero and, for
    /// Wilhelms-Van Gelder, glow zero), both transfer functions constant over the range
    /// (closed form without evaluating the field), or general.
    enum CellKind : std::uint8_t { kEmpty = 0, kConstant = 1, kVarying = 2 };
    std::vector<std::uint8_t> cellKind;

    /// eps_V: target absolute error of a pixel's RGB.
    double tolerance = 1e-10;
    /// Largest colour value (chromaticity or glow): bounds what lies behind a point.
    double colorMax = 0;
    /// Largest |slope| of the transfer functions (per unit of their field): how an error
    /// of the field values becomes an error of extinction and colour.
    double extinctionSlope = 0, colorSlope = 0;
    double mappingTolerance = 1e-12;

    ProjectionOptions projection;
    RootOptions roots;
    InversionOptions inversion;
};

/// Every t in (p.a, p.b) where the polynomial series p crosses one of the sorted
/// `levels` (count of them), appended to `out`: p is split at its critical points (the
/// roots of p', isolated on its series, which misses no sign change of p' larger than
/// its rounding), and on each monotone interval between them a level strictly between
/// the end values is crossed once, polished by safeguarded Newton to `tol` in t, started
/// from the samples (sampleT ascending, sampleV of the field there; samples may be 0)
/// where they change sides. `scratch`, `points` and `derivative` are caller-owned buffers.
void SeriesCrossings(const LegendreSeries& p, const double* levels, int count, double tol,
                     const double* sampleT, const double* sampleV, int samples,
                     std::vector<double>& scratch, std::vector<double>& points,
                     LegendreSeries& derivative, std::vector<double>& out);

/// VolumeSetup::degreeTail of one Lagrange hexahedron of order p (1..kMaxOrder) from its
/// nodal values u (lattice order of mesh/cell.h, i fastest): tail[m] for m = 0..3p.
void LagrangeHexDegreeTail(int p, const double* u, double* tail);

/// The colour transfer function of a scene (`volume.color_tf`, `slices.#.color_tf`).
PiecewiseLinearTf MakeColorTf(const std::vector<ColorControlPoint>& points);

/// Resolves the volume fields of `scene.volume` (InputError naming the scene and the key
/// if a field is missing), takes their per-cell ranges from `cache` (computed there the
/// first time a field is used) and classifies the cells for the transfer functions
/// (parallel).
VolumeSetup MakeVolumeSetup(const Mesh& mesh, const Scene& scene, FieldCache& cache);

/// VolumeSetup::gradientBound of the linear tetrahedron whose corners are points[3 id]
/// for the four `ids`, with field values u[id].
float LinearTetGradientBound(const double* points, const double* u,
                             const std::int64_t* ids);

/// Front-to-back compositing state of one ray: premultiplied colour and opacity (rgba),
/// transmittance, and the error bookkeeping of the volume integration.
struct RayComposite {
    double* rgba = nullptr;  ///< the pixel's premultiplied RGBA, updated in place
    double transmittance = 1;
    double error[3] = {0, 0, 0};  ///< estimated absolute error of R, G, B so far
    /// Signed estimates of quadrature errors (truth minus result) of R, G, B so far, whose
    /// magnitude VolumeRayMarcher::FinishRay adds to `error` (their uncertainty is in
    /// `error` already): errors of opposite signs along the ray cancel in the estimate
    /// as they do in the pixel.
    double signedError[3] = {0, 0, 0};
    /// Estimated absolute error of the optical depth integrated so far: every later
    /// contribution c carries an error of about |c| times this.
    double depthError = 0;

    /// Adds premultiplied colour `rgb` (already times the transmittance) with its
    /// propagated depth error.
    void AddColor(const double rgb[3]) {
        for (int c = 0; c < 3; ++c) {
            rgba[c] += rgb[c];
            error[c] += std::abs(rgb[c]) * depthError;
        }
    }
};

/// out[i] = exp(-x[i]) for x[i] >= 0 (0 beyond 708), to within 3 ulps (the series
/// pieces' quadrature nodes; four at a time where the build has AVX2).
void ExpNegative(const double* x, int n, double* out);

/// A series piece's opacity 1 - e^-d and attenuation e^-d (d >= 0) with at most one
/// exponential: below d = 0.5, d times the Taylor series of (1 - e^-d) / d to degree 16
/// (the next term below 2e-20 of the sum) by Estrin's scheme (five multiply-adds deep,
/// where Horner's rule waits for sixteen), and the attenuation 1 - opacity (>= 0.6);
/// above, the attenuation by exp and the opacity 1 - it (>= 0.39). Each within 3 ulps.
void PieceOpacity(double d, double& opacity, double& attenuation);

/// out[i] = ln(x[i]) for positive normal x[i], within 2 eps of its larger of 1 and |ln
/// x[i]| (a linear pyramid's optical depth at the series pieces' quadrature nodes; four
/// at a time where the build has AVX2).
void NaturalLog(const double* x, int n, double* out);

/// An affine linear hexahedron's or wedge's field along a segment [mid - half, mid +
/// half] as its polynomial (SegmentField::LinearCellLine, degree 3 or 2): f = m0 + m1 x +
/// m2 x^2
/// + m3 x^3 at x = (t - mid) / half, and V = half (m1 x^2 / 2 + m2 x^3 / 3 + m3 x^4 / 4),
/// the antiderivative in t of f - m0 (the series pieces' depth line).
struct PolyLine {
    double mid = 0, half = 0, inverseHalf = 0;
    double m[4] = {0, 0, 0, 0};
    double AtX(double x) const { return ((m[3] * x + m[2]) * x + m[1]) * x + m[0]; }
    double At(double t) const { return AtX((t - mid) * inverseHalf); }
};
/// The field at the n points t (out) and, where depth is not null, V there (depth): four
/// at a time in vector lanes where the build has AVX2 (each value independent of n).
void PolyLineAt(const PolyLine& p, const double* t, int n, double* out, double* depth);
/// The PolyLine on [t0, t1] of mono[0..degree] (degree <= 3; monomials in x).
PolyLine MakePolyLine(double t0, double t1, const double* mono, int degree);
/// The real roots of a x^2 + b x + c by the stable formula (a linear equation where a =
/// 0), into out in no order (a double root twice); their count.
int QuadraticRoots(double a, double b, double c, double out[2]);
/// The distinct roots of a x^2 + b x + c strictly inside (-1, 1), ascending, into out;
/// their count.
int QuadraticRootsInside(double a, double b, double c, double out[2]);
/// The critical points of p's polynomial inside (-1, 1) (x, ascending) into out; their
/// count.
int PolyCriticalPoints(const PolyLine& p, double out[2]);
/// Appends to `out` the t in (tEnter, tExit) where p's field equals `level`: the
/// polynomial's monotone stretches between its critical points (the derivative's roots in
/// closed form), each holding at most one root, found by Newton's method within its
/// bracket.
void PolyLevelCrossings(const PolyLine& p, double level, double tEnter, double tExit,
                        std::vector<double>& out);

/// A linear pyramid's field along a segment in closed form (PyramidLine) as the volume
/// integrates it: the antiderivative in t of the field less `mean`, V = half (a2 x^2 + g
/// ln(1 + rho x)) at x = (t - mid) / half (the basis' R S / U in partial fractions), and
/// bounds of the rounding.
struct PyramidDepthLine {
    double a2 = 0, g = 0, rho = 0, mean = 0;
    double depthError = 0;  ///< of V anywhere on the segment (the mean's error included)
    double fieldError = 0;  ///< of PyramidLine::At (and PyramidLineAt) against the field
};
/// The depth line of `p` and its bounds (cellScale: the largest |value| of the field in
/// the cell; sumV: the sum of the |nodal values|). False where the closed form is not to
/// be used: no twist (a quadratic), the pole more than 63 half-lengths or less than
/// 1/1024 of one beyond the segment, or the bounds above about what a series' rounding
/// comes to.
bool MakePyramidDepthLine(const PyramidLine& p, double cellScale, double sumV,
                          PyramidDepthLine& out);
/// The field at the n points t (out) and, where depth is not null, V there (depth): four
/// at a time in vector lanes where the build has AVX2 (each value independent of n).
void PyramidLineAt(const PyramidLine& p, const PyramidDepthLine& d, const double* t,
                   int n, double* out, double* depth);
/// Appends to `out` the t in (tEnter, tExit) where p's field equals `level`: the roots of
/// a quadratic (U > 0 on the segment), polished on its product form.
void PyramidLevelCrossings(const PyramidLine& p, double level, double tEnter,
                           double tExit, std::vector<double>& out);

/// A sliver that a clip plane through a face leaves at an end of the ray's span [tMin,
/// tMax]: a segment at most sliverLength long that starts at tMin or ends at tMax. It
/// holds nothing visible (sliverLength is about 1e-12 of the mesh size) but would cost as
/// much as a whole segment, so the renderer skips it.
inline bool IsSpanEndSliver(const Segment& seg, double sliverLength, double tMin,
                            double tMax) {
    return seg.tExit - seg.tEnter <= sliverLength &&
           (seg.tEnter == tMin || seg.tExit == tMax);
}

/// Per-thread volume integrator: reused across rays and segments without allocation once
/// its buffers have grown.
class VolumeRayMarcher {
  public:
    /// Starts a ray whose segments inside the mesh span [tStart, tEnd] (world t).
    void BeginRay(const VolumeSetup& setup, const Ray& ray, double tStart, double tEnd);

    /// Prepares segment `seg` (cell, tEnter, tExit) of the current ray: the volume fields
    /// along it and their transfer-function breakpoints. Returns false when the cell
    /// holds nothing to integrate (empty-space skipping: no field is evaluated).
    /// `ends` (optional): the face points where the ray enters and leaves the cell; for a
    /// linear tetrahedron with Valid ones, the fields along the segment come from the
    /// face values there (no access to the cell's nodes).
    bool BeginSegment(const Mesh& mesh, const MeshGeometry& geometry, const Segment& seg,
                      RenderCounters& counters, const SegmentEnds* ends = nullptr);

    /// Integrates [a, b] (inside the current segment) into `composite`. Returns true when
    /// the ray may stop: the transmittance fell so low that everything behind changes the
    /// pixel by less than a tenth of the tolerance (that bound is added to the error).
    bool Integrate(double a, double b, RayComposite& composite, RenderCounters& counters);

    /// What LinearTet did with a segment.
    enum class LinearTetResult : std::uint8_t {
        kOther,  ///< not such a segment: nothing changed (BeginSegment, Integrate)
        kEmpty,  ///< the cell holds nothing to integrate
        kGoOn,   ///< integrated; the ray goes on
        kStop    ///< integrated; the ray may stop (as Integrate's true)
    };
    /// BeginSegment and Integrate(seg.tEnter, seg.tExit) in one, for the common segment
    /// of a large linear mesh: a linear tetrahedron with Valid face points `ends`, in a
    /// volume whose colour and extinction come from one point field, or a cell whose
    /// transfer functions are constant or empty over its range. The same arithmetic as
    /// those two calls (bitwise the same pixel), without their general cases.
    LinearTetResult LinearTet(const MeshGeometry& geometry, const Segment& seg,
                              const SegmentEnds& ends, RayComposite& composite);
    /// The cells where an isosurface may lie: its field's guaranteed range in the cell
    /// holds its value (the renderer's test for a segment's isosurface sources).
    struct IsoCells {
        static constexpr int kMax = 8;
        int count = 0;
        const Interval* ranges[kMax] = {};  ///< per isosurface, its field's cell ranges
        double values[kMax] = {};
        bool Holds(std::int64_t cell) const {
            for (int k = 0; k < count; ++k) {
                const Interval& r = ranges[k][cell];
                if (values[k] >= r.lo && values[k] <= r.hi) return true;
            }
            return false;
        }
    };
    /// LinearTet on the segments first, first + 1, ... (< last) of the ray in one loop,
    /// as long as each is such a segment, in no cell of `isoCells` (null: none), and the
    /// ray goes on. Slivers at the span's ends (IsSpanEndSliver) and empty cells are
    /// skipped and counted in `culled`.
    struct LinearTetRunResult {
        std::size_t next;  ///< the first segment not taken (kOther), or last
        bool stop;         ///< LinearTet said kStop for segment next - 1
        bool seen;         ///< some segment was integrated
        double culled;
    };
    LinearTetRunResult LinearTetRun(const MeshGeometry& geometry, const Segment* segs,
                                    const SegmentEnds* ends, std::size_t first,
                                    std::size_t last, double sliverLength, double tMin,
                                    double tMax, const IsoCells* isoCells,
                                    RayComposite& composite);
    /// Segments LinearTetRun took in groups of up to four (LinearTetGroup), since
    /// construction.
    std::int64_t GroupedSegments() const { return groupedSegments_; }
    /// LinearTet queues the pieces of its segments and composites them in batches; this
    /// composites what is queued. Call it before any other segment is integrated and
    /// before FinishRay. True when the ray may stop (as Integrate's true); the rest of
    /// the queue is then dropped.
    bool FlushLinearTets(RayComposite& composite);

    /// Ends the ray: adds to the error the signed quadrature estimates and the
    /// first-order effect of rounding in the ray's entry and exit parameters (a few ulps
    /// of t).
    void FinishRay(RayComposite& composite) const;

    /// Statistics of the last ray.
    int KronrodIntervals() const { return kronrodIntervals_; }

  private:
    struct FieldState {
        bool constant = false;  ///< cell field: value fixed on the cell
        bool linear = false;    ///< value linear in t on the segment
        bool bySeries = false;  ///< exact Legendre series available (affine polynomial)
        bool pyramid = false;   ///< a linear pyramid's field in closed form (pyramid_)
        bool poly = false;      ///< an affine linear hex's or wedge's polynomial (poly_)
        double valueEnter = 0, valueExit = 0;  ///< at tEnter and tExit (linear fields)
        double error = 0;  ///< bound of the absolute error of the values on the segment
    };
    /// How the pieces of the current segment are integrated.
    enum class Mode : std::uint8_t {
        kClosed,  ///< transfer functions constant, or every field linear: closed form
        kSeries,  ///< every field a polynomial along the ray, held as a series
        kGeneric  ///< adaptive Gauss-Kronrod on the true field
    };
    /// Error terms of a piece of a varying cell, of length `length` and optical depth
    /// `depth` at transmittance T, extinction >= tauMin on it: the field errors through
    /// the transfer functions' slopes (`colorSlope`, `tauSlope`: |d value / d field| on
    /// the piece), into the colour error and the depth error.
    void AddFieldError(double length, double depth, double tauMin, double T,
                       double colorSlope, double tauSlope, RayComposite& composite) const;
    /// AddFieldError's term of each channel's error, before the transmittance T.
    double FieldErrorOwn(double length, double depth, double tauMin, double colorError,
                         double tauError) const;
    /// Records the emission density at the ray's ends (for FinishRay).
    void RecordEnds(double p0, double p1, double tau0, const double e0[3], double tau1,
                    const double e1[3], double transmittanceAtP1);
    double FieldAt(int f, double t);
    void Sample(double t, double& tau, double emission[3]);
    void LinearPiece(double p0, double p1, RayComposite& composite);
    /// Queues LinearPiece(p0, p1) of LinearTet's current segment: a varying cell (one
    /// linear field drives both transfer functions) or a constant one.
    void QueueLinearTetPiece(double p0, double p1, bool varying);
    /// A linear piece before its closed form and compositing: LinearPiece's own, or one
    /// that LinearTet queued (the colours clamped at 0).
    struct QueuedPiece {
        double p0, p1, length, tau0, tau1, c0[3], c1[3];
        double colorError, tauError;  ///< field errors through the transfer functions
        bool varying;
    };
    /// Fills `piece` from its ends and its transfer-function values there (clamped at 0,
    /// as LinearPiece does); colorError and tauError are 0 unless varying (the caller
    /// sets them).
    static void SetPiece(QueuedPiece& piece, double p0, double p1, bool varying,
                         double tau0, double tau1, const double c0[3],
                         const double c1[3]);
    /// LinearPiece's compositing of `piece` with its closed form q: emission, error
    /// terms, transmittance, the ray's end emissions.
    void CompositeLinearPiece(const QueuedPiece& piece, const LinearPieceIntegrals& q,
                              RayComposite& composite);
    /// What LinearTetGroup did: the segments it took (0: nothing done), and whether the
    /// ray stopped (after segment taken - 1, or at 0 before any of them).
    struct GroupResult {
        int taken;
        bool stop;
    };
    /// Up to four consecutive segments of a run (segs[0..3], ends[0..3]) as LinearTet
    /// takes them, in SIMD lanes where the build has AVX2, each lane bitwise LinearTet:
    /// the segments before the first that is not a varying linear tetrahedron (no
    /// sliver, not in isoCells) with valid face points and a gradient bound whose field
    /// passes no breakpoint of the transfer functions (one piece each). Their pieces are
    /// queued as LinearTet queues them.
    GroupResult LinearTetGroup(const MeshGeometry& geometry, const Segment* segs,
                               const SegmentEnds* ends, double sliverLength, double tMin,
                               double tMax, const IsoCells* isoCells,
                               RayComposite& composite);
    std::int64_t groupedSegments_ = 0;
    /// Queued pieces beyond which LinearTet and LinearTetGroup composite: whole batches
    /// of eight closed forms where the processor has AVX-512 (IntegrateLinearPieces).
    static constexpr std::size_t kQueuedPieces = 16;
    std::vector<QueuedPiece> queue_;  ///< the first queued_ are queued
    std::size_t queued_ = 0;
    std::vector<LinearPieceIntegrals> pieceIntegrals_;
    void KronrodPiece(double p0, double p1, RayComposite& composite);
    void SeriesPiece(double p0, double p1, RayComposite& composite);
    /// How SeriesPieceOf's fields are held: as series (linePtr_), as pyramid_
    /// (BeginPyramidLine) or as poly_ (BeginPolyLine).
    enum LineKind { kSeriesLine, kPyramidLine, kPolyLine };
    /// SeriesPiece for Williams-Max glow (wm) or not, one field (oneField) or two, and
    /// the fields held as `line` says.
    template <bool wm, bool oneField, int line = kSeriesLine>
    void SeriesPieceOf(double p0, double p1, RayComposite& composite);
    /// SeriesPieceOf for the glow model and field count in use.
    template <int line>
    void SeriesPieceFor(double p0, double p1, RayComposite& composite);
    /// Series mode for an affine linear hexahedron's or wedge's field f (for two fields,
    /// as BeginPyramidLine), without a series: its polynomial along the segment (poly_,
    /// monomials in x), the depth line its antiderivative, the crossings of the
    /// breakpoints PolyLevelCrossings'; the rounding bounds as the series'. With one
    /// field, sets it linear instead where the terms above degree 1 are within that
    /// rounding.
    /// False where the cell is not such a one (or the projection is pinned).
    bool BeginPolyLine(int f, const Segment& seg);
    /// Series mode for a linear pyramid's field f (for two fields, both the same kind:
    /// BeginSegment makes series of them otherwise), without a series: the field in
    /// closed form (pyramid_), its optical depth's antiderivative from partial fractions,
    /// the breakpoints' crossings as roots of quadratics, each with a bound of its
    /// rounding. False (fall back to the series) where that bound would exceed the
    /// series' own, or the pole is far (the series is short there) or within 1/1024 of
    /// the segment.
    bool BeginPyramidLine(int f, const Segment& seg);
    /// The crossings of the breakpoints in the cell's range by field f held in closed
    /// form (poly_[f] or pyramid_[f]) into crossings_.
    void ClosedLineCrossings(int f, const Segment& seg);
    bool Terminate(double t, RayComposite& composite);
    /// Field f (a point field) along a linear tetrahedron's segment from the face points
    /// `ends`: its values at the segment's ends and the bound of their error. False (and
    /// nothing set) for a tetrahedron too flat to bound that error in the ray frame.
    bool LinearFromFacePoints(int f, const SegmentEnds& ends);
    void FindCrossings(int f, const Segment& seg, RenderCounters& counters);
    /// constTau_ and constColor_ of a cell whose transfer functions are constant over its
    /// ranges.
    void BeginConstantCell(std::int64_t cell);
    /// FindCrossings of a linear field f (state_[f].linear).
    void LinearCrossings(int f, const Segment& seg);
    /// The control points of the transfer functions field f drives, ascending, and the
    /// span [first, last) of them that may lie in (lo, hi): exactly those where the list
    /// is short enough to count them (ShortAscending), else the whole list.
    struct BreakpointSpan {
        const std::vector<double>& points;
        std::size_t first, last;
    };
    BreakpointSpan BreakpointsIn(int f, double lo, double hi) const;
    /// The exact Legendre series of field f (a polynomial along the ray) on the segment
    /// into pieces_[f].
    void ProjectExact(int f, const MeshGeometry& geometry, const Segment& seg);
    /// The series of a field that is the polynomial mono[0..n] (monomials in x in [-1, 1]
    /// over the segment, n <= 3; every term at most `magnitude`) along the segment, kept
    /// as SeriesFromSamples keeps a sampled one.
    void SeriesFromPolynomial(int f, const Segment& seg, int n, const double* mono,
                              double magnitude);
    /// Drops the trailing coefficients of an exact series of field f whose sum is at the
    /// level of its rounding (kTruncation eps of the cell's largest |value|), keeping
    /// their sum in truncated_[f].
    void DropNoiseTail(int f, const Segment& seg, std::vector<double>& c);
    /// How many of c[0..size) DropNoiseTail keeps (the sum of the others into
    /// truncated_[f]).
    int KeptCoefficients(int f, const Segment& seg, const double* c, int size);
    /// The series of field f on the segment from the values at the n + 1 Legendre-Gauss-
    /// Lobatto nodes in samples_[f] (values, then the nodes' t): pieces_[f], its rounding
    /// as eps, trailing coefficients below the noise dropped into truncated_[f].
    void SeriesFromSamples(int f, const Segment& seg, int n);
    /// A linear pyramid's field (SegmentField::RationalPole) as one series whose miss,
    /// bounded from the pole, is below the noise ProjectExact drops: pieces_[f], with the
    /// miss in its eps and unresolved_[f]. False (nothing set) where that needs a degree
    /// above kMaxRationalDegree.
    bool ProjectRational(int f, const Segment& seg, double gap, double residue);
    /// pieces_[f] (empty when a segment begins) as one piece, for an exact series.
    ProjectedPiece& OnlyPiece(int f) {
        std::vector<ProjectedPiece>& pieces = pieces_[f];
        if (pieces.empty())
            pieces.emplace_back();
        else
            pieces.resize(1);
        return pieces[0];
    }

    const VolumeSetup* setup_ = nullptr;
    Ray ray_;
    double tStart_ = 0, tEnd_ = 0, pathLength_ = 0;
    Segment seg_;
    std::uint8_t kind_ = 0;
    Mode mode_ = Mode::kClosed;
    /// Series mode: each field along the segment (degree 0 for a cell field, 1 for a
    /// linear one), its bound of evaluation error, and the extinction field's
    /// antiderivative (built when first needed).
    LegendreSeries line_[2];
    double lineError_[2] = {0, 0};
    double truncated_[2] = {0, 0};  ///< sum of the dropped coefficients of each series
    double unresolved_[2] = {0, 0};  ///< bound of the degree not sampled
    LegendreSeries depthLine_, derivative_;
    /// A linear pyramid's field in closed form and its depth line (BeginPyramidLine):
    /// pyramidLine_ in series mode.
    bool pyramidLine_ = false;
    PyramidLine pyramid_[2];
    PyramidDepthLine pyramidDepth_[2];
    /// An affine linear hexahedron's or wedge's polynomial per field (BeginPolyLine):
    /// polyLine_ in series mode; with LinearCellLine's bound of its terms.
    bool polyLine_ = false;
    PolyLine poly_[2];
    double polyMagnitude_[2] = {0, 0};
    bool haveDepthLine_ = false;
    double depthLineError_ = 0;
    double depthLineT_ = 0, depthLineV_ = 0;  ///< the last end where it was evaluated
    double quadratureNodes_ = 0;  ///< integrand samples not yet counted
    double fieldSamples_ = 0;     ///< field samples of the hexahedron kernel, not yet counted
    CellScratch cellScratch_;
    double constTau_ = 0, constColor_[3] = {0, 0, 0};
    /// The last transfer-function value LinearTetPiece computed at a piece's end: piece
    /// `piece` of the function at field value `value` (piece -2: none).
    struct TfValue {
        int piece = -2;
        double value = 0;
        double out[3] = {0, 0, 0};
    };
    TfValue lastColor_, lastExtinction_;
    /// Per field, what LinearFromFacePoints computed at the last face point (the exit
    /// of the last segment), keyed by its t and corners: the next segment's entry.
    struct FacePointSums {
        double t = 0;
        std::int32_t v[3] = {-1, -1, -1};
        double value = 0, rounding = 0;
    };
    FacePointSums faceSums_[2];
    int fieldCount_ = 1;
    /// LinearTet applies: one point field, with per-point values, drives both.
    bool linearTetField_ = false;
    /// LinearTetGroup applies: linearTetField_, and transfer functions of at most
    /// ShortAscending::kMax points with 3 colour channels and 1 extinction channel.
    bool groupable_ = false;
    /// Bounds of |d field / d x|, |d / d y|, |d / d z| in the ray frame per unit of a
    /// tetrahedron's VolumeSetup::gradientBound (trace/ray_frame.h: x and y are world
    /// axes sheared along z, z a scaled world axis).
    double frameGradient_[3] = {1, 1, 1};
    FieldState state_[2];
    SegmentField field_[2];
    std::vector<ProjectedPiece> pieces_[2];
    /// Storage of the last exact series' coefficients (ProjectExact), reused without an
    /// allocation per segment.
    std::vector<double> spareCoefficients_[2];
    ProjectionStats projectionStats_;
    std::vector<double> scratch_;
    std::vector<double> crossings_;  ///< breakpoint crossings in (tEnter, tExit), sorted
    std::vector<double> levels_, points_;
    std::vector<double> bounds_;
    struct Work {
        double lo, hi;
        int depth;
        int level = 0;  ///< series mode: the rung of the nested ladder to apply
    };
    std::vector<Work> stack_;
    int kronrodIntervals_ = 0;
    double startTau_ = 0, startEmission_[3] = {0, 0, 0};
    double endEmission_[3] = {0, 0, 0};  ///< times the transmittance there
    /// Per field, the exact series' samples: the values at [0, sampleCount_[f]), the
    /// nodes' t after them. Fixed storage (degree <= kMaxLegendreDegree): written in
    /// place by the sampling, read in place by SeriesCrossings, never resized. Last: its
    /// 2 kB kept out of the way of the members the linear tets' path reads.
    int sampleCount_[2] = {0, 0};
    double samples_[2][2 * (kMaxLegendreDegree + 1)];
    /// The series SeriesPiece reads for each field: pieces_[f][0].p where the field was
    /// projected, else line_[f] (set by BeginSegment in series mode; not where the field
    /// is held in closed form).
    const LegendreSeries* linePtr_[2] = {nullptr, nullptr};
};

}  // namespace hpray
