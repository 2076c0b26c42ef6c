#pragma once
// AVX2 versions of the solvers' hottest sums over a particle's neighbour list, on padded vectors
// (Vec4, w = 0): two neighbours per 256-bit instruction where the sum is over vectors, eight (the
// positions transposed to x, y and z lanes) where it needs distances or per-pair scalars. The
// `..._rows` functions take a range of particles and call a `finish` for each, which inlines into
// them: an AVX2 function cannot be inlined into generic code, and a call per particle cost as much
// as its pairs. (The neighbour search's AVX2 filter uses the same switch.) Chosen at run time
// (avx2::available()); the build stays generic x86-64, so only these functions are compiled for AVX2 (GCC/Clang target
// attribute) and the rest of the program keeps Eigen's default alignment (which Debian's DART and
// OpenVDB are built with). With FMA their results round differently from the generic loops: a run
// is reproducible on one machine, not bit for bit across machines with and without AVX2.
// Where the CPU has AVX-512F, the viscous product and the density change rates (the solvers' sums
// over vectors) take four neighbours per 512-bit instruction, and the neighbour search's filter
// sixteen candidates (avx512::available(), M3DP_NO_AVX512).
#include "m3dp/core/types.hpp"
#include "m3dp/sph/kernels.hpp"

#if (defined(__x86_64__) || defined(__i386__)) && (defined(__GNUC__) || defined(__clang__)) && !defined(M3DP_USE_DOUBLE)
#define M3DP_NEIGHBOR_SUMS_AVX2 1
#include <immintrin.h>

#include <algorithm>
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

/// sum + the last neighbour's w (a_i − a_j) ⊙ (b_i − b_j) in the low half where the count is odd, zero
/// where it is even: a branch on the count's parity would be mispredicted for half of the particles.
__attribute__((target("avx2,fma"))) inline __m256 with_last_if_odd(const Vec4* a, const Vec4* b, const Index* neighbor, const Real* weight,
                                                                   Index count, __m256 a_ii, __m256 b_ii, __m256 sum) {
  const Index last = neighbor[count - 1];
  const __m256 odd = _mm256_castsi256_ps(_mm256_set1_epi32(-static_cast<int>(count & 1)));
  const __m256 last_weight = _mm256_and_ps(odd, _mm256_set_m128(_mm_setzero_ps(), _mm_set1_ps(weight[count - 1])));  // low half only
  const __m256 product = _mm256_mul_ps(_mm256_sub_ps(a_ii, load_pair(a, last, last)), _mm256_sub_ps(b_ii, load_pair(b, last, last)));
  return _mm256_fmadd_ps(last_weight, product, sum);
}

/// Σ_k w_k (a_i − a_j) ⊙ (b_i − b_j), j = neighbor[k], lane by lane (as the generic loop in dfsph).
__attribute__((target("avx2,fma"))) inline Vec4 difference_products(const Vec4* a, const Vec4* b, const Index* neighbor,
                                                                    const Real* weight, Index count, const Vec4& a_i,
                                                                    const Vec4& b_i) {
  if (count == 0) return Vec4::Zero();
  const __m256 a_ii = broadcast(a_i), b_ii = broadcast(b_i);
  __m256 sum = _mm256_setzero_ps();
  Index k = 0;
  for (; k + 1 < count; k += 2) {
    const Index j0 = neighbor[k], j1 = neighbor[k + 1];
    const __m256 product = _mm256_mul_ps(_mm256_sub_ps(a_ii, load_pair(a, j0, j1)), _mm256_sub_ps(b_ii, load_pair(b, j0, j1)));
    sum = _mm256_fmadd_ps(spread_pair(weight + k), product, sum);
  }
  return halves_added(with_last_if_odd(a, b, neighbor, weight, count, a_ii, b_ii, sum));
}

/// Σ_{i in [begin, end)} finish(i, Σ_k w_k (a_i − a_j) ⊙ (b_i − b_j)) over each particle's list: the
/// sweep around difference_products, so that the per-particle sum is inlined rather than called.
template <class Finish>
__attribute__((target("avx2,fma"))) inline Real difference_product_rows(std::size_t begin, std::size_t end, const Vec4* a, const Vec4* b,
                                                                         const Index* neighbor_lists, const Index* neighbor_counts,
                                                                         const std::size_t* firsts, const Real* weights, Finish&& finish) {
  Real total = 0;
  for (std::size_t i = begin; i < end; ++i)
    total += finish(i, difference_products(a, b, neighbor_lists + firsts[i], weights + firsts[i], neighbor_counts[i], a[i], b[i]));
  return total;
}

/// The dot product of a and b in each 128-bit half, in all four of its lanes: (x + y) + (z + w), the
/// order vdpps adds in, from a multiply, two in-lane shuffles and two adds (vdpps, one instruction,
/// held up the viscous product: a third of its samples sat on the instruction after it).
__attribute__((target("avx2,fma"))) inline __m256 lane_dots(__m256 a, __m256 b) {
  const __m256 products = _mm256_mul_ps(a, b);
  const __m256 pairs = _mm256_add_ps(products, _mm256_permute_ps(products, _MM_SHUFFLE(2, 3, 0, 1)));  // x+y x+y z+w z+w
  return _mm256_add_ps(pairs, _mm256_permute_ps(pairs, _MM_SHUFFLE(1, 0, 3, 2)));
}

