// The reconstruction loop (model.step) for one instruction set; included by reconstruct_*.cpp
// inside a namespace of their own, after sampling.inl.
static void reconstruct_rows(const Recon& a, int r0, int r1) {
  std::vector<float> vert(3 * size_t(a.w) + 1, 0.0f), gv(3 * size_t(a.gw) + 1, 0.0f);
  for (int Y = r0; Y < r1; ++Y) {
    const int j0 = a.ay->i0[size_t(Y)];
    const float* wy = &a.ay->w[3 * size_t(Y)];
    const float dy0 = a.ay->d0[size_t(Y)];
    const int rows[3] = {clampi(j0 - 1, 0, a.h - 1), j0, clampi(j0 + 1, 0, a.h - 1)};
    const float ty = a.gy->t[size_t(Y)];
    const float* ga = &a.grid[size_t(a.gy->a[size_t(Y)]) * size_t(a.gw) * 3];
    const float* gb = &a.grid[size_t(a.gy->b[size_t(Y)]) * size_t(a.gw) * 3];
    // The current frame's three rows, weighted for this output row: vert[i] = sum_b wy_b y(i,
    // row_b).
    const float* y0 = &a.y[size_t(rows[0]) * size_t(a.w) * 3];
    const float* y1 = &a.y[size_t(rows[1]) * size_t(a.w) * 3];
    const float* y2 = &a.y[size_t(rows[2]) * size_t(a.w) * 3];
    for (size_t q = 0; q < 3 * size_t(a.w); ++q)
      vert[q] = wy[0] * y0[q] + wy[1] * y1[q] + wy[2] * y2[q];
    for (size_t q = 0; q < 3 * size_t(a.gw); ++q) gv[q] = (1 - ty) * ga[q] + ty * gb[q];
    for (int X = 0; X < a.W; ++X) {
      const int i0 = a.ax->i0[size_t(X)];
      const float* wx = &a.ax->w[3 * size_t(X)];
      const int cols[3] = {clampi(i0 - 1, 0, a.w - 1), i0, clampi(i0 + 1, 0, a.w - 1)};
      __m128 cur = _mm_mul_ps(_mm_set1_ps(wx[0]), _mm_loadu_ps(&vert[size_t(cols[0]) * 3]));
      cur =
          _mm_add_ps(cur, _mm_mul_ps(_mm_set1_ps(wx[1]), _mm_loadu_ps(&vert[size_t(cols[1]) * 3])));
      cur =
          _mm_add_ps(cur, _mm_mul_ps(_mm_set1_ps(wx[2]), _mm_loadu_ps(&vert[size_t(cols[2]) * 3])));
      cur =
          _mm_mul_ps(cur, _mm_set1_ps(1.0f / ((wx[0] + wx[1] + wx[2]) * (wy[0] + wy[1] + wy[2]))));
      const size_t P = size_t(Y) * size_t(a.W) + size_t(X);
      float* o = &a.next[3 * P];
      if (!a.history) {
        store3(o, cur);
      } else {
        const size_t pl = size_t(j0) * size_t(a.w) + size_t(i0);
        const float hx = float(X) + 0.5f + float(a.f) * a.mdil[2 * pl],
                    hy = float(Y) + 0.5f + float(a.f) * a.mdil[2 * pl + 1];
        const bool valid =
            hx >= 0 && hx < float(a.W) && hy >= 0 && hy < float(a.H) && a.keep[pl] != 0;
        // Parameters: bilinear from the grid (the rows already blended into gv).
        const float tx = a.gx->t[size_t(X)];
        alignas(16) float prm[4];
        _mm_store_ps(
            prm,
            _mm_add_ps(
                _mm_mul_ps(_mm_set1_ps(1 - tx), _mm_loadu_ps(&gv[3 * size_t(a.gx->a[size_t(X)])])),
                _mm_mul_ps(_mm_set1_ps(tx), _mm_loadu_ps(&gv[3 * size_t(a.gx->b[size_t(X)])]))));
        const float dx0 = a.ax->d0[size_t(X)];
        const float conf = std::exp(-prm[2] * float(a.f * a.f) * (dx0 * dx0 + dy0 * dy0));
        const float alpha = valid ? prm[0] * conf : 1.0f;
        const __m128 hc = sample_catmull_rom3<true>(a.hist, a.W, a.H, hx, hy);
        const __m128 m = _mm_loadu_ps(&a.mu[3 * pl]),
                     sg = _mm_mul_ps(_mm_set1_ps(prm[1]), _mm_loadu_ps(&a.sigma[3 * pl]));
        const __m128 v = _mm_min_ps(_mm_max_ps(hc, _mm_sub_ps(m, sg)), _mm_add_ps(m, sg));
        store3(o, _mm_add_ps(v, _mm_mul_ps(_mm_set1_ps(alpha), _mm_sub_ps(cur, v))));
      }
      float yc[3] = {std::max(o[0], 0.0f), std::max(o[1], 0.0f), std::max(o[2], 0.0f)};
      const float s = 1.0f / std::max(1.0f - luma(yc), 1e-3f);
      float* lin = a.out + 3 * P;
      lin[0] = yc[0] * s, lin[1] = yc[1] * s, lin[2] = yc[2] * s;
    }
  }
}
