// Included by kernels.inl (inside namespace kestrel::denoise::KESTREL_ISA_NS): the two bounds
// of the neural denoiser's recurrence, the history clamp and the firefly clamp (model.py).

// The 4x4 block maxima and minima of this frame's irradiance (ws.xlin) per quarter-res cell,
// into ws.bound (per channel: maxima, then minima): the history clamp's bounds and the
// firefly spreading's brightest samples.
static void block_bounds(Workspace& ws, int W, int H) {
  const int Wq = W / 4, Hq = H / 4;
  const size_t Nq = size_t(Wq) * size_t(Hq);
  ws.bound.resize(6 * Nq);
  parallel_rows(Hq, 8, [&](int r0, int r1) {
    for (int c = 0; c < 3; ++c)
      for (int qy = r0; qy < r1; ++qy)
        for (int qx = 0; qx < Wq; ++qx) {
          const float* x0 = ws.xlin.ch(c) + size_t(qy * 4) * size_t(W) + size_t(qx * 4);
          float hi = x0[0], lo = x0[0];
          for (int sy = 0; sy < 4; ++sy) {
            const float* x = x0 + size_t(sy) * size_t(W);
            for (int sx = 0; sx < 4; ++sx) {
              hi = x[sx] > hi ? x[sx] : hi;
              lo = x[sx] < lo ? x[sx] : lo;
            }
          }
          const size_t q = size_t(qy) * size_t(Wq) + size_t(qx);
          ws.bound[size_t(2 * c) * Nq + q] = hi;
          ws.bound[size_t(2 * c + 1) * Nq + q] = lo;
        }
  });
}

// The history clamp (model.py): yw = clamp(yw, A, B), A per channel the 3x3 minimum over
// quarter-res cells of the 4x4 block minima of the current irradiance (a 12x12 window), B the
// 5x5 maximum of their maxima (a 20x20 window: sparse bright light keeps its history where a
// 12x12 window holds no bright sample this frame). Needs block_bounds of this frame.
static void clamp_history(Workspace& ws, int W, int H) {
  const int Wq = W / 4, Hq = H / 4;
  const size_t Nq = size_t(Wq) * size_t(Hq);
  ws.bound3.resize(ws.bound.size());
  parallel_rows(Hq, 8, [&](int r0, int r1) {
    for (int c = 0; c < 3; ++c)
      for (int qy = r0; qy < r1; ++qy)
        for (int qx = 0; qx < Wq; ++qx) {
          const size_t q = size_t(qy) * size_t(Wq) + size_t(qx);
          const float* bh = ws.bound.data() + size_t(2 * c) * Nq;
          const float* bl = bh + Nq;
          float hi = bh[q], lo = bl[q];
          for (int dy = -kHistoryMaxReach; dy <= kHistoryMaxReach; ++dy)
            for (int dx = -kHistoryMaxReach; dx <= kHistoryMaxReach; ++dx) {
              const int y = qy + dy, x = qx + dx;
              if (y < 0 || y >= Hq || x < 0 || x >= Wq) continue;
              const size_t k = size_t(y) * size_t(Wq) + size_t(x);
              hi = bh[k] > hi ? bh[k] : hi;
              if (dy >= -1 && dy <= 1 && dx >= -1 && dx <= 1) lo = bl[k] < lo ? bl[k] : lo;
            }
          ws.bound3[size_t(2 * c) * Nq + q] = hi;
          ws.bound3[size_t(2 * c + 1) * Nq + q] = lo;
        }
  });
  parallel_rows(H, 8, [&](int r0, int r1) {
    for (int c = 0; c < 3; ++c)
      for (int y = r0; y < r1; ++y) {
        const float* hi = ws.bound3.data() + size_t(2 * c) * Nq + size_t(y / 4) * size_t(Wq);
        const float* lo = hi + Nq;
        float* yw = ws.yw.ch(c) + size_t(y) * size_t(W);
        for (int i = 0; i < W; ++i) {
          const float v = yw[i] < hi[i / 4] ? yw[i] : hi[i / 4];
          yw[i] = v > lo[i / 4] ? v : lo[i / 4];
        }
      }
  });
}

// The second largest so far (top2 = max(top2, min(top1, q)), top1 = max(top1, q): model.py's
// order).
static inline void add_neighbour(float& top1, float& top2, float q) {
  const float lo = top1 < q ? top1 : q;
  top2 = top2 > lo ? top2 : lo;
  top1 = top1 > q ? top1 : q;
}

