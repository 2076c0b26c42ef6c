#pragma once
// AVX2 versions of the solvers' hottest sums over a particle's neighbour list, on padded vectors
// (Vec4, w = 0): two neighbours per 256-bit instruction. (The neighbour search's AVX2 filter uses
// the same switch.) Chosen at run time (avx2::available()); the
// build stays generic x86-64, so only these functions are compiled for AVX2 (GCC/Clang target
// attribute) and the rest of the program keeps Eigen's default alignment (which Debian's DART and
// OpenVDB are built with). With FMA their results round differently from the generic loops: a run
// is reproducible on one machine, not bit for bit across machines with and without AVX2.
#include "m3dp/core/types.hpp"

#if (defined(__x86_64__) || defined(__i386__)) && (defined(__GNUC__) || defined(__clang__)) && !defined(M3DP_USE_DOUBLE)
#define M3DP_NEIGHBOR_SUMS_AVX2 1
#include <immintrin.h>

#include <cstddef>
#include <cstdlib>

namespace m3dp::sph::avx2 {

/// Whether the CPU has AVX2 and FMA, unless the environment variable M3DP_NO_AVX2 is set (to run and
/// test the generic loops on a machine that has them).
inline bool available() {
  static const bool supported =
      __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma") && __builtin_cpu_supports("popcnt") && !std::getenv("M3DP_NO_AVX2");
  return supported;
}

/// Vectors j0 and j1 of a padded array in the low and high halves.
__attribute__((target("avx2,fma"))) inline __m256 load_pair(const Vec4* vectors, Index j0, Index j1) {
  return _mm256_insertf128_ps(_mm256_castps128_ps256(_mm_load_ps(vectors[j0].data())), _mm_load_ps(vectors[j1].data()), 1);
}
/// (w0, w0, w0, w0, w1, w1, w1, w1) from two consecutive weights.
__attribute__((target("avx2,fma"))) inline __m256 spread_pair(const Real* weights) {
  const __m128 two = _mm_castpd_ps(_mm_load_sd(reinterpret_cast<const double*>(weights)));
  return _mm256_permutevar8x32_ps(_mm256_castps128_ps256(two), _mm256_setr_epi32(0, 0, 0, 0, 1, 1, 1, 1));
}
__attribute__((target("avx2,fma"))) inline __m256 broadcast(const Vec4& vector) {
  return _mm256_broadcast_ps(reinterpret_cast<const __m128*>(vector.data()));
}
/// The two halves added: a Vec4.
__attribute__((target("avx2,fma"))) inline Vec4 halves_added(__m256 sum) {
  Vec4 result;
  _mm_storeu_ps(result.data(), _mm_add_ps(_mm256_castps256_ps128(sum), _mm256_extractf128_ps(sum, 1)));
  return result;
}

/// Σ_k w_k (a_i − a_j) ⊙ (b_i − b_j), j = neighbor[k], lane by lane (as the generic loop in dfsph).
__attribute__((target("avx2,fma"))) inline Vec4 difference_products(const Vec4* a, const Vec4* b, const Index* neighbor,
                                                                    const Real* weight, Index count, const Vec4& a_i,
                                                                    const Vec4& b_i) {
  const __m256 a_ii = broadcast(a_i), b_ii = broadcast(b_i);
  __m256 sum = _mm256_setzero_ps();
  Index k = 0;
  for (; k + 1 < count; k += 2) {
    const Index j0 = neighbor[k], j1 = neighbor[k + 1];
    const __m256 product = _mm256_mul_ps(_mm256_sub_ps(a_ii, load_pair(a, j0, j1)), _mm256_sub_ps(b_ii, load_pair(b, j0, j1)));
    sum = _mm256_fmadd_ps(spread_pair(weight + k), product, sum);
  }
  Vec4 result = halves_added(sum);
  if (k < count) result += weight[k] * (a_i - a[neighbor[k]]).cwiseProduct(b_i - b[neighbor[k]]);
  return result;
}

/// Σ_k w_k ((b_i − b_j)·(x_i − x_j)) (b_i − b_j), j = neighbor[k]: the viscous matrix-vector product's
/// sum (b positions, x the operand).
__attribute__((target("avx2,fma"))) inline Vec4 projections(const Vec4* b, const Vec4* x, const Index* neighbor, const Real* weight,
                                                            Index count, const Vec4& b_i, const Vec4& x_i) {
  const __m256 b_ii = broadcast(b_i), x_ii = broadcast(x_i);
  __m256 sum = _mm256_setzero_ps();
  Index k = 0;
  for (; k + 1 < count; k += 2) {
    const Index j0 = neighbor[k], j1 = neighbor[k + 1];
    const __m256 r = _mm256_sub_ps(b_ii, load_pair(b, j0, j1));
    // Each half's dot product over x, y, z, in all four of its lanes.
    const __m256 dot = _mm256_dp_ps(r, _mm256_sub_ps(x_ii, load_pair(x, j0, j1)), 0x7F);
    sum = _mm256_fmadd_ps(_mm256_mul_ps(dot, spread_pair(weight + k)), r, sum);
  }
  Vec4 result = halves_added(sum);
  if (k < count) {
    const Vec4 r = b_i - b[neighbor[k]];
    result += (weight[k] * r.dot(x_i - x[neighbor[k]])) * r;
  }
  return result;
}

}  // namespace m3dp::sph::avx2
#endif
