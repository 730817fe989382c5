#include "hmlvs/solvers/parallel.h"

#include <exception>
#include <mutex>

namespace hmlvs::solvers {

int ResolveThreads(int threads) {
  if (threads > 0) return threads;
  const unsigned hw = std::thread::hardware_concurrency();
  return hw == 0 ? 1 : static_cast<int>(hw);
}

void RunTeam(int threads, const std::function<void(int, SpinBarrier&)>& body) {
  threads = threads < 1 ? 1 : threads;
  SpinBarrier barrier(threads);
  std::exception_ptr error;
  std::mutex error_mutex;
  auto guarded = [&](int member) {
    try {
      body(member, barrier);
    } catch (...) {
      std::lock_guard<std::mutex> lock(error_mutex);
      if (!error) error = std::current_exception();
    }
  };
  std::vector<std::thread> workers;
  workers.reserve(threads - 1);
  for (int t = 1; t < threads; ++t) workers.emplace_back(guarded, t);
  guarded(0);
  for (auto& w : workers) w.join();
  if (error) std::rethrow_exception(error);
}

}  // namespace hmlvs::solvers