// The largest and second largest of pixel i's 8 neighbours, a, b, d the rows above, at and
// below (all inside the image), in model.py's order.
static inline void neighbours_top2(const float* __restrict a, const float* __restrict b,
                                   const float* __restrict d, int i, float& top1, float& top2) {
  top1 = 0.0f, top2 = 0.0f;
  add_neighbour(top1, top2, a[i - 1]);
  add_neighbour(top1, top2, a[i]);
  add_neighbour(top1, top2, a[i + 1]);
  add_neighbour(top1, top2, b[i - 1]);
  add_neighbour(top1, top2, b[i + 1]);
  add_neighbour(top1, top2, d[i - 1]);
  add_neighbour(top1, top2, d[i]);
  add_neighbour(top1, top2, d[i + 1]);
}

// The same for pixel (x, y) of a W-wide plane whose neighbours may lie outside the
// image_w x image_h image (the padding included): those count as 0.
static inline void neighbours_top2_checked(const float* plane, int W, int x, int y, int image_w,
                                           int image_h, float& top1, float& top2) {
  top1 = 0.0f, top2 = 0.0f;
  for (int dy = -1; dy <= 1; ++dy)
    for (int dx = -1; dx <= 1; ++dx) {
      const int yy = y + dy, xx = x + dx;
      if (dy == 0 && dx == 0) continue;
      const bool inside = yy >= 0 && yy < image_h && xx >= 0 && xx < image_w;
      add_neighbour(top1, top2, inside ? plane[size_t(yy) * size_t(W) + size_t(xx)] : 0.0f);
    }
}

// r cut to max(m + kappa max(mu - (r + m1) s, 0), 4 yw valid): m1, m the largest and second
// largest neighbour, mu the 12x12 window's mean, s r's own share of it (r's share and its
// brightest neighbour's at the same weight taken out: a firefly does not raise its own
// allowance, nor do two adjacent ones each other's), yw the history.
static inline float firefly_cut(float r, float m1, float m, float kappa, float mu, float s,
                                float yw, float valid) {
  const float others = mu - (r + m1) * s;
  const float t = m + kappa * (others > 0.0f ? others : 0.0f);
  const float hist = kHistoryAllowance * (yw * valid);
  const float bound = t > hist ? t : hist;
  return r < bound ? r : bound;
}

// The firefly bound over pixels [i0, i1) of a row whose neighbours are all inside the image:
// a, b, d the rows above, at and below; restrict-qualified so that it vectorises.
static void firefly_row(int i0, int i1, const float* __restrict a, const float* __restrict b,
                        const float* __restrict d, const float* __restrict kappa,
                        const float* __restrict mu, const float* __restrict share,
                        const float* __restrict yw, const float* __restrict valid,
                        float* __restrict out) {
  for (int i = i0; i < i1; ++i) {
    float top1, top2;
    neighbours_top2(a, b, d, i, top1, top2);
    out[i] = firefly_cut(b[i], top1, top2, kappa[i], mu[i], share[i], yw[i], valid[i]);
  }
}

// model.py's output_clamp and the remodulation over pixels [i0, i1) of a row whose neighbours
// are all inside the image: o = max(min(r, max(m, yw [n >= kHistoryEvidence])), 0) d, m the
// second largest of r's 8 neighbours (a, b, d the rows above, at and below), yw the warped
// history, n its warped length (0 where the history is not valid, so the bar also tests
// validity), d the demodulation; restrict-qualified so that it vectorises.
static inline float output_cut(float r, float m, float yw, float n, float dm) {
  const float hist = n >= kHistoryEvidence ? yw : 0.0f;
  const float bound = m > hist ? m : hist, v = r < bound ? r : bound;
  return (v > 0.0f ? v : 0.0f) * dm;
}

static void output_row(int i0, int i1, const float* __restrict a, const float* __restrict b,
                       const float* __restrict d, const float* __restrict yw,
                       const float* __restrict n, const float* __restrict dm,
                       float* __restrict out) {
  for (int i = i0; i < i1; ++i) {
    float top1, top2;
    neighbours_top2(a, b, d, i, top1, top2);
    out[i] = output_cut(b[i], top2, yw[i], n[i], dm[i]);
  }
}

