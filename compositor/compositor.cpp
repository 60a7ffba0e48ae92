// Distributed compositing over MPI: the swap rounds, the final gather, the reference.
#include "compositor.h"

#include <algorithm>
#include <climits>
#include <cstring>
#include <exception>
#include <string>
#include <vector>

#include "active_pixels.h"
#include "swap_schedule.h"
#include "util/check.h"
#include "util/error.h"
#include "util/mpi.h"

namespace hpray::compositor {
namespace {

/// A private duplicate of the caller's communicator, so our tags never meet theirs.
class DupComm {
  public:
    explicit DupComm(MPI_Comm comm) { MPI_Comm_dup(comm, &comm_); }
    ~DupComm() { MPI_Comm_free(&comm_); }
    DupComm(const DupComm&) = delete;
    DupComm& operator=(const DupComm&) = delete;
    MPI_Comm Get() const { return comm_; }

  private:
    MPI_Comm comm_ = MPI_COMM_NULL;
};

/// FNV-1a over the bytes of a value, to compare trees and views across ranks cheaply.
struct Fnv {
    std::uint64_t h = 1469598103934665603ull;
    template <typename T>
    void Add(const T& value) {
        unsigned char bytes[sizeof(T)];
        std::memcpy(bytes, &value, sizeof(T));
        for (unsigned char c : bytes) h = (h ^ c) * 1099511628211ull;
    }
};

std::uint64_t Fingerprint(const KdTree& tree, const ViewOrigin& view,
                          Method method) {
    Fnv f;
    f.Add(tree.root);
    for (const KdNode& node : tree.nodes) {
        f.Add(node.axis);
        f.Add(node.split);
        f.Add(node.low);
        f.Add(node.high);
        f.Add(node.leaf);
    }
    f.Add(view.orthographic);
    for (int d = 0; d < 3; ++d) {
        f.Add(view.eye[d]);
        f.Add(view.direction[d]);
    }
    f.Add(static_cast<int>(method));
    return f.h;
}

/// Checks that all ranks agree on everything the message pattern depends on. Every rank
/// learns the outcome, so on failure all throw together and none is left waiting.
void CheckAgreement(const Image& image, const KdTree& tree,
                    const ViewOrigin& view, Method method, MPI_Comm comm, int size) {
    std::string problem = tree.Problem(size);
    const std::size_t n = image.PixelCount();
    if (problem.empty() && image.width > 0 && image.height > 0) {
        for (const auto& [name, channel] : image.Channels())
            if (channel->size() != n)
                problem = "image channel " + name + " has wrong size";
    }
    if (problem.empty() && (image.width < 0 || image.height < 0))
        problem = "negative size";
    // Max of values and of their negations: equal on all ranks iff min == max.
    const long long fp = static_cast<long long>(Fingerprint(tree, view, method) >> 2);
    long long mine[7] = {problem.empty() ? 0 : 1, image.width, -image.width, image.height,
                         -image.height,           fp,          -fp};
    long long all[7];
    MPI_Allreduce(mine, all, 7, MPI_LONG_LONG, MPI_MAX, comm);
    if (!problem.empty()) throw InternalError("Composite: " + problem);
    if (all[0] != 0)
        throw InternalError("Composite: another rank rejected its arguments");
    if (all[1] != -all[2] || all[3] != -all[4])
        throw InternalError("Composite: ranks disagree on the image size");
    if (all[5] != -all[6])
        throw InternalError("Composite: ranks disagree on the tree, view or method");
}

int CountOf(const WireBuffer& buffer) {
    HPRAY_CHECK_MSG(buffer.size() <= static_cast<std::size_t>(INT_MAX),
                    "compositor message of " << buffer.size() << " doubles is too large");
    return static_cast<int>(buffer.size());
}

/// Message tags: the final gather uses 0, a merge step at tree depth d uses d + 1 (the
/// standard guarantees tags up to 32767, far beyond any tree height in use).
constexpr int kGatherTag = 0;
int StepTag(const MergeStep& step) {
    HPRAY_CHECK_LT(step.tag, 32766);
    return step.tag + 1;
}

/// Message buffers kept across the steps of one Composite call: later rounds move less
/// data than earlier ones, so they reuse pages already mapped instead of faulting in new
/// memory (a first touch costs about as much as the copy itself).
struct Scratch {
    std::vector<WireBuffer> send, recv;

