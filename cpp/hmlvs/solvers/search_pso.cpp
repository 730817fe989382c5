#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <functional>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "hmlvs/model/opencv_fitness.h"
#include "hmlvs/model/paper.h"
#include "hmlvs/solvers/parallel.h"
#include "hmlvs/solvers/random.h"
#include "hmlvs/solvers/search.h"
#include "hmlvs/solvers/solve.h"

namespace hmlvs::solvers {

namespace {

// The best personal best among one team member's particles after a generation. Cache-line
// aligned: each member writes its own entry every generation.
template <int N>
struct alignas(64) MemberBest {
  double fit = std::numeric_limits<double>::infinity();
  typename Fitness<N>::Vector best = Fitness<N>::Vector::Zero();
  bool stop = false;  // member 0: cancellation requested before this generation
};

// One particle: position, velocity, personal best and random stream. Cache-line aligned, so
// that team members updating neighbouring particles never write to the same line.
template <int N>
struct alignas(64) Particle {
  typename Fitness<N>::Vector x, v, pbest;
  double fit = 0.0, pbest_fit = 0.0;
  Rng rng{0};
};

// One swarm: its particles and the global best.
// Cache-line aligned, its global best on lines of its own: team member 0 writes it every
// generation, while every member reads the fields before it (the particles' and the member
// bests' buffers), which so never share a line with that write.
template <int N>
struct alignas(64) Swarm {
  int n;
  std::vector<Particle<N>> p;
  // Per team member, double-buffered by generation parity: a member may write generation
  // t + 1's entry while the others still read generation t's.
  std::array<std::vector<MemberBest<N>>, 2> member_best;
  alignas(64) typename Fitness<N>::Vector gbest;
  double gbest_fit = std::numeric_limits<double>::infinity();
  explicit Swarm(int size) : n(size), p(size) {}
};

// What moving a particle needs besides the particle: the generation's inertia and the options.
struct Motion {
  double w, c1, c2;
  const double *lower, *upper, *vmax, *neg_vmax, *gbest;
};

// Moves one particle (Eq. 19, 21): velocity towards its own and the swarm's best, limited to
// +-vmax, then the position, held at a bound with zero velocity where it would leave the box.
// The random draws come first, in the order r1, r2 of each dimension in turn (the particle's
// stream); the update is element-wise, so it vectorises without reordering any floating-point
// operation of an element. On x86-64 an AVX2 clone is chosen at load time when the CPU has it
// (not FMA, which would fuse the multiply-adds and change the results); both give the same bits.
template <int N>
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && !defined(__AVX2__)
__attribute__((target_clones("avx2", "default")))
#endif
void Move(const Motion& m, Particle<N>& p) {
  double r1[N], r2[N];
  UniformPairs(p.rng, N, r1, r2);
  double* x = p.x.data();
  double* v = p.v.data();
  const double* pbest = p.pbest.data();
  const double w = m.w, c1 = m.c1, c2 = m.c2;
  const double *lower = m.lower, *upper = m.upper, *g = m.gbest;
#pragma omp simd
  for (int d = 0; d < N; ++d) {
    double vd = w * v[d] + c1 * r1[d] * (pbest[d] - x[d]) + c2 * r2[d] * (g[d] - x[d]);
    // std::clamp(vd, -vmax, vmax): the same comparisons, as selects (no branches).
    const double hi = m.vmax[d], lo = m.neg_vmax[d];
    vd = hi < vd ? hi : vd;
    vd = vd < lo ? lo : vd;
    const double xd = x[d] + vd;
    // Held at a bound, with zero velocity (lower <= upper: at most one of the two holds). The
    // quiet comparisons answer as < and > do but cannot trap, so both may be evaluated
    // unconditionally.
    const bool below = std::isless(xd, lower[d]);
    const bool above = std::isgreater(xd, upper[d]);
    const double xb = below ? lower[d] : xd;
    x[d] = above ? upper[d] : xb;
    v[d] = (below | above) ? 0.0 : vd;
  }
}

template <int N>
class PsoRunner {
 public:
  using Vector = typename Fitness<N>::Vector;
  using Swarm = hmlvs::solvers::Swarm<N>;
  using Particle = hmlvs::solvers::Particle<N>;

