// The accumulated warp's row step (nsrr_warp.h) with AVX-512: 16 output pixels per step,
// the same operations in the same order as warp_row_scalar (no FMA contraction), so the same
// bits. Built with -mavx512f/vl/bw/dq (CMakeLists.txt); called only where default_isa() is
// avx512.
// GCC 12 takes the intrinsics' _mm512_undefined_* sources for uninitialised reads once the
// row loop branches (a false positive: under a full mask that source is never read).
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include <immintrin.h>

#include "upscale/nsrr_warp.h"

namespace kestrel::upscale::nsrr {

namespace {
// The smallest (kMax false) or largest of the lanes of m (m != 0).
template <bool kMax>
int reduce(__mmask16 m, __m512i q) {
  auto op = [](__m512i a, __m512i b) {
    return kMax ? _mm512_max_epi32(a, b) : _mm512_min_epi32(a, b);
  };
  __m512i v = _mm512_mask_blend_epi32(m, _mm512_set1_epi32(kMax ? -0x7FFFFFFF - 1 : 0x7FFFFFFF), q);
  v = op(v, _mm512_shuffle_i64x2(v, v, 0x4E));
  v = op(v, _mm512_shuffle_i64x2(v, v, 0xB1));
  v = op(v, _mm512_shuffle_epi32(v, _MM_PERM_BADC));
  v = op(v, _mm512_shuffle_epi32(v, _MM_PERM_CDAB));
  return _mm_cvtsi128_si32(_mm512_castsi512_si128(v));
}
int reduce_min(__mmask16 m, __m512i q) {
  return reduce<false>(m, q);
}
int reduce_max(__mmask16 m, __m512i q) {
  return reduce<true>(m, q);
}
// Lanes that index fewer than 32 neighbouring entries [lo, hi] of an array: two masked loads
// (only those entries read) and a two-source permute replace a gather, ~5 times slower here.
struct Span {
  int lo, hi;
  bool narrow() const { return hi - lo < 32; }
  // v[q - lo] for the lanes of m, 0 in the others.
  __m512 fetch(const float* v, __mmask16 m, __m512i q) const {
    const __m512i i = _mm512_sub_epi32(q, _mm512_set1_epi32(lo));
    const __m512 a = _mm512_maskz_loadu_ps(mask(0), v + lo),
                 b = _mm512_maskz_loadu_ps(mask(16), v + lo + 16);
    return _mm512_maskz_permutex2var_ps(m, a, i, b);
  }
  __m512i fetch(const int32_t* v, __mmask16 m, __m512i q, __m512i other) const {
    const __m512i i = _mm512_sub_epi32(q, _mm512_set1_epi32(lo));
    const __m512i a = _mm512_maskz_loadu_epi32(mask(0), v + lo),
                  b = _mm512_maskz_loadu_epi32(mask(16), v + lo + 16);
    return _mm512_mask_blend_epi32(m, other, _mm512_permutex2var_epi32(a, i, b));
  }
  // Entries [lo + from, lo + from + 16) that lie in [lo, hi].
  __mmask16 mask(int from) const {
    const int n = hi - lo + 1 - from;
    return n <= 0 ? __mmask16(0) : n >= 16 ? __mmask16(0xFFFF) : __mmask16((1u << n) - 1u);
  }
};
}  // namespace

void warp_row_avx512(const WarpRow& a, float* pos, int32_t* out) {
  const __m512 inv_f = _mm512_set1_ps(a.inv_f), half = _mm512_set1_ps(0.5f),
               one = _mm512_set1_ps(1.0f), f = _mm512_set1_ps(a.f), zero = _mm512_setzero_ps(),
               Wf = _mm512_set1_ps(float(a.W)), Hf = _mm512_set1_ps(float(a.H));
  const __m512i wmax = _mm512_set1_epi32(a.w - 1), hmax = _mm512_set1_epi32(a.h - 1),
                izero = _mm512_setzero_si512(), ione = _mm512_set1_epi32(1),
                w = _mm512_set1_epi32(a.w), none = _mm512_set1_epi32(-1);
  // Lane i of a 32-float (x, y) block: x at 2 i, y at 2 i + 1.
  const __m512i even = _mm512_set_epi32(30, 28, 26, 24, 22, 20, 18, 16, 14, 12, 10, 8, 6, 4, 2, 0);
  const __m512i odd = _mm512_add_epi32(even, ione);
  const __m512i lo = _mm512_set_epi32(23, 7, 22, 6, 21, 5, 20, 4, 19, 3, 18, 2, 17, 1, 16, 0);
  const __m512i hi = _mm512_add_epi32(lo, _mm512_set1_epi32(8));
  for (int X = 0; X < a.W; X += 16) {
    const int n = a.W - X < 16 ? a.W - X : 16;
    const __mmask16 m = __mmask16((1u << n) - 1u);
    const __mmask16 m0 = __mmask16(n >= 8 ? 0xFFFFu : (1u << (2 * n)) - 1u);
    const __mmask16 m1 = __mmask16(n <= 8 ? 0u : (1u << (2 * (n - 8))) - 1u);
    const __m512 p0 = _mm512_maskz_loadu_ps(m0, pos + 2 * X),
                 p1 = _mm512_maskz_loadu_ps(m1, pos + 2 * X + 16);
    __m512 px = _mm512_permutex2var_ps(p0, even, p1), py = _mm512_permutex2var_ps(p0, odd, p1);
    const __m512 xf = _mm512_sub_ps(_mm512_mul_ps(px, inv_f), half),
                 yf = _mm512_sub_ps(_mm512_mul_ps(py, inv_f), half);
    const __m512 fx = _mm512_floor_ps(xf), fy = _mm512_floor_ps(yf);
    const __m512i x0 = _mm512_cvttps_epi32(fx), y0 = _mm512_cvttps_epi32(fy);
    const __m512 tx = _mm512_sub_ps(xf, fx), ty = _mm512_sub_ps(yf, fy);
    const __m512i i0 = _mm512_min_epi32(_mm512_max_epi32(x0, izero), wmax),
                  i1 = _mm512_min_epi32(_mm512_max_epi32(_mm512_add_epi32(x0, ione), izero), wmax),
                  j0 = _mm512_mullo_epi32(_mm512_min_epi32(_mm512_max_epi32(y0, izero), hmax), w),
                  j1 = _mm512_mullo_epi32(
                      _mm512_min_epi32(_mm512_max_epi32(_mm512_add_epi32(y0, ione), izero), hmax),
                      w);
    const __m512 ux = _mm512_sub_ps(one, tx), uy = _mm512_sub_ps(one, ty);
    const __m512 w00 = _mm512_mul_ps(uy, ux), w01 = _mm512_mul_ps(uy, tx),
                 w10 = _mm512_mul_ps(ty, ux), w11 = _mm512_mul_ps(ty, tx);
    const __m512i q00 = _mm512_add_epi32(j0, i0), q01 = _mm512_add_epi32(j0, i1),
                  q10 = _mm512_add_epi32(j1, i0), q11 = _mm512_add_epi32(j1, i1);
    // The taps of each row: q00 <= q01 <= q00 + 1 (and q10, q11) in every lane.
    const Span top{reduce_min(m, q00), reduce_max(m, q01)},
        bottom{reduce_min(m, q10), reduce_max(m, q11)};
    auto fetch = [&](const float* img, const Span& s, __m512i q) {
      return s.narrow() ? s.fetch(img, m, q) : _mm512_mask_i32gather_ps(zero, m, q, img, 4);
    };
    auto bilinear = [&](const float* img) {
      __m512 v = _mm512_mul_ps(w00, fetch(img, top, q00));
      v = _mm512_add_ps(v, _mm512_mul_ps(w01, fetch(img, top, q01)));
      v = _mm512_add_ps(v, _mm512_mul_ps(w10, fetch(img, bottom, q10)));
      return _mm512_add_ps(v, _mm512_mul_ps(w11, fetch(img, bottom, q11)));
    };
    px = _mm512_add_ps(px, _mm512_mul_ps(f, bilinear(a.mx)));
    py = _mm512_add_ps(py, _mm512_mul_ps(f, bilinear(a.my)));
    _mm512_mask_storeu_ps(pos + 2 * X, m0, _mm512_permutex2var_ps(px, lo, py));
    _mm512_mask_storeu_ps(pos + 2 * X + 16, m1, _mm512_permutex2var_ps(px, hi, py));
    const __mmask16 inside =
        m & _mm512_cmp_ps_mask(px, zero, _CMP_GE_OQ) & _mm512_cmp_ps_mask(px, Wf, _CMP_LT_OQ) &
        _mm512_cmp_ps_mask(py, zero, _CMP_GE_OQ) & _mm512_cmp_ps_mask(py, Hf, _CMP_LT_OQ);
    __m512i src = none;
    if (inside) {
      // The row's and the column's tables: a table lookup each (nearby lanes, nearby entries).
      const __m512i qy = _mm512_cvttps_epi32(_mm512_floor_ps(py)),
                    qx = _mm512_cvttps_epi32(_mm512_floor_ps(px));
      auto table = [&](const int32_t* t, __m512i q) {
        const Span s{reduce_min(inside, q), reduce_max(inside, q)};
        return s.narrow() ? s.fetch(t, inside, q, none)
                          : _mm512_mask_i32gather_epi32(none, inside, q, t, 4);
      };
      const __m512i j = table(a.row_at, qy), i = table(a.col_at, qx);
      const __mmask16 both = _mm512_cmpge_epi32_mask(j, izero) & _mm512_cmpge_epi32_mask(i, izero);
      src = _mm512_mask_add_epi32(none, both, _mm512_mullo_epi32(j, w), i);
    }
    _mm512_mask_storeu_epi32(out + X, m, src);
  }
}

namespace {
// v with its 128-bit quarter r (0..3) replaced by x: a cell's row r of 4 pixels.
__m512i insert_row(__m512i v, __m128i x, int r) {
  switch (r) {  // _mm512_inserti32x4 takes its lane as a constant
    case 0:
      return _mm512_inserti32x4(v, x, 0);
    case 1:
      return _mm512_inserti32x4(v, x, 1);
    case 2:
      return _mm512_inserti32x4(v, x, 2);
    default:
      return _mm512_inserti32x4(v, x, 3);
  }
}
}  // namespace

void grid_rows_avx512(const GridFill& a, size_t gy0, size_t gy1) {
  // No gathers (slow where the Gather Data Sampling mitigation is on): a cell's 16 indices
  // are four row loads, and only its pixels that hold a sample (1 in f^2 on average) are
  // copied, one at a time, into the cell's 4 x 16 channel block.
  constexpr int kC = GridFill::kChannels, kX = GridFill::kX;
  const __m512i none = _mm512_set1_epi32(-1), izero = _mm512_setzero_si512(),
                round = _mm512_set1_epi32(0x7FFF), lsb = _mm512_set1_epi32(1);
  const size_t N = size_t(a.W) * size_t(a.H);
  // 16 channels at element `at` of the grid, bf16 (round to nearest even) or float.
  auto put = [&](size_t at, __m512 v) {
    if (a.bf16) {
      const __m512i u = _mm512_castps_si512(v);
      const __m512i rr = _mm512_add_epi32(
          u, _mm512_add_epi32(round, _mm512_and_si512(_mm512_srli_epi32(u, 16), lsb)));
      _mm256_storeu_si256(reinterpret_cast<__m256i*>(static_cast<uint16_t*>(a.grid) + at),
                          _mm512_cvtepi32_epi16(_mm512_srli_epi32(rr, 16)));
    } else {
      _mm512_storeu_ps(static_cast<float*>(a.grid) + at, v);
    }
  };
  for (size_t gy = gy0; gy < gy1; ++gy)
    for (size_t gx = 0; gx < size_t(a.Gw); ++gx) {
      const size_t cell = (gy * size_t(a.Gw) + gx) * size_t(kC);
      const int X0 = int(4 * gx), Y0 = int(4 * gy);
      const int cols = a.W - X0 < 4 ? (a.W - X0 > 0 ? a.W - X0 : 0) : 4;
      const int rows = a.H - Y0 < 4 ? (a.H - Y0 > 0 ? a.H - Y0 : 0) : 4;
      const __mmask8 cm = __mmask8((1u << cols) - 1u);
      for (int k = 0; k < GridFill::kFrames; ++k) {
        __m512i idx = none;
        if (k < a.frames)
          for (int r = 0; r < rows; ++r) {
            const int32_t* row = a.at[k] + size_t(Y0 + r) * size_t(a.W) + size_t(X0);
            idx = insert_row(idx, _mm_mask_loadu_epi32(_mm_set1_epi32(-1), cm, row), r);
          }
        alignas(64) int32_t lane_index[16];
        _mm512_store_si512(lane_index, idx);
        alignas(64) float block[kX][16] = {};
        const float* base = a.packed + size_t(k) * a.n * kX;
        for (unsigned m = _mm512_cmpge_epi32_mask(idx, izero); m; m &= m - 1) {
          const int lane = __builtin_ctz(m);
          const float* x = base + size_t(kX) * size_t(lane_index[lane]);
          for (int c = 0; c < kX; ++c) block[c][lane] = x[c];
        }
        for (int c = 0; c < kX; ++c)
          put(cell + size_t((kX * k + c) * 16), _mm512_load_ps(block[c]));
      }
      // The history's y: a cell's 16 pixels are four row loads per channel.
      for (size_t c = 0; c < 3; ++c) {
        __m512i v = _mm512_setzero_si512();
        for (int r = 0; r < rows; ++r) {
          const float* row = a.hist + c * N + size_t(Y0 + r) * size_t(a.W) + size_t(X0);
          v = insert_row(v, _mm_maskz_loadu_epi32(cm, row), r);
        }
        put(cell + size_t(GridFill::kHistory) + 16 * c, _mm512_castsi512_ps(v));
      }
      if (a.bf16)
        static_cast<uint16_t*>(a.grid)[cell + kC - 1] = float_to_bf16(a.last);
      else
        static_cast<float*>(a.grid)[cell + kC - 1] = a.last;
    }
}

}  // namespace kestrel::upscale::nsrr