/// The implicit viscosity's product y = A x for the particles [begin, end) (see multiply_row in
/// viscosity_weiler2018.cpp): calls finish(i, y_i) with y_i = Σ_j c_ij r_ij r_ijᵀ (x_i − x_j) +
/// own_block_i x_i, x and the positions padded. One call per range rather than per particle: the
/// per-particle call and its result's round trip through memory cost as much as the pairs' sum.
template <class Finish>
__attribute__((target("avx2,fma"))) inline void viscous_product_rows(std::size_t begin, std::size_t end, const Vec4* position,
                                                                      const Vec4* operand, const Index* neighbor_lists,
                                                                      const Index* neighbor_counts, const std::size_t* firsts,
                                                                      const Real* coefficients, const Mat3* own_block, Finish&& finish) {
  for (std::size_t i = begin; i < end; ++i) {
    const Index* neighbor = neighbor_lists + firsts[i];
    const Real* coefficient = coefficients + firsts[i];
    const Index count = neighbor_counts[i];
    const __m256 position_i = broadcast(position[i]), operand_i = broadcast(operand[i]);
    __m256 sum = _mm256_setzero_ps();
    Index k = 0;
    for (; k + 1 < count; k += 2) {
      const Index j0 = neighbor[k], j1 = neighbor[k + 1];
      const __m256 r = _mm256_sub_ps(position_i, load_pair(position, j0, j1));
      const __m256 dot = lane_dots(r, _mm256_sub_ps(operand_i, load_pair(operand, j0, j1)));
      sum = _mm256_fmadd_ps(_mm256_mul_ps(dot, spread_pair(coefficient + k)), r, sum);
    }
    Vec4 result = halves_added(sum);
    if (k < count) {
      const Vec4 r = position[i] - position[neighbor[k]];
      result += (coefficient[k] * r.dot(operand[i] - operand[neighbor[k]])) * r;
    }
    finish(i, Vec3(result.head<3>() + own_block[i] * operand[i].head<3>()));
  }
}

/// r_k = c − v[neighbor[k]] for eight neighbours, as x, y and z lanes. The lanes hold the neighbours
/// in the order 0 2 4 6 1 3 5 7 (what the transpose gives for free); kNeighborOrderLanes undoes it.
struct EightDifferences {
  __m256 x, y, z;
};
__attribute__((target("avx2,fma"))) inline EightDifferences eight_differences(const Vec4* vectors, const Index* neighbor, __m256 center) {
  const __m256 r01 = _mm256_sub_ps(center, load_pair(vectors, neighbor[0], neighbor[1]));  // x0 y0 z0 0 | x1 y1 z1 0
  const __m256 r23 = _mm256_sub_ps(center, load_pair(vectors, neighbor[2], neighbor[3]));
  const __m256 r45 = _mm256_sub_ps(center, load_pair(vectors, neighbor[4], neighbor[5]));
  const __m256 r67 = _mm256_sub_ps(center, load_pair(vectors, neighbor[6], neighbor[7]));
  const __m256 xy0213 = _mm256_unpacklo_ps(r01, r23);  // x0 x2 y0 y2 | x1 x3 y1 y3
  const __m256 zw0213 = _mm256_unpackhi_ps(r01, r23);
  const __m256 xy4657 = _mm256_unpacklo_ps(r45, r67);
  const __m256 zw4657 = _mm256_unpackhi_ps(r45, r67);
  return {_mm256_shuffle_ps(xy0213, xy4657, _MM_SHUFFLE(1, 0, 1, 0)), _mm256_shuffle_ps(xy0213, xy4657, _MM_SHUFFLE(3, 2, 3, 2)),
          _mm256_shuffle_ps(zw0213, zw4657, _MM_SHUFFLE(1, 0, 1, 0))};
}