// model.own_counts: along an axis of n positions (the first `inside` the image's, the rest
// copies of its last one), how many times each position's value counts in its window mean
// (a 3-cell box, edge cells replicated, over 4-pixel cells), its copies included.
static std::vector<float> own_counts(int n, int inside) {
  const int cells = n / 4;
  std::vector<float> counts(static_cast<size_t>(n));
  for (int x = 0; x < n; ++x) {
    const int c = x / 4;
    const int window[3] = {std::clamp(c - 1, 0, cells - 1), c, std::clamp(c + 1, 0, cells - 1)};
    const int q0 = x < inside - 1 ? x : inside - 1, q1 = x < inside - 1 ? x + 1 : n;
    int k = 0;
    for (int q = q0; q < q1; ++q)
      for (int j : window) k += j == q / 4 ? 1 : 0;
    counts[size_t(x)] = float(k);
  }
  return counts;
}

// model.py's window_mean of each of src's 3 channels, per quarter-res cell: the 3x3 box (edge
// cells replicated) over the cells' 4x4 block means (into `cells`), into `means`.
static void window_means(const Planes& src, int W, int H, std::vector<float>& cells,
                         std::vector<float>& means) {
  const int Wq = W / 4, Hq = H / 4;
  const size_t Nq = size_t(Wq) * size_t(Hq);
  cells.resize(3 * Nq), means.resize(3 * Nq);
  parallel_rows(Hq, 8, [&](int r0, int r1) {
    for (int c = 0; c < 3; ++c)
      for (int qy = r0; qy < r1; ++qy)
        for (int qx = 0; qx < Wq; ++qx) {
          float s = 0.0f;
          for (int sy = 0; sy < 4; ++sy) {
            const float* x = src.ch(c) + size_t(qy * 4 + sy) * size_t(W) + size_t(qx * 4);
            s += x[0] + x[1] + x[2] + x[3];
          }
          cells[size_t(c) * Nq + size_t(qy) * size_t(Wq) + size_t(qx)] = s * (1.0f / 16.0f);
        }
  });
  parallel_rows(Hq, 8, [&](int r0, int r1) {
    for (int c = 0; c < 3; ++c)
      for (int qy = r0; qy < r1; ++qy)
        for (int qx = 0; qx < Wq; ++qx) {
          float s = 0.0f;
          for (int dy = -1; dy <= 1; ++dy)
            for (int dx = -1; dx <= 1; ++dx) {
              const int y = std::clamp(qy + dy, 0, Hq - 1), x = std::clamp(qx + dx, 0, Wq - 1);
              s += cells[size_t(c) * Nq + size_t(y) * size_t(Wq) + size_t(x)];
            }
          means[size_t(c) * Nq + size_t(qy) * size_t(Wq) + size_t(qx)] = s * (1.0f / 9.0f);
        }
  });
}