  PsoRunner(const Fitness<N>& data, const PsoOptions<N>& o) : data_(data), o_(o) {
    range_ = o.upper - o.lower;
    vmax_ = o.vmax * range_;
    neg_vmax_ = -vmax_;
    init_lo_ = o.lower;
    init_hi_ = o.upper;
    if ((o.init_lower.array() <= o.init_upper.array()).all()) {
      init_lo_ = o.init_lower.cwiseMax(o.lower);
      init_hi_ = o.init_upper.cwiseMin(o.upper);
      for (int d = 0; d < N; ++d) {
        if (init_lo_[d] > init_hi_[d]) {
          throw std::invalid_argument("the initial box of " + data.ParameterName(d) +
                                      " lies outside the search bounds");
        }
      }
    }
  }

  void Init(Swarm& s, int run, int first, int last) const {
    for (int i = first; i < last; ++i) {
      Particle& p = s.p[i];
      p.rng =
          Rng(StreamKey(o_.seed, static_cast<std::uint64_t>(run), static_cast<std::uint64_t>(i)));
      for (int d = 0; d < N; ++d) {
        p.x[d] = init_lo_[d] + p.rng.Uniform() * (init_hi_[d] - init_lo_[d]);
        p.v[d] = (2.0 * p.rng.Uniform() - 1.0) * vmax_[d];
      }
      p.fit = data_.Evaluate(p.x.data());
      p.pbest = p.x;
      p.pbest_fit = p.fit;
    }
  }

  void Step(Swarm& s, int t, int first, int last, const Vector& gbest) const {
    Motion m;
    m.w = o_.w_max - (o_.w_max - o_.w_min) * t / o_.iterations;  // Eq. 20
    m.c1 = o_.c1;
    m.c2 = o_.c2;
    m.lower = o_.lower.data();
    m.upper = o_.upper.data();
    m.vmax = vmax_.data();
    m.neg_vmax = neg_vmax_.data();
    m.gbest = gbest.data();
    for (int i = first; i < last; ++i) {
      Particle& p = s.p[i];
      Move<N>(m, p);
      p.fit = data_.Evaluate(p.x.data());
      if (p.fit < p.pbest_fit) {
        p.pbest_fit = p.fit;
        p.pbest = p.x;
      }
    }
  }

  // Global best over personal bests in particle order (ties: lowest index): deterministic.
  static void UpdateGlobal(Swarm& s) {
    for (int i = 0; i < s.n; ++i) {
      if (s.p[i].pbest_fit < s.gbest_fit) {
        s.gbest_fit = s.p[i].pbest_fit;
        s.gbest = s.p[i].pbest;
      }
    }
  }

  // Runs one swarm on `members` threads of a team (member ids [0, members)). With several
  // members, one barrier per generation: each member finds the best personal best among its own
  // particles, and after the barrier every member combines these in member order (particles in
  // index order, ties to the lowest index, as UpdateGlobal does), so all hold the same global
  // best without a second barrier. A cancellation seen by member 0 before a generation is
  // passed with its result, so that all members stop after the same generation.
  void RunSwarm(int run, int member, int members, SpinBarrier* barrier, PsoRun<N>* out,
                std::atomic<bool>* cancel, const std::function<void(int)>& tick) const {
    Swarm& s = *swarms_[run];
    const int chunk = (s.n + members - 1) / members;
    const int first = std::min(s.n, member * chunk);
    const int last = std::min(s.n, first + chunk);
    Init(s, run, first, last);
    if (barrier) barrier->Wait();
    if (member == 0) UpdateGlobal(s);
    if (barrier) barrier->Wait();
    Vector gbest = s.gbest;  // this member's copy: the same on every member
    double gbest_fit = s.gbest_fit;
    int t = 0;
    std::string termination = "max_iterations";
    for (; t < o_.iterations; ++t) {
      if (gbest_fit <= o_.target_fitness) {
        termination = "target_fitness";
        break;
      }
      if (barrier == nullptr) {
        if (cancel->load(std::memory_order_relaxed)) {
          termination = "cancelled";
          break;
        }
        Step(s, t, first, last, s.gbest);
        UpdateGlobal(s);
        gbest_fit = s.gbest_fit;
      } else {
        const bool stop = member == 0 && cancel->load(std::memory_order_relaxed);
        Step(s, t, first, last, gbest);
        MemberBest<N>& mine = s.member_best[t & 1][member];
        mine.fit = std::numeric_limits<double>::infinity();
        int best = -1;
        for (int i = first; i < last; ++i) {
          if (s.p[i].pbest_fit < mine.fit) {
            mine.fit = s.p[i].pbest_fit;
            best = i;
          }
        }
        if (best >= 0) mine.best = s.p[best].pbest;
        mine.stop = stop;
        barrier->Wait();
        const std::vector<MemberBest<N>>& all = s.member_best[t & 1];
        if (all[0].stop) {
          termination = "cancelled";
          break;
        }
        for (int m = 0; m < members; ++m) {
          if (all[m].fit < gbest_fit) {
            gbest_fit = all[m].fit;
            gbest = all[m].best;
          }
        }
        if (member == 0) {
          s.gbest = gbest;
          s.gbest_fit = gbest_fit;
        }
      }
      if (member == 0) {
        out->history.push_back(s.gbest_fit);
        tick(t + 1);
      }
    }
    if (member == 0) {
      out->best = s.gbest;
      out->best_fitness = s.gbest_fit;
      out->iterations = t;
      out->termination = termination;
    }
  }