/// W and (dW/dr)/r of eight distances (the scalar kernels' formulas, lane by lane).
struct EightKernelValues {
  __m256 value, gradient_factor;
};
__attribute__((target("avx2,fma"))) inline EightKernelValues eight_kernel_values(const CubicSplineKernel& kernel, __m256 distance) {
  const __m256 inverse_support = _mm256_set1_ps(Real(1) / kernel.support_radius);
  const __m256 q = _mm256_mul_ps(distance, inverse_support);
  const __m256 one_minus_q = _mm256_sub_ps(_mm256_set1_ps(1), q);
  const __m256 value_coefficient = _mm256_set1_ps(kernel.value_coefficient);
  const __m256 gradient_coefficient = _mm256_set1_ps(kernel.gradient_coefficient);
  const __m256 q_squared = _mm256_mul_ps(q, q);
  const __m256 inner_value = _mm256_mul_ps(
      value_coefficient, _mm256_add_ps(_mm256_mul_ps(_mm256_set1_ps(6), _mm256_sub_ps(_mm256_mul_ps(q_squared, q), q_squared)), _mm256_set1_ps(1)));
  const __m256 outer_cube = _mm256_mul_ps(_mm256_mul_ps(one_minus_q, one_minus_q), one_minus_q);
  const __m256 outer_value = _mm256_mul_ps(_mm256_mul_ps(value_coefficient, _mm256_set1_ps(2)), outer_cube);
  const __m256 inner_gradient = _mm256_mul_ps(_mm256_mul_ps(gradient_coefficient, _mm256_sub_ps(_mm256_mul_ps(_mm256_set1_ps(3), q), _mm256_set1_ps(2))),
                                              _mm256_mul_ps(inverse_support, inverse_support));
  // Where the outer piece is not taken (q ≤ 1/2, coincident particles included) its 1/r is discarded.
  const __m256 outer_gradient = _mm256_div_ps(
      _mm256_mul_ps(_mm256_mul_ps(_mm256_sub_ps(_mm256_setzero_ps(), gradient_coefficient), _mm256_mul_ps(one_minus_q, one_minus_q)), inverse_support),
      distance);
  const __m256 inner = _mm256_cmp_ps(q, _mm256_set1_ps(0.5f), _CMP_LE_OQ);
  const __m256 inside = _mm256_cmp_ps(q, _mm256_set1_ps(1), _CMP_LE_OQ);
  return {_mm256_and_ps(inside, _mm256_blendv_ps(outer_value, inner_value, inner)),
          _mm256_and_ps(inside, _mm256_blendv_ps(outer_gradient, inner_gradient, inner))};
}
__attribute__((target("avx2,fma"))) inline EightKernelValues eight_kernel_values(const WendlandC2Kernel& kernel, __m256 distance) {
  const __m256 q = _mm256_mul_ps(distance, _mm256_set1_ps(Real(1) / kernel.support_radius));
  const __m256 one_minus_q = _mm256_sub_ps(_mm256_set1_ps(1), q);
  const __m256 squared = _mm256_mul_ps(one_minus_q, one_minus_q);
  const __m256 inside = _mm256_cmp_ps(q, _mm256_set1_ps(1), _CMP_LT_OQ);
  const __m256 value = _mm256_mul_ps(_mm256_mul_ps(_mm256_set1_ps(kernel.value_coefficient), _mm256_mul_ps(squared, squared)),
                                     _mm256_add_ps(_mm256_set1_ps(1), _mm256_mul_ps(_mm256_set1_ps(4), q)));
  const __m256 gradient = _mm256_mul_ps(_mm256_set1_ps(kernel.gradient_coefficient), _mm256_mul_ps(squared, one_minus_q));
  return {_mm256_and_ps(inside, value), _mm256_and_ps(inside, gradient)};
}

/// The sum of a __m256's eight lanes.
__attribute__((target("avx2,fma"))) inline Real lanes_added(__m256 sum) {
  __m128 four = _mm_add_ps(_mm256_castps256_ps128(sum), _mm256_extractf128_ps(sum, 1));
  four = _mm_add_ps(four, _mm_movehl_ps(four, four));
  four = _mm_add_ss(four, _mm_movehdup_ps(four));
  return _mm_cvtss_f32(four);
}

