#include "hmlvs/solvers/random.h"

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#include <immintrin.h>
#define HMLVS_AVX2_DRAWS 1
#endif

namespace hmlvs::solvers {

namespace {

void ScalarPairs(Rng& rng, int n, double* r1, double* r2) {
  for (int d = 0; d < n; ++d) {
    r1[d] = rng.Uniform();
    r2[d] = rng.Uniform();
  }
}

#ifdef HMLVS_AVX2_DRAWS
// x * c (mod 2^64) on four lanes, from 32-bit halves (AVX2 has no 64-bit multiply).
__attribute__((target("avx2"))) inline __m256i Mul64(__m256i x, __m256i c_lo, __m256i c_hi) {
  const __m256i cross =
      _mm256_add_epi64(_mm256_mul_epu32(_mm256_srli_epi64(x, 32), c_lo), _mm256_mul_epu32(x, c_hi));
  return _mm256_add_epi64(_mm256_mul_epu32(x, c_lo), _mm256_slli_epi64(cross, 32));
}

// Rng::Uniform of four Weyl states: SplitMix64's mix, the top 53 bits, then the conversion to
// double. The 53-bit integer u = hi * 2^32 + lo is converted exactly: the exponent bits of
// 2^84 and 2^52 put hi * 2^32 and lo in the mantissas, and every step below is exact because
// each result is an integer below 2^85 with at most 53 significant bits.
__attribute__((target("avx2"))) inline __m256d UniformOf(__m256i z) {
  z = _mm256_xor_si256(z, _mm256_srli_epi64(z, 30));
  z = Mul64(z, _mm256_set1_epi64x(0x1ce4e5b9LL), _mm256_set1_epi64x(0xbf58476dLL));
  z = _mm256_xor_si256(z, _mm256_srli_epi64(z, 27));
  z = Mul64(z, _mm256_set1_epi64x(0x133111ebLL), _mm256_set1_epi64x(0x94d049bbLL));
  z = _mm256_xor_si256(z, _mm256_srli_epi64(z, 31));
  const __m256i u = _mm256_srli_epi64(z, 11);
  const __m256i lo = _mm256_blend_epi32(u, _mm256_set1_epi64x(0x4330000000000000LL), 0xAA);
  const __m256i hi =
      _mm256_or_si256(_mm256_srli_epi64(u, 32), _mm256_set1_epi64x(0x4530000000000000LL));
  const __m256d v =
      _mm256_add_pd(_mm256_sub_pd(_mm256_castsi256_pd(hi), _mm256_set1_pd(0x1.00000001p84)),
                    _mm256_castsi256_pd(lo));
  return _mm256_mul_pd(v, _mm256_set1_pd(0x1.0p-53));
}

__attribute__((target("avx2"))) void Avx2Pairs(Rng& rng, int n, double* r1, double* r2) {
  constexpr std::uint64_t g = Rng::kGamma;
  const int vec = n / 4 * 4;
  const std::uint64_t s = rng.State();
  // pair d draws number 2d + 1 and 2d + 2 of the stream
  __m256i a = _mm256_add_epi64(
      _mm256_set1_epi64x(static_cast<long long>(s)),
      _mm256_setr_epi64x(static_cast<long long>(1 * g), static_cast<long long>(3 * g),
                         static_cast<long long>(5 * g), static_cast<long long>(7 * g)));
  const __m256i one = _mm256_set1_epi64x(static_cast<long long>(g));
  const __m256i step = _mm256_set1_epi64x(static_cast<long long>(8 * g));
  for (int d = 0; d < vec; d += 4) {
    _mm256_storeu_pd(r1 + d, UniformOf(a));
    _mm256_storeu_pd(r2 + d, UniformOf(_mm256_add_epi64(a, one)));
    a = _mm256_add_epi64(a, step);
  }
  rng.Discard(2 * static_cast<std::uint64_t>(vec));
  ScalarPairs(rng, n - vec, r1 + vec, r2 + vec);
}

bool HaveAvx2() {
  static const bool have = __builtin_cpu_supports("avx2");
  return have;
}
#endif

}  // namespace

void UniformPairs(Rng& rng, int n, double* r1, double* r2) {
#ifdef HMLVS_AVX2_DRAWS
  if (HaveAvx2()) {
    Avx2Pairs(rng, n, r1, r2);
    return;
  }
#endif
  ScalarPairs(rng, n, r1, r2);
}

}  // namespace hmlvs::solvers
