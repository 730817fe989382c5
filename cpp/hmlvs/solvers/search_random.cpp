#include <algorithm>
#include <atomic>
#include <chrono>
#include <limits>
#include <stdexcept>
#include <vector>

#include "hmlvs/model/opencv_fitness.h"
#include "hmlvs/model/paper.h"
#include "hmlvs/solvers/parallel.h"
#include "hmlvs/solvers/random.h"
#include "hmlvs/solvers/search.h"
#include "hmlvs/solvers/solve.h"

namespace hmlvs::solvers {

template <int N>
RandomSearchResult<N> RunRandomSearch(const Fitness<N>& data, const RandomSearchOptions<N>& o,
                                      const ProgressCallback& progress) {
  using Vector = typename Fitness<N>::Vector;
  if (data.size() < 1) {
    throw std::invalid_argument("random search needs at least one calibration point");
  }
  if (o.evaluations < 1) throw std::invalid_argument("evaluations must be >= 1");
  CheckBounds<N>(data, o.lower, o.upper, "search bounds");
  const auto start = std::chrono::steady_clock::now();
  const int threads =
      static_cast<int>(std::min<long long>(ResolveThreads(o.threads), o.evaluations));
  constexpr long long kBlock = 4096;  // evaluations between cancellation checks
  const long long blocks = (o.evaluations + kBlock - 1) / kBlock;
  std::vector<double> best_fit(threads, std::numeric_limits<double>::infinity());
  std::vector<long long> best_idx(threads, -1);
  std::vector<Vector> best(threads, Vector::Zero());
  std::atomic<long long> next_block(0), done(0);
  std::atomic<bool> cancel(false);
  const Vector range = o.upper - o.lower;

  RunTeam(threads, [&](int member, SpinBarrier&) {
    Vector q;
    long long own_blocks = 0;  // member 0 reports after its 1st, 9th, 17th, ... block
    for (;;) {
      const long long b = next_block.fetch_add(1);
      if (b >= blocks || cancel.load(std::memory_order_relaxed)) break;
      const long long end = std::min(o.evaluations, (b + 1) * kBlock);
      for (long long e = b * kBlock; e < end; ++e) {
        // Candidate e depends only on (seed, e): identical for any thread count.
        Rng r(StreamKey(o.seed, 0x5253ULL, static_cast<std::uint64_t>(e)));
        for (int d = 0; d < N; ++d) q[d] = o.lower[d] + r.Uniform() * range[d];
        const double f = data.Evaluate(q.data());
        if (f < best_fit[member] || (f == best_fit[member] && e < best_idx[member])) {
          best_fit[member] = f;
          best_idx[member] = e;
          best[member] = q;
        }
      }
      done.fetch_add(end - b * kBlock, std::memory_order_relaxed);
      if (member == 0 && progress && (own_blocks++ % 8 == 0)) {
        Progress p;
        p.done = done.load();
        p.total = o.evaluations;
        p.best_fitness = best_fit[0];
        if (!progress(p)) cancel.store(true);
      }
    }
  });
  RandomSearchResult<N> result;
  result.threads = threads;
  result.best_fitness = std::numeric_limits<double>::infinity();
  for (int t = 0; t < threads; ++t) {
    if (best_idx[t] < 0) continue;
    if (best_fit[t] < result.best_fitness ||
        (best_fit[t] == result.best_fitness && best_idx[t] < result.best_index)) {
      result.best_fitness = best_fit[t];
      result.best_index = best_idx[t];
      result.best = best[t];
    }
  }
  result.evaluations = done.load();
  result.cancelled = cancel.load();
  if (progress && !result.cancelled) {  // the last count, whichever member did the work
    Progress p;
    p.done = result.evaluations;
    p.total = o.evaluations;
    p.best_fitness = result.best_fitness;
    progress(p);
  }
  result.seconds = SecondsSince(start);
  return result;
}

template RandomSearchResult<paper::kNumParams> RunRandomSearch(
    const Fitness<paper::kNumParams>&, const RandomSearchOptions<paper::kNumParams>&,
    const ProgressCallback&);
template RandomSearchResult<opencv::kNumPointParams> RunRandomSearch(
    const Fitness<opencv::kNumPointParams>&, const RandomSearchOptions<opencv::kNumPointParams>&,
    const ProgressCallback&);

}  // namespace hmlvs::solvers