/// The implicit viscosity's pair coefficients for the particles [begin, end) (the set-up of
/// solve_implicit_viscosity): c_ij = s_i · 2 μ_i μ_j · (m_j/ρ_j) · g_ij / ((μ_i + μ_j)(|r_ij|² + ε)), zero where
/// μ_i + μ_j = 0, stored per pair; then finish(i, Σ_j c_ij r_ij r_ijᵀ). scale(i) is s_i. Eight pairs at a
/// time, the rest as the generic loop does them.
template <class Scale, class Finish>
__attribute__((target("avx2,fma"))) inline void viscous_coefficient_rows(std::size_t begin, std::size_t end, const Vec4* position,
                                                                          const Real* viscosity, const Real* mass, const Real* density,
                                                                          const Index* neighbor_lists, const Index* neighbor_counts,
                                                                          const std::size_t* firsts, const Real* pair_gradients, Real regularisation,
                                                                          Real* coefficients, Scale&& scale, Finish&& finish) {
  const __m256i transpose_order = _mm256_setr_epi32(0, 2, 4, 6, 1, 3, 5, 7);
  const __m256i neighbor_order = _mm256_setr_epi32(0, 4, 1, 5, 2, 6, 3, 7);
  const __m256 epsilon = _mm256_set1_ps(regularisation);
  for (std::size_t i = begin; i < end; ++i) {
    const Index* neighbor = neighbor_lists + firsts[i];
    const Real* pair_gradient = pair_gradients + firsts[i];
    Real* coefficient = coefficients + firsts[i];
    const Index count = neighbor_counts[i];
    const Real mu_i = viscosity[i], scale_i = scale(i);
    const __m256 center = broadcast(position[i]), mu_ii = _mm256_set1_ps(mu_i), numerator_i = _mm256_set1_ps(2 * scale_i * mu_i);
    __m256 xx = _mm256_setzero_ps(), xy = xx, xz = xx, yy = xx, yz = xx, zz = xx;
    Index k = 0;
    for (; k + 8 <= count; k += 8) {
      const EightDifferences r = eight_differences(position, neighbor + k, center);
      const __m256i indices = _mm256_permutevar8x32_epi32(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(neighbor + k)), transpose_order);
      const __m256 mu_j = _mm256_i32gather_ps(viscosity, indices, 4);
      const __m256 gradient = _mm256_permutevar8x32_ps(_mm256_loadu_ps(pair_gradient + k), transpose_order);
      const __m256 distance_squared = _mm256_fmadd_ps(r.x, r.x, _mm256_fmadd_ps(r.y, r.y, _mm256_mul_ps(r.z, r.z)));
      const __m256 numerator = _mm256_mul_ps(_mm256_mul_ps(numerator_i, mu_j), _mm256_mul_ps(_mm256_i32gather_ps(mass, indices, 4), gradient));
      const __m256 denominator = _mm256_mul_ps(_mm256_mul_ps(_mm256_add_ps(mu_ii, mu_j), _mm256_i32gather_ps(density, indices, 4)),
                                               _mm256_add_ps(distance_squared, epsilon));
      const __m256 c = _mm256_and_ps(_mm256_cmp_ps(denominator, _mm256_setzero_ps(), _CMP_GT_OQ), _mm256_div_ps(numerator, denominator));
      _mm256_storeu_ps(coefficient + k, _mm256_permutevar8x32_ps(c, neighbor_order));
      const __m256 cx = _mm256_mul_ps(c, r.x), cy = _mm256_mul_ps(c, r.y);
      xx = _mm256_fmadd_ps(cx, r.x, xx);
      xy = _mm256_fmadd_ps(cx, r.y, xy);
      xz = _mm256_fmadd_ps(cx, r.z, xz);
      yy = _mm256_fmadd_ps(cy, r.y, yy);
      yz = _mm256_fmadd_ps(cy, r.z, yz);
      zz = _mm256_fmadd_ps(_mm256_mul_ps(c, r.z), r.z, zz);
    }
    Mat3 coupling;
    coupling(0, 0) = lanes_added(xx);
    coupling(0, 1) = coupling(1, 0) = lanes_added(xy);
    coupling(0, 2) = coupling(2, 0) = lanes_added(xz);
    coupling(1, 1) = lanes_added(yy);
    coupling(1, 2) = coupling(2, 1) = lanes_added(yz);
    coupling(2, 2) = lanes_added(zz);
    for (; k < count; ++k) {
      const Index j = neighbor[k];
      const Vec3 r = (position[i] - position[j]).head<3>();
      const Real denominator = (mu_i + viscosity[j]) * density[j] * (r.squaredNorm() + regularisation);
      const Real c = denominator > 0 ? 2 * scale_i * mu_i * viscosity[j] * mass[j] * pair_gradient[k] / denominator : Real(0);
      coefficient[k] = c;
      coupling += c * r * r.transpose();
    }
    finish(i, coupling);
  }
}

/// The symmetric part of Σ_j w_j (v_j − v_i) r_ijᵀ, w_j = scale · (m_j/ρ_j) · g_ij, for the particles [begin, end)
/// that wants(i) (the velocity gradient of update_effective_viscosity); finish(i, that) for every one
/// (zero where not wanted). Eight pairs at a time, the rest as the generic loop does them.
template <class Wants, class Finish>
__attribute__((target("avx2,fma"))) inline void velocity_gradient_rows(std::size_t begin, std::size_t end, const Vec4* position,
                                                                        const Vec4* velocity, const Real* mass, const Real* density,
                                                                        const Index* neighbor_lists, const Index* neighbor_counts,
                                                                        const std::size_t* firsts, const Real* pair_gradients, Real scale,
                                                                        Wants&& wants, Finish&& finish) {
  const __m256i transpose_order = _mm256_setr_epi32(0, 2, 4, 6, 1, 3, 5, 7);
  const __m256 minus_scale = _mm256_set1_ps(-scale);
  for (std::size_t i = begin; i < end; ++i) {
    if (!wants(i)) {
      finish(i, Mat3::Zero().eval());
      continue;
    }
    const Index* neighbor = neighbor_lists + firsts[i];
    const Real* pair_gradient = pair_gradients + firsts[i];
    const Index count = neighbor_counts[i];
    const __m256 position_i = broadcast(position[i]), velocity_i = broadcast(velocity[i]);
    __m256 xx = _mm256_setzero_ps(), yy = xx, zz = xx, xy = xx, xz = xx, yz = xx;  // xy: Σ a_x r_y + a_y r_x, ...
    Index k = 0;
    for (; k + 8 <= count; k += 8) {
      const EightDifferences r = eight_differences(position, neighbor + k, position_i);
      const EightDifferences dv = eight_differences(velocity, neighbor + k, velocity_i);  // v_i − v_j
      const __m256i indices = _mm256_permutevar8x32_epi32(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(neighbor + k)), transpose_order);
      const __m256 gradient = _mm256_permutevar8x32_ps(_mm256_loadu_ps(pair_gradient + k), transpose_order);
      // −w: the differences are v_i − v_j.
      const __m256 weight = _mm256_div_ps(_mm256_mul_ps(_mm256_mul_ps(minus_scale, _mm256_i32gather_ps(mass, indices, 4)), gradient),
                                          _mm256_i32gather_ps(density, indices, 4));
      const __m256 ax = _mm256_mul_ps(weight, dv.x), ay = _mm256_mul_ps(weight, dv.y), az = _mm256_mul_ps(weight, dv.z);
      xx = _mm256_fmadd_ps(ax, r.x, xx);
      yy = _mm256_fmadd_ps(ay, r.y, yy);
      zz = _mm256_fmadd_ps(az, r.z, zz);
      xy = _mm256_fmadd_ps(ax, r.y, _mm256_fmadd_ps(ay, r.x, xy));
      xz = _mm256_fmadd_ps(ax, r.z, _mm256_fmadd_ps(az, r.x, xz));
      yz = _mm256_fmadd_ps(ay, r.z, _mm256_fmadd_ps(az, r.y, yz));
    }
    Mat3 gradient_sum;
    gradient_sum(0, 0) = lanes_added(xx);
    gradient_sum(1, 1) = lanes_added(yy);
    gradient_sum(2, 2) = lanes_added(zz);
    gradient_sum(0, 1) = gradient_sum(1, 0) = Real(0.5) * lanes_added(xy);
    gradient_sum(0, 2) = gradient_sum(2, 0) = Real(0.5) * lanes_added(xz);
    gradient_sum(1, 2) = gradient_sum(2, 1) = Real(0.5) * lanes_added(yz);
    Mat3 rest = Mat3::Zero();
    for (; k < count; ++k) {
      const Index j = neighbor[k];
      const Real weight = scale * (mass[j] / density[j]) * pair_gradient[k];
      rest += (weight * (velocity[j] - velocity[i]).head<3>()) * (position[i] - position[j]).head<3>().transpose();
    }
    finish(i, Mat3(gradient_sum + Real(0.5) * (rest + rest.transpose())));
  }
}

