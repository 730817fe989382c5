#include "hmlvs/solvers/multistart.h"

#include <algorithm>
#include <atomic>
#include <exception>
#include <limits>
#include <mutex>

#include "hmlvs/solvers/parallel.h"

namespace hmlvs::solvers {

MultiStartResult RunLmMany(const paper::FitnessData& data, StartsRef starts,
                           const LmOptions& options, int threads,
                           const ProgressCallback& progress) {
  const Eigen::Index n = starts.rows();
  MultiStartResult out;
  out.results.resize(n);
  out.errors.resize(n);
  const int team = std::max(1, std::min<int>(ResolveThreads(threads), static_cast<int>(n)));
  std::atomic<Eigen::Index> next(0);
  std::atomic<long long> done(0);
  std::atomic<bool> cancel(false);
  std::vector<std::atomic<bool>> started(n);
  for (auto& s : started) s.store(false);
  std::mutex best_mutex;
  double best = std::numeric_limits<double>::infinity();
  RunTeam(team, [&](int member, SpinBarrier&) {
    for (Eigen::Index i = next.fetch_add(1); i < n && !cancel.load(); i = next.fetch_add(1)) {
      started[i].store(true);
      try {
        out.results[i] = RunLm(data, starts.row(i).transpose(), options);
        std::lock_guard<std::mutex> lock(best_mutex);
        best = std::min(best, out.results[i].final_cost);
      } catch (const std::exception& e) {
        out.errors[i] = e.what();
      }
      const long long d = done.fetch_add(1) + 1;
      if (member == 0 && progress) {
        Progress p;
        p.done = d;
        p.total = n;
        {
          std::lock_guard<std::mutex> lock(best_mutex);
          p.best_fitness = best;
        }
        if (!progress(p)) cancel.store(true);
      }
    }
  });
  for (Eigen::Index i = 0; i < n; ++i) {
    if (!started[i].load()) out.errors[i] = "cancelled";
  }
  return out;
}

}  // namespace hmlvs::solvers
