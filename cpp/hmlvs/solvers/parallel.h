// A team of threads created once per solve, with a low-latency barrier for per-iteration
// synchronisation. The calling thread is member 0, so a progress callback made by member 0
// runs on the caller's thread.
#pragma once

#include <atomic>
#include <functional>
#include <thread>
#include <vector>

namespace hmlvs::solvers {

/// Sense-reversing spin barrier that yields the CPU after a short spin (the machine may have
/// fewer cores than threads).
class SpinBarrier {
 public:
  explicit SpinBarrier(int count) : count_(count), waiting_(0), sense_(false) {}
  void Wait() {
    const bool sense = sense_.load(std::memory_order_relaxed);
    if (waiting_.fetch_add(1, std::memory_order_acq_rel) == count_ - 1) {
      waiting_.store(0, std::memory_order_relaxed);
      sense_.store(!sense, std::memory_order_release);
      return;
    }
    int spins = 0;
    while (sense_.load(std::memory_order_acquire) == sense) {
      if (++spins > 2000) std::this_thread::yield();
    }
  }

 private:
  const int count_;
  std::atomic<int> waiting_;
  std::atomic<bool> sense_;
};

/// Runs body(member, barrier) on `threads` threads (the caller is member 0) and joins them.
/// Exceptions thrown by a member are rethrown on the caller after all have finished.
void RunTeam(int threads, const std::function<void(int member, SpinBarrier& barrier)>& body);

/// Number of threads to use for a request of `threads` (<= 0: all hardware threads).
int ResolveThreads(int threads);

}  // namespace hmlvs::solvers