/// The density pass's sums over a particle's fluid neighbours, eight at a time (see
/// compute_density_and_factor in dfsph_bender2017.cpp): Σ V W_ij, Σ g_ij r_ij and Σ (m_i/m_j) |g_ij r_ij|²
/// with g_ij = V (dW/dr)/r, which is also stored per pair. Eight at a time, the last one to seven as a
/// masked group; returns how many neighbours it took (all of them).
struct DensityPairSums {
  Real density_ratio = 0;
  Vec3 gradient_sum = Vec3::Zero();
  Real gradient_squares = 0;
  Index pairs_done = 0;
};
/// The density pass's gradient sums, lane by lane: Σ g r (x, y and z) and Σ (m_i/m_j) |g r|².
struct GradientGroupSums {
  __m256 x, y, z, squares;  // no initialisers: the implicit constructor is not compiled for AVX
};
/// Adds one group of eight pairs (pair gradients g and differences r in transposed lanes; `group`, its
/// neighbours in list order). With kOneMass (every fluid particle of one mass: one rest density) the
/// mass ratios are 1, without the masses' gather and the division.
template <bool kOneMass>
__attribute__((target("avx2,fma"))) inline void add_gradient_group(__m256 pair, const EightDifferences& r, const Index* group,
                                                                    const Real* mass, __m256 mass_i_lanes, GradientGroupSums& sums) {
  const __m256 gx = _mm256_mul_ps(pair, r.x), gy = _mm256_mul_ps(pair, r.y), gz = _mm256_mul_ps(pair, r.z);
  sums.x = _mm256_add_ps(sums.x, gx);
  sums.y = _mm256_add_ps(sums.y, gy);
  sums.z = _mm256_add_ps(sums.z, gz);
  const __m256 squared = _mm256_fmadd_ps(gx, gx, _mm256_fmadd_ps(gy, gy, _mm256_mul_ps(gz, gz)));
  if constexpr (kOneMass) {
    sums.squares = _mm256_add_ps(sums.squares, squared);
  } else {
    const __m256i indices = _mm256_permutevar8x32_epi32(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(group)),
                                                        _mm256_setr_epi32(0, 2, 4, 6, 1, 3, 5, 7));  // transposed order
    sums.squares = _mm256_fmadd_ps(_mm256_div_ps(mass_i_lanes, _mm256_i32gather_ps(mass, indices, 4)), squared, sums.squares);
  }
}
template <bool kOneMass, class Kernel>
__attribute__((target("avx2,fma"))) inline DensityPairSums density_pair_sums(const Kernel& kernel, const Vec4* position, const Real* mass,
                                                                            const Index* neighbor, Index count, const Vec4& position_i,
                                                                            Real mass_i, Real volume, Real* pair_gradient) {
  const __m256 center = broadcast(position_i);
  const __m256 volume_lanes = _mm256_set1_ps(volume);
  const __m256 mass_i_lanes = _mm256_set1_ps(mass_i);
  const __m256i transpose_order = _mm256_setr_epi32(0, 2, 4, 6, 1, 3, 5, 7);
  const __m256i neighbor_order = _mm256_setr_epi32(0, 4, 1, 5, 2, 6, 3, 7);  // lanes back to neighbour order
  __m256 density = _mm256_setzero_ps();
  GradientGroupSums gradients{density, density, density, density};
  Index k = 0;
  for (; k + 8 <= count; k += 8) {
    const EightDifferences r = eight_differences(position, neighbor + k, center);
    const __m256 distance = _mm256_sqrt_ps(_mm256_fmadd_ps(r.x, r.x, _mm256_fmadd_ps(r.y, r.y, _mm256_mul_ps(r.z, r.z))));
    const EightKernelValues w = eight_kernel_values(kernel, distance);
    density = _mm256_fmadd_ps(volume_lanes, w.value, density);
    const __m256 pair = _mm256_mul_ps(volume_lanes, w.gradient_factor);
    _mm256_storeu_ps(pair_gradient + k, _mm256_permutevar8x32_ps(pair, neighbor_order));
    add_gradient_group<kOneMass>(pair, r, neighbor + k, mass, mass_i_lanes, gradients);
  }
  if (k < count) {
    // The last one to seven pairs as one masked group, not one by one in the caller's scalar loop,
    // where their branchy kernel made a tenth of the pairs a third of the pass. The empty lanes
    // repeat the last neighbour and count nothing, and their pair gradients are not stored.
    const Index left = count - k;
    Index tail[8];
    for (Index lane = 0; lane < 8; ++lane) tail[lane] = neighbor[k + std::min<Index>(lane, left - 1)];
    const __m256i left_lanes = _mm256_set1_epi32(static_cast<int>(left));
    const __m256 live = _mm256_castsi256_ps(_mm256_cmpgt_epi32(left_lanes, transpose_order));  // lanes in transposed order
    const __m256i stored = _mm256_cmpgt_epi32(left_lanes, _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7));  // in neighbour order
    const EightDifferences r = eight_differences(position, tail, center);
    const __m256 distance = _mm256_sqrt_ps(_mm256_fmadd_ps(r.x, r.x, _mm256_fmadd_ps(r.y, r.y, _mm256_mul_ps(r.z, r.z))));
    const EightKernelValues w = eight_kernel_values(kernel, distance);
    density = _mm256_fmadd_ps(volume_lanes, _mm256_and_ps(live, w.value), density);
    const __m256 pair = _mm256_and_ps(live, _mm256_mul_ps(volume_lanes, w.gradient_factor));
    _mm256_maskstore_ps(pair_gradient + k, stored, _mm256_permutevar8x32_ps(pair, neighbor_order));
    add_gradient_group<kOneMass>(pair, r, tail, mass, mass_i_lanes, gradients);
    k = count;
  }
  DensityPairSums sums;
  sums.density_ratio = lanes_added(density);
  sums.gradient_sum = Vec3(lanes_added(gradients.x), lanes_added(gradients.y), lanes_added(gradients.z));
  sums.gradient_squares = lanes_added(gradients.squares);
  sums.pairs_done = k;
  return sums;
}