  std::vector<std::unique_ptr<Swarm>> swarms_;

 private:
  const Fitness<N>& data_;
  const PsoOptions<N>& o_;
  Vector range_, vmax_, neg_vmax_, init_lo_, init_hi_;
};

}  // namespace

template <int N>
PsoResult<N> RunPso(const Fitness<N>& data, const PsoOptions<N>& o,
                    const ProgressCallback& progress) {
  if (data.size() < 1) throw std::invalid_argument("PSO needs at least one calibration point");
  if (o.swarm_size < 2) throw std::invalid_argument("the swarm needs at least 2 particles");
  if (o.iterations < 0) throw std::invalid_argument("iterations must be >= 0");
  if (o.runs < 1) throw std::invalid_argument("runs must be >= 1");
  if (!(o.vmax > 0.0)) throw std::invalid_argument("vmax must be > 0");
  CheckBounds<N>(data, o.lower, o.upper, "search bounds");
  const auto start = std::chrono::steady_clock::now();
  const int threads = ResolveThreads(o.threads);

  PsoRunner<N> runner(data, o);
  PsoResult<N> result;
  result.runs.resize(o.runs);
  for (int r = 0; r < o.runs; ++r) {
    runner.swarms_.push_back(std::make_unique<Swarm<N>>(o.swarm_size));
    for (auto& buffer : runner.swarms_.back()->member_best) buffer.assign(threads, MemberBest<N>());
    result.runs[r].history.reserve(o.iterations);
  }
  std::atomic<bool> cancel(false);
  std::atomic<long long> done(0);
  const long long total = static_cast<long long>(o.iterations) * o.runs;
  const int every = std::max(1, o.progress_every);
  // Progress is reported by team member 0 only (the caller's thread).
  auto report = [&](bool from_caller) {
    if (!progress || !from_caller) return;
    Progress p;
    p.done = done.load();
    p.total = total;
    p.best_fitness = std::numeric_limits<double>::infinity();
    for (const auto& s : runner.swarms_) p.best_fitness = std::min(p.best_fitness, s->gbest_fit);
    if (!progress(p)) cancel.store(true);
  };

  if (o.runs >= threads || threads == 1) {
    // Independent runs in parallel, one thread each.
    const int team = std::min(threads, o.runs);
    result.threads = team;
    RunTeam(team, [&](int member, SpinBarrier&) {
      for (int r = member; r < o.runs; r += team) {
        runner.RunSwarm(r, 0, 1, nullptr, &result.runs[r], &cancel, [&](int t) {
          done.fetch_add(1, std::memory_order_relaxed);
          if (member == 0 && t % every == 0) report(true);
        });
      }
    });
  } else {
    // Fewer runs than threads: the particles of each run are shared among the team.
    result.threads = threads;
    RunTeam(threads, [&](int member, SpinBarrier& barrier) {
      for (int r = 0; r < o.runs; ++r) {
        runner.RunSwarm(r, member, threads, &barrier, &result.runs[r], &cancel, [&](int t) {
          done.fetch_add(1, std::memory_order_relaxed);
          if (t % every == 0) report(true);
        });
      }
    });
  }
  result.cancelled = cancel.load();
  for (int r = 1; r < o.runs; ++r) {
    if (result.runs[r].best_fitness < result.runs[result.best_run].best_fitness) {
      result.best_run = r;
    }
  }
  result.seconds = SecondsSince(start);
  return result;
}

template PsoResult<paper::kNumParams> RunPso(const Fitness<paper::kNumParams>&,
                                             const PsoOptions<paper::kNumParams>&,
                                             const ProgressCallback&);
template PsoResult<opencv::kNumPointParams> RunPso(const Fitness<opencv::kNumPointParams>&,
                                                   const PsoOptions<opencv::kNumPointParams>&,
                                                   const ProgressCallback&);

}  // namespace hmlvs::solvers