// model.py's firefly_clamp on this frame's irradiance (ws.xlin) into ws.xo:
// min(r, max(m + kappa max(mu - (r + m1) s, 0), 4 yw valid)) (s: own_counts / 144), m1 and m the
// largest and second largest of the 8 neighbours inside the image_w x image_h image (outside ones
// count as 0: a firefly on the border is not its own neighbour), mu the 3x3 box (edge replicated)
// over quarter-res cells of 4x4 block means, kappa the activation map 17 upsampled as alpha is
// (ws.hrows).
static void firefly_clamp(Workspace& ws, int W, int H, int image_w, int image_h) {
  const int Wq = W / 4, Hq = H / 4;
  const size_t Nq = size_t(Wq) * size_t(Hq);
  const Planes& r = ws.xlin;
  window_means(r, W, H, ws.mu, ws.mu3);
  const size_t hplane = size_t(Hq) * size_t(W);
  const std::vector<float> ox = own_counts(W, image_w), oy = own_counts(H, image_h);
  parallel_rows(H, 8, [&](int r0, int r1) {
    std::vector<float> kappa(static_cast<size_t>(W)), mu_row(static_cast<size_t>(W)),
        share(static_cast<size_t>(W));
    for (int y = r0; y < r1; ++y) {
      const UpTap ty = up_tap(y, Hq, 0.25f);
      const float* top =
          ws.hrows.data() + size_t(kOutputs - 1) * hplane + size_t(ty.i0) * size_t(W);
      const float* bot =
          ws.hrows.data() + size_t(kOutputs - 1) * hplane + size_t(ty.i1) * size_t(W);
      for (int i = 0; i < W; ++i) kappa[size_t(i)] = top[i] * (1 - ty.f) + bot[i] * ty.f;
      // Neighbours outside the image (the padding included) count as 0: the rows and columns
      // at the image's edges and beyond it take the checked path, the rest the plain one.
      const size_t row = size_t(y) * size_t(W);
      const bool inner_row = y >= 1 && y + 1 < image_h;
      for (int i = 0; i < W; ++i) share[size_t(i)] = ox[size_t(i)] * oy[size_t(y)] / 144.0f;
      for (int c = 0; c < 3; ++c) {
        const float* b = r.ch(c) + row;
        const float *a = b - (y >= 1 ? W : 0), *d = b + (y + 1 < H ? W : 0);
        const float* mu = ws.mu3.data() + size_t(c) * Nq + size_t(y / 4) * size_t(Wq);
        float* out = ws.xo.ch(c) + row;
        const float* yw = ws.yw.ch(c) + row;
        const float* valid = ws.valid.data() + row;
        auto checked = [&](int i) {
          float top1, top2;
          neighbours_top2_checked(r.ch(c), W, i, y, image_w, image_h, top1, top2);
          out[i] = firefly_cut(b[i], top1, top2, kappa[size_t(i)], mu[i / 4], share[size_t(i)],
                               yw[i], valid[i]);
        };
        const int i1 = inner_row ? std::min(image_w - 1, W) : 0;
        if (i1 > 0) checked(0);
        if (i1 > 1) {
          for (int i = 1; i < i1; ++i) mu_row[size_t(i)] = mu[i / 4];
          firefly_row(1, i1, a, b, d, kappa.data(), mu_row.data(), share.data(), yw, valid, out);
        }
        for (int i = i1 > 0 ? i1 : 0; i < W; ++i) checked(i);
      }
    }
  });
}

// model.py's redistribute: the energy the firefly cut took (ws.xlin - ws.xo) spread over its
// 12x12 window, ws.xo += min(mean(r - rc), kRedistributeCap mean(rc)), at most the window's
// brightest sample. mean(r - rc) is firefly_clamp's window mean of r (ws.mu3) less that of rc,
// both summed in the same order (rc <= r, so the difference is never negative); the maximum
// over the same cells, from block_bounds of this frame.
static void redistribute(Workspace& ws, int W, int H) {
  const int Wq = W / 4, Hq = H / 4;
  const size_t Nq = size_t(Wq) * size_t(Hq);
  window_means(ws.xo, W, H, ws.cells, ws.cut3);
  ws.top3.resize(3 * Nq);  // per channel and cell: the window's brightest sample of r
  parallel_rows(Hq, 8, [&](int r0, int r1) {
    for (int c = 0; c < 3; ++c)
      for (int qy = r0; qy < r1; ++qy)
        for (int qx = 0; qx < Wq; ++qx) {
          const float* mx = ws.bound.data() + size_t(2 * c) * Nq;  // block maxima
          float hi = mx[size_t(qy) * size_t(Wq) + size_t(qx)];
          for (int dy = -1; dy <= 1; ++dy)
            for (int dx = -1; dx <= 1; ++dx) {
              const int y = std::clamp(qy + dy, 0, Hq - 1), x = std::clamp(qx + dx, 0, Wq - 1);
              const float v = mx[size_t(y) * size_t(Wq) + size_t(x)];
              hi = v > hi ? v : hi;
            }
          ws.top3[size_t(c) * Nq + size_t(qy) * size_t(Wq) + size_t(qx)] = hi;
        }
  });
  parallel_rows(H, 8, [&](int r0, int r1) {
    for (int c = 0; c < 3; ++c)
      for (int y = r0; y < r1; ++y) {
        const size_t cells = size_t(c) * Nq + size_t(y / 4) * size_t(Wq);
        const float *mu = ws.mu3.data() + cells, *cut = ws.cut3.data() + cells,
                    *hi = ws.top3.data() + cells;
        float* rc = ws.xo.ch(c) + size_t(y) * size_t(W);
        for (int i = 0; i < W; ++i) {
          const float e = mu[i / 4] - cut[i / 4], cap = kRedistributeCap * cut[i / 4];
          const float v = rc[i] + (e < cap ? e : cap);
          rc[i] = v < hi[i / 4] ? v : hi[i / 4];
        }
      }
  });
}