/// The particle shifting's sums' lanes (no initialisers: the implicit constructor is not compiled for AVX).
struct ShiftingLanes {
  __m256 concentration, gx, gy, gz, wx, wy, wz;
};
/// Adds one group of eight neighbours; `live`: the lanes (in transposed order) that hold one.
template <class Kernel>
__attribute__((target("avx2,fma"))) inline void add_shifting_group(const Kernel& kernel, const Vec4* position, const Index* group, __m256 center,
                                                                    __m256 live, __m256 volume, __m256 reference, __m256 clumping,
                                                                    ShiftingLanes& sums) {
  const EightDifferences r = eight_differences(position, group, center);
  const __m256 distance = _mm256_sqrt_ps(_mm256_fmadd_ps(r.x, r.x, _mm256_fmadd_ps(r.y, r.y, _mm256_mul_ps(r.z, r.z))));
  const EightKernelValues w = eight_kernel_values(kernel, distance);
  const __m256 taken = _mm256_and_ps(live, _mm256_cmp_ps(distance, _mm256_setzero_ps(), _CMP_GT_OQ));  // not a coincident one
  const __m256 value = _mm256_and_ps(taken, w.value);
  const __m256 pair = _mm256_and_ps(taken, _mm256_mul_ps(volume, w.gradient_factor));
  sums.concentration = _mm256_fmadd_ps(volume, value, sums.concentration);
  const __m256 px = _mm256_mul_ps(pair, r.x), py = _mm256_mul_ps(pair, r.y), pz = _mm256_mul_ps(pair, r.z);
  sums.gx = _mm256_add_ps(sums.gx, px);
  sums.gy = _mm256_add_ps(sums.gy, py);
  sums.gz = _mm256_add_ps(sums.gz, pz);
  const __m256 relative = _mm256_mul_ps(value, reference);
  const __m256 squared = _mm256_mul_ps(relative, relative);
  const __m256 weight = _mm256_fmadd_ps(clumping, _mm256_mul_ps(squared, squared), _mm256_set1_ps(1));
  sums.wx = _mm256_fmadd_ps(weight, px, sums.wx);
  sums.wy = _mm256_fmadd_ps(weight, py, sums.wy);
  sums.wz = _mm256_fmadd_ps(weight, pz, sums.wz);
}
/// The particle shifting's sums over a particle's fluid neighbours at 0 < r < h (see shift_particles in
/// shifting/lind2012.cpp), for the particles [begin, end) that wants(i): finish(i, Σ V W_ij, Σ V g_ij r_ij,
/// Σ (1 + R (W_ij/W(d))⁴) V g_ij r_ij), g_ij = (dW/dr)/r; `reference` is 1/W(d), `clumping` R. Eight pairs
/// at a time, the last one to seven as a masked group (their kernel, branchy in the generic loop, selected).
template <class Kernel, class Wants, class Finish>
__attribute__((target("avx2,fma"))) inline void shifting_sum_rows(std::size_t begin, std::size_t end, const Kernel& kernel, const Vec4* position,
                                                                   const Index* neighbor_lists, const Index* neighbor_counts,
                                                                   const std::size_t* firsts, Real volume, Real reference, Real clumping,
                                                                   Wants&& wants, Finish&& finish) {
  const __m256i transpose_order = _mm256_setr_epi32(0, 2, 4, 6, 1, 3, 5, 7);
  const __m256 volume_lanes = _mm256_set1_ps(volume), reference_lanes = _mm256_set1_ps(reference);
  const __m256 clumping_lanes = _mm256_set1_ps(clumping), all = _mm256_castsi256_ps(_mm256_set1_epi32(-1));
  for (std::size_t i = begin; i < end; ++i) {
    if (!wants(i)) continue;
    const Index* neighbor = neighbor_lists + firsts[i];
    const Index count = neighbor_counts[i];
    const __m256 center = broadcast(position[i]);
    const __m256 zero = _mm256_setzero_ps();
    ShiftingLanes sums{zero, zero, zero, zero, zero, zero, zero};
    Index k = 0;
    for (; k + 8 <= count; k += 8)
      add_shifting_group(kernel, position, neighbor + k, center, all, volume_lanes, reference_lanes, clumping_lanes, sums);
    if (k < count) {  // the last one to seven: the empty lanes repeat the last neighbour and count nothing
      const Index left = count - k;
      Index tail[8];
      for (Index lane = 0; lane < 8; ++lane) tail[lane] = neighbor[k + std::min<Index>(lane, left - 1)];
      const __m256 live = _mm256_castsi256_ps(_mm256_cmpgt_epi32(_mm256_set1_epi32(static_cast<int>(left)), transpose_order));
      add_shifting_group(kernel, position, tail, center, live, volume_lanes, reference_lanes, clumping_lanes, sums);
    }
    finish(i, lanes_added(sums.concentration), Vec3(lanes_added(sums.gx), lanes_added(sums.gy), lanes_added(sums.gz)),
           Vec3(lanes_added(sums.wx), lanes_added(sums.wy), lanes_added(sums.wz)));
  }
}

}  // namespace m3dp::sph::avx2

