// Counter-based random numbers: the value drawn depends only on (key, counter), never on which
// thread draws it, so solver results are identical for any thread count.
#pragma once

#include <cstdint>

namespace hmlvs::solvers {

inline std::uint64_t SplitMix64(std::uint64_t x) {
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

/// Key of a stream from a seed and up to three indices (run, particle, ...).
inline std::uint64_t StreamKey(std::uint64_t seed, std::uint64_t a, std::uint64_t b = 0,
                               std::uint64_t c = 0) {
  return SplitMix64(SplitMix64(SplitMix64(SplitMix64(seed) ^ a) ^ b) ^ c);
}

/// A sequential generator over one stream (SplitMix64 on a Weyl sequence): its k-th draw
/// depends only on the key and k, so draws can also be made several at a time.
class Rng {
 public:
  static constexpr std::uint64_t kGamma = 0x9e3779b97f4a7c15ULL;
  explicit Rng(std::uint64_t key) : state_(key) {}
  std::uint64_t Next() {
    state_ += kGamma;
    std::uint64_t z = state_;
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    return z ^ (z >> 31);
  }
  /// Uniform in [0, 1).
  double Uniform() { return static_cast<double>(Next() >> 11) * 0x1.0p-53; }
  /// The state before the next draw (the k-th next draw mixes state + k * kGamma).
  std::uint64_t State() const { return state_; }
  /// Skips n draws.
  void Discard(std::uint64_t n) { state_ += n * kGamma; }

 private:
  std::uint64_t state_;
};

/// n pairs of uniform draws, the same values as n rounds of r1[d] = rng.Uniform(), r2[d] =
/// rng.Uniform() (bit for bit); with AVX2, where the CPU has it, four pairs at a time.
void UniformPairs(Rng& rng, int n, double* r1, double* r2);

}  // namespace hmlvs::solvers
