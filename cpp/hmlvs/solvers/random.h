// Counter-based random numbers: the value drawn depends only on (key, counter), never on which
// thread draws it, so solver results are identical for any thread count.
#pragma once

#include <cstdint>
#include <cstring>

namespace hmlvs {

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

/// A sequential generator over one stream (SplitMix64 on a Weyl sequence).
class Rng {
 public:
  explicit Rng(std::uint64_t key) : state_(key) {}
  std::uint64_t Next() {
    state_ += 0x9e3779b97f4a7c15ULL;
    std::uint64_t z = state_;
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    return z ^ (z >> 31);
  }
  /// Uniform in [0, 1).
  double Uniform() { return static_cast<double>(Next() >> 11) * 0x1.0p-53; }

  /// The next 2 n draws of Uniform(), alternately into a[0], b[0], a[1], b[1], ..., a[n - 1],
  /// b[n - 1]: the same values in the same order as 2 n calls. Draw j is a function of the
  /// state plus j steps of the Weyl sequence, so the draws have no serial dependency and the
  /// loop vectorises; the conversion to double is exact, as in Uniform().
  template <int n>
  void UniformPairs(double* a, double* b) {
    constexpr std::uint64_t kStep = 0x9e3779b97f4a7c15ULL;
    // 53-bit integer z >> 11 to double without an int64 -> double instruction (none in SSE2 or
    // AVX2): the bits 0x433 << 52 | low are the double 2^52 + low, exact for low < 2^52, from
    // which 2^52 is subtracted again unless the top bit of the 53 is set. The result is the
    // exact integer, which then scales exactly by 2^-53.
    constexpr std::uint64_t kLow = (std::uint64_t{1} << 52) - 1;
    constexpr std::uint64_t kTwo52 = std::uint64_t{0x433} << 52;  // the bits of 2^52
    std::uint64_t bits[2 * n], offset[2 * n];
    const std::uint64_t s = state_;
#pragma omp simd
    for (int j = 0; j < 2 * n; ++j) {
      std::uint64_t z = s + static_cast<std::uint64_t>(j + 1) * kStep;
      z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
      z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
      z = (z ^ (z >> 31)) >> 11;
      bits[j] = kTwo52 | (z & kLow);
      offset[j] = ((z >> 52) - 1) & kTwo52;  // 2^52 if the top bit is clear, else +0.0
    }
    state_ = s + static_cast<std::uint64_t>(2 * n) * kStep;
    double big[2 * n], sub[2 * n];
    std::memcpy(big, bits, sizeof big);
    std::memcpy(sub, offset, sizeof sub);
#pragma omp simd
    for (int i = 0; i < n; ++i) {
      a[i] = (big[2 * i] - sub[2 * i]) * 0x1.0p-53;
      b[i] = (big[2 * i + 1] - sub[2 * i + 1]) * 0x1.0p-53;
    }
  }

 private:
  std::uint64_t state_;
};

}  // namespace hmlvs