    static WireBuffer& Get(std::vector<WireBuffer>& pool, std::size_t k) {
        if (pool.size() <= k) pool.resize(k + 1);
        pool[k].clear();
        return pool[k];
    }
};

/// A message this rank expects in a step: from `source`, for `range`, of child `child`,
/// received into scratch.recv[buffer].
struct Incoming {
    int source = -1;
    int child = -1;
    PixelRange range;
    std::size_t buffer = 0;
    bool received = false;
};

/// Runs this rank's part of `step`. Returns bytes sent.
std::uint64_t RunStep(const MergeStep& step, const std::vector<int>& visPos, int me,
                      Image& image, MPI_Comm comm, Scratch& scratch) {
    int ownChild = -1;
    PixelRange oldRange, newRange;
    for (std::size_t c = 0; c < step.children.size(); ++c)
        for (const Piece& piece : step.children[c])
            if (piece.rank == me) {
                ownChild = static_cast<int>(c);
                oldRange = piece.range;
            }
    if (ownChild < 0) return 0;
    const int tag = StepTag(step);
    for (const Piece& piece : step.result)
        if (piece.rank == me) newRange = piece.range;

    // Sends first (non-blocking), so that no pair of ranks can wait on each other.
    std::uint64_t bytesSent = 0;
    std::vector<MPI_Request> requests;
    requests.reserve(step.result.size());
    for (const Piece& piece : step.result) {
        if (piece.rank == me) continue;
        const PixelRange overlap = Intersect(oldRange, piece.range);
        if (overlap.Empty()) continue;
        WireBuffer& out = Scratch::Get(scratch.send, requests.size());
        EncodeActive(image, overlap, out);
        requests.emplace_back();
        MPI_Isend(out.data(), CountOf(out), MPI_DOUBLE, piece.rank, tag, comm,
                  &requests.back());
        bytesSent += out.size() * sizeof(double);
    }

    std::vector<Incoming> incoming;
    for (std::size_t c = 0; c < step.children.size(); ++c)
        for (const Piece& piece : step.children[c]) {
            if (piece.rank == me) continue;
            const PixelRange overlap = Intersect(piece.range, newRange);
            if (!overlap.Empty())
                incoming.push_back(
                    {piece.rank, static_cast<int>(c), overlap, incoming.size(), false});
        }
    // Receive in arrival order; sizes vary with the number of active pixels.
    for (std::size_t k = 0; k < incoming.size(); ++k) {
        MPI_Status status;
        MPI_Probe(MPI_ANY_SOURCE, tag, comm, &status);
        auto it = std::find_if(incoming.begin(), incoming.end(), [&](const Incoming& in) {
            return in.source == status.MPI_SOURCE && !in.received;
        });
        HPRAY_CHECK_MSG(it != incoming.end(),
                        "unexpected message from rank " << status.MPI_SOURCE);
        int count = 0;
        MPI_Get_count(&status, MPI_DOUBLE, &count);
        HPRAY_CHECK_GE(count, 0);
        WireBuffer& in = Scratch::Get(scratch.recv, it->buffer);
        in.resize(static_cast<std::size_t>(count));
        MPI_Recv(in.data(), count, MPI_DOUBLE, it->source, tag, comm, MPI_STATUS_IGNORE);
        it->received = true;
    }

    // Children front to back: groups are whole subtrees, hence contiguous in the
    // visibility order, so any one rank's position orders them.
    std::vector<int> order(step.children.size());
    for (std::size_t c = 0; c < order.size(); ++c) order[c] = static_cast<int>(c);
    std::sort(order.begin(), order.end(), [&](int x, int y) {
        return visPos[step.children[x].front().rank] <
               visPos[step.children[y].front().rank];
    });
    const int own =
        static_cast<int>(std::find(order.begin(), order.end(), ownChild) - order.begin());

    // Own group's data: ours inside the old piece, the rest (rounding only) from peers of
    // the same group, placed into cleared pixels.
    ClearRange(image, {newRange.begin, std::min(newRange.end, oldRange.begin)});
    ClearRange(image, {std::max(newRange.begin, oldRange.end), newRange.end});
    const auto apply = [&](int child, DecodeMode mode) {
        for (const Incoming& in : incoming)
            if (in.child == child) {
                const WireBuffer& data = scratch.recv[in.buffer];
                DecodeActive(data.data(), data.size(), in.range, mode, image);
            }
    };
    apply(ownChild, DecodeMode::Assign);
    // Associativity lets us grow the composite around our own group: groups behind it
    // go under, in order, then groups in front of it go over, nearest last.
    for (std::size_t k = own + 1; k < order.size(); ++k)
        apply(order[k], DecodeMode::Under);
    for (int k = own - 1; k >= 0; --k) apply(order[k], DecodeMode::Over);

    MPI_Waitall(static_cast<int>(requests.size()), requests.data(), MPI_STATUSES_IGNORE);
    return bytesSent;
}

/// Sends every rank's final range to rank 0, which assembles the full image. Returns
/// bytes sent by this rank.
std::uint64_t GatherFinal(const CompositePlan& plan, int me, Image& image, MPI_Comm comm,
                          Scratch& scratch) {
    const int size = plan.ranks;
    if (size == 1) return 0;
    if (me != 0) {
        WireBuffer& buffer = Scratch::Get(scratch.send, 0);
        EncodeActive(image, plan.finalRange[me], buffer);
        MPI_Send(buffer.data(), CountOf(buffer), MPI_DOUBLE, 0, kGatherTag, comm);
        return buffer.size() * sizeof(double);
    }
    const PixelRange mine = plan.finalRange[0];
    ClearRange(image, {0, mine.begin});
    ClearRange(image, {mine.end, plan.pixels});
    WireBuffer& buffer = Scratch::Get(scratch.recv, 0);
    for (int k = 1; k < size; ++k) {
        MPI_Status status;
        MPI_Probe(MPI_ANY_SOURCE, kGatherTag, comm, &status);
        int count = 0;
        MPI_Get_count(&status, MPI_DOUBLE, &count);
        buffer.resize(static_cast<std::size_t>(count));
        MPI_Recv(buffer.data(), count, MPI_DOUBLE, status.MPI_SOURCE, kGatherTag, comm,
                 MPI_STATUS_IGNORE);
        DecodeActive(buffer.data(), buffer.size(), plan.finalRange[status.MPI_SOURCE],
                     DecodeMode::Assign, image);
    }
    return 0;
}

/// The reference: whole images to rank 0, composited there in visibility order.
std::uint64_t GatherReference(const std::vector<int>& visibility, int me, Image& image,
                              MPI_Comm comm) {
    if (visibility.size() == 1) return 0;
    const std::size_t n = image.PixelCount();
    HPRAY_CHECK_LE(n, static_cast<std::size_t>(INT_MAX));
    const int count = static_cast<int>(n);
    if (me != 0) {
        int tag = 0;
        for (auto& [name, channel] : image.Channels())
            MPI_Send(channel->data(), count, MPI_DOUBLE, 0, tag++, comm);
        return static_cast<std::uint64_t>(n) * kBytesPerPixel;
    }
    Image accumulated, received;
    accumulated.Resize(image.width, image.height);
    received.Resize(image.width, image.height);
    for (int rank : visibility) {
        if (rank == 0) {
            CompositeOver(accumulated, image);
            continue;
        }
        int tag = 0;
        for (auto& [name, channel] : received.Channels())
            MPI_Recv(channel->data(), count, MPI_DOUBLE, rank, tag++, comm,
                     MPI_STATUS_IGNORE);
        CompositeOver(accumulated, received);
    }
    image = std::move(accumulated);
    return 0;
}

}  // namespace

CompositeStats Composite(Image& image, const KdTree& tree,
                         const ViewOrigin& view, MPI_Comm comm, Method method) {
    int me = 0, size = 1;
    MPI_Comm_rank(comm, &me);
    MPI_Comm_size(comm, &size);
    CheckAgreement(image, tree, view, method, comm, size);

    CompositeStats stats;
    std::uint64_t sentLocal = 0, gatherLocal = 0;
    double swapSeconds = 0.0, gatherSeconds = 0.0;
    // From here on a failure on one rank would leave others blocked: end the job instead.
    try {
        DupComm work(comm);
        const std::vector<int> visibility = tree.FrontToBack(view);
        if (method == Method::GatherReference) {
            const double t0 = MPI_Wtime();
            gatherLocal = GatherReference(visibility, me, image, work.Get());
            gatherSeconds = MPI_Wtime() - t0;
        } else {
            const CompositePlan plan = method == Method::TreeSwap
                                           ? PlanTreeSwap(tree, size, image.PixelCount())
                                           : PlanDirectSend(size, image.PixelCount());
            std::vector<int> visPos(size);
            for (int k = 0; k < size; ++k) visPos[visibility[k]] = k;
            const double t0 = MPI_Wtime();
            Scratch scratch;
            for (const MergeStep& step : plan.steps)
                sentLocal += RunStep(step, visPos, me, image, work.Get(), scratch);
            const double t1 = MPI_Wtime();
            gatherLocal = GatherFinal(plan, me, image, work.Get(), scratch);
            swapSeconds = t1 - t0;
            gatherSeconds = MPI_Wtime() - t1;
            stats.rounds = plan.rounds;
        }
        std::uint64_t maxIn[1] = {sentLocal}, maxOut[1];
        std::uint64_t sumIn[2] = {sentLocal, gatherLocal}, sumOut[2];
        double timeIn[2] = {swapSeconds, gatherSeconds}, timeOut[2];
        MPI_Allreduce(maxIn, maxOut, 1, MPI_UINT64_T, MPI_MAX, work.Get());
        MPI_Allreduce(sumIn, sumOut, 2, MPI_UINT64_T, MPI_SUM, work.Get());
        MPI_Allreduce(timeIn, timeOut, 2, MPI_DOUBLE, MPI_MAX, work.Get());
        stats.bytesSentMax = maxOut[0];
        stats.bytesSentTotal = sumOut[0];
        stats.bytesGather = sumOut[1];
        stats.bytesSentLocal = sentLocal;
        stats.swapSeconds = timeOut[0];
        stats.gatherSeconds = timeOut[1];
    } catch (const std::exception& e) {
        mpi::Abort(std::string("compositing failed: ") + e.what(), 1);
    }
    return stats;
}

}  // namespace hpray::compositor