/// AVX-512 versions, where the CPU has AVX-512F (and AVX2 and FMA: they fall back on the AVX2 pieces
/// for a list's last pairs), unless M3DP_NO_AVX512 or M3DP_NO_AVX2 is set. Four neighbours per 512-bit
/// instruction where the sum is over vectors. They round differently from the AVX2 loops (other
/// partial sums): a run is reproducible on one machine, as with AVX2.
// GCC 12's AVX-512 intrinsics fill their unused mask operands with _mm512_undefined_ps(), which its
// -Wmaybe-uninitialized takes for a read of an unset value (GCC bug 105593, fixed in 13).
#if !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#endif
namespace m3dp::sph::avx512 {
inline bool available() {
  static const bool supported = avx2::available() && __builtin_cpu_supports("avx512f") && !std::getenv("M3DP_NO_AVX512");
  return supported;
}
#define M3DP_TARGET_AVX512 __attribute__((target("avx512f,avx2,fma")))
/// Vectors j0..j3 of a padded array in the four 128-bit quarters.
M3DP_TARGET_AVX512 inline __m512 load_quad(const Vec4* vectors, const Index* j) {
  const __m512 low = _mm512_castps256_ps512(avx2::load_pair(vectors, j[0], j[1]));
  return _mm512_castpd_ps(_mm512_insertf64x4(_mm512_castps_pd(low), _mm256_castps_pd(avx2::load_pair(vectors, j[2], j[3])), 1));
}
/// (w0 ×4, w1 ×4, w2 ×4, w3 ×4) from four consecutive weights.
M3DP_TARGET_AVX512 inline __m512 spread_quad(const Real* weights) {
  return _mm512_permutexvar_ps(_mm512_setr_epi32(0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2, 2, 3, 3, 3, 3), _mm512_castps128_ps512(_mm_loadu_ps(weights)));
}
/// The dot product of a and b in each 128-bit quarter, in all four of its lanes, in avx2::lane_dots's order.
M3DP_TARGET_AVX512 inline __m512 lane_dots(__m512 a, __m512 b) {
  const __m512 products = _mm512_mul_ps(a, b);
  const __m512 pairs = _mm512_add_ps(products, _mm512_permute_ps(products, _MM_SHUFFLE(2, 3, 0, 1)));
  return _mm512_add_ps(pairs, _mm512_permute_ps(pairs, _MM_SHUFFLE(1, 0, 3, 2)));
}
/// avx2::viscous_product_rows four pairs at a time; the last one to three as AVX2 pairs and one alone.
template <class Finish>
M3DP_TARGET_AVX512 inline void viscous_product_rows(std::size_t begin, std::size_t end, const Vec4* position, const Vec4* operand,
                                                    const Index* neighbor_lists, const Index* neighbor_counts, const std::size_t* firsts,
                                                    const Real* coefficients, const Mat3* own_block, Finish&& finish) {
  for (std::size_t i = begin; i < end; ++i) {
    const Index* neighbor = neighbor_lists + firsts[i];
    const Real* coefficient = coefficients + firsts[i];
    const Index count = neighbor_counts[i];
    const __m512 position_i = _mm512_broadcast_f32x4(_mm_load_ps(position[i].data()));
    const __m512 operand_i = _mm512_broadcast_f32x4(_mm_load_ps(operand[i].data()));
    __m512 sum = _mm512_setzero_ps();
    Index k = 0;
    for (; k + 3 < count; k += 4) {
      const __m512 r = _mm512_sub_ps(position_i, load_quad(position, neighbor + k));
      const __m512 dot = lane_dots(r, _mm512_sub_ps(operand_i, load_quad(operand, neighbor + k)));
      sum = _mm512_fmadd_ps(_mm512_mul_ps(dot, spread_quad(coefficient + k)), r, sum);
    }
    __m256 half = _mm256_add_ps(_mm512_castps512_ps256(sum), _mm256_castpd_ps(_mm512_extractf64x4_pd(_mm512_castps_pd(sum), 1)));
    if (k + 1 < count) {
      const __m256 position_pair = _mm512_castps512_ps256(position_i), operand_pair = _mm512_castps512_ps256(operand_i);
      const __m256 r = _mm256_sub_ps(position_pair, avx2::load_pair(position, neighbor[k], neighbor[k + 1]));
      const __m256 dot = avx2::lane_dots(r, _mm256_sub_ps(operand_pair, avx2::load_pair(operand, neighbor[k], neighbor[k + 1])));
      half = _mm256_fmadd_ps(_mm256_mul_ps(dot, avx2::spread_pair(coefficient + k)), r, half);
      k += 2;
    }
    Vec4 result = avx2::halves_added(half);
    if (k < count) {
      const Vec4 r = position[i] - position[neighbor[k]];
      result += (coefficient[k] * r.dot(operand[i] - operand[neighbor[k]])) * r;
    }
    finish(i, Vec3(result.head<3>() + own_block[i] * operand[i].head<3>()));
  }
}

/// avx2::difference_products four pairs at a time: Σ_k w_k (a_i − a_j) ⊙ (b_i − b_j), lane by lane; the
/// last one to three as an AVX2 pair and the last neighbour weighted by the count's parity (as there).
M3DP_TARGET_AVX512 inline Vec4 difference_products(const Vec4* a, const Vec4* b, const Index* neighbor, const Real* weight, Index count,
                                                   const Vec4& a_i, const Vec4& b_i) {
  if (count == 0) return Vec4::Zero();
  const __m512 a_ii = _mm512_broadcast_f32x4(_mm_load_ps(a_i.data())), b_ii = _mm512_broadcast_f32x4(_mm_load_ps(b_i.data()));
  __m512 sum = _mm512_setzero_ps();
  Index k = 0;
  for (; k + 3 < count; k += 4) {
    const __m512 product = _mm512_mul_ps(_mm512_sub_ps(a_ii, load_quad(a, neighbor + k)), _mm512_sub_ps(b_ii, load_quad(b, neighbor + k)));
    sum = _mm512_fmadd_ps(spread_quad(weight + k), product, sum);
  }
  __m256 half = _mm256_add_ps(_mm512_castps512_ps256(sum), _mm256_castpd_ps(_mm512_extractf64x4_pd(_mm512_castps_pd(sum), 1)));
  const __m256 a_pair = _mm512_castps512_ps256(a_ii), b_pair = _mm512_castps512_ps256(b_ii);
  if (k + 1 < count) {
    const __m256 product = _mm256_mul_ps(_mm256_sub_ps(a_pair, avx2::load_pair(a, neighbor[k], neighbor[k + 1])),
                                         _mm256_sub_ps(b_pair, avx2::load_pair(b, neighbor[k], neighbor[k + 1])));
    half = _mm256_fmadd_ps(avx2::spread_pair(weight + k), product, half);
  }
  return avx2::halves_added(avx2::with_last_if_odd(a, b, neighbor, weight, count, a_pair, b_pair, half));
}
/// Σ_{i in [begin, end)} finish(i, difference_products of i): avx2::difference_product_rows four pairs at a time.
template <class Finish>
M3DP_TARGET_AVX512 inline Real difference_product_rows(std::size_t begin, std::size_t end, const Vec4* a, const Vec4* b, const Index* neighbor_lists,
                                                       const Index* neighbor_counts, const std::size_t* firsts, const Real* weights,
                                                       Finish&& finish) {
  Real total = 0;
  for (std::size_t i = begin; i < end; ++i)
    total += finish(i, difference_products(a, b, neighbor_lists + firsts[i], weights + firsts[i], neighbor_counts[i], a[i], b[i]));
  return total;
}
#undef M3DP_TARGET_AVX512
}  // namespace m3dp::sph::avx512
#if !defined(__clang__)
#pragma GCC diagnostic pop
#endif
#endif
