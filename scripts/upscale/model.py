"""kestrel's temporal upsampler, the reference definition (the engine computes the same
function: src/upscale/upscale.cpp; docs/upscaler.md explains the design).

A learned TAAU. Per frame the low-resolution colour (point-sampled at the frame's jitter
(jx, jy): pixel (i, j) holds the sample at (i + jx, j + jy)), its depth and motion vectors
(pixels of the low-resolution frame; the surface seen at p was at p + m before) are merged
with a full-resolution history, the previous output:

  y = c / (1 + L(c))                    every colour in this reversible tone-mapped space
  m* = motion of the nearest surface (least depth) in the 3x3 neighbourhood
  H  = Catmull-Rom(history, X + 0.5 + f m*)          the reprojected history, clamped to
                                                     the range of its 2x2 central taps
  Hc = clamp(H, mu - gamma sigma, mu + gamma sigma)  mu, sigma: 3x3 neighbourhood of y
  C  = sum_k w_k y_k / sum_k w_k,  w_k = exp(-2 d_k^2)  the 3x3 samples nearest the pixel
  alpha = a * exp(-kappa (f d0)^2), 1 where the history is missing, off screen or
          disoccluded (keep_history: no previous depth near the reprojected position matches)
  out = Hc + alpha (C - Hc)

d_k: distance from the output pixel's centre to sample k, in low-resolution pixels; d0: to
the nearest sample. The TAAU-like baseline uses constants (a, gamma, kappa); the network
predicts them per pixel from features of the current frame against the reprojected
history (luminance differences, neighbourhood contrast, depth change, motion, depth edges),
on a grid at 1/4 of the output resolution (2x2-pooled low-resolution features at factor 2,
the low-resolution pixels themselves at factor 4); the decoded constants are bilinearly
upsampled.
"""
import torch
import torch.nn as nn
import torch.nn.functional as F

LUMA = (0.2126, 0.7152, 0.0722)
FEATURES = 11
OUTPUTS = 3
CURRENT_SHARPNESS = 2.0
# The TAAU-like baseline's constants (a, gamma, kappa); train.py --tune-taau picks them on the
# training clips, and the network starts from them.
TAAU = dict(a=0.6, gamma=0.75, kappa=0.0625)
MIN_DEPTH = 1e-3
DISOCCLUSION = 0.1  # relative depth difference beyond which a history sample is another surface


def luma(x):
    return LUMA[0] * x[:, 0:1] + LUMA[1] * x[:, 1:2] + LUMA[2] * x[:, 2:3]


def to_y(c):
    c = torch.clamp(torch.nan_to_num(c, nan=0.0, posinf=0.0, neginf=0.0), min=0.0)
    return c / (1.0 + luma(c))


def from_y(y):
    y = torch.clamp(y, min=0.0)
    return y / torch.clamp(1.0 - luma(y), min=1e-3)


def gather2d(img, ix, iy):
    """img (B,C,H,W); ix, iy (B,1,h,w) long, already clamped -> (B,C,h,w)."""
    B, C, H, W = img.shape
    idx = (iy * W + ix).view(B, 1, -1).expand(B, C, -1)
    return torch.gather(img.reshape(B, C, H * W), 2, idx).view(B, C, *ix.shape[2:])


def bilinear_at(img, x, y):
    """Samples img at continuous pixel coordinates (pixel centres at k + 0.5), edges clamped."""
    H, W = img.shape[2:]
    xf, yf = x - 0.5, y - 0.5
    x0, y0 = torch.floor(xf), torch.floor(yf)
    tx, ty = xf - x0, yf - y0
    x0, y0 = x0.long(), y0.long()
    out = 0
    for dy, wy in ((0, 1 - ty), (1, ty)):
        for dx, wx in ((0, 1 - tx), (1, tx)):
            out = out + wy * wx * gather2d(img, (x0 + dx).clamp(0, W - 1), (y0 + dy).clamp(0, H - 1))
    return out


def catmull_rom_weights(t):
    t2, t3 = t * t, t * t * t
    return (-0.5 * t3 + t2 - 0.5 * t, 1.5 * t3 - 2.5 * t2 + 1.0, -1.5 * t3 + 2.0 * t2 + 0.5 * t, 0.5 * t3 - 0.5 * t2)


def catmull_rom_at(img, x, y, footprint=False):
    """Catmull-Rom at continuous coordinates (pixel centres at k + 0.5, edges clamped); with
    footprint, clamped per channel to the range of the 2x2 central taps (no overshoot)."""
    H, W = img.shape[2:]
    xf, yf = x - 0.5, y - 0.5
    x1, y1 = torch.floor(xf), torch.floor(yf)
    wx, wy = catmull_rom_weights(xf - x1), catmull_rom_weights(yf - y1)
    x1, y1 = x1.long(), y1.long()
    out, central = 0, []
    for j in range(4):
        row = 0
        iy = (y1 + j - 1).clamp(0, H - 1)
        for i in range(4):
            t = gather2d(img, (x1 + i - 1).clamp(0, W - 1), iy)
            row = row + wx[i] * t
            if i in (1, 2) and j in (1, 2):
                central.append(t)
        out = out + wy[j] * row
    if footprint:
        lo = torch.minimum(torch.minimum(central[0], central[1]), torch.minimum(central[2], central[3]))
        hi = torch.maximum(torch.maximum(central[0], central[1]), torch.maximum(central[2], central[3]))
        out = torch.minimum(torch.maximum(out, lo), hi)
    return out


def neighbours(img):
    """3x3 neighbourhood, edges replicated: (B,C,h,w) -> list of 9 (B,C,h,w), row-major."""
    p = F.pad(img, (1, 1, 1, 1), mode="replicate")
    h, w = img.shape[2:]
    return [p[:, :, dy:dy + h, dx:dx + w] for dy in range(3) for dx in range(3)]


def dilate_motion(depth, motion):
    """The motion of the least-depth pixel (0 = sky, farthest) of each 3x3 neighbourhood."""
    d = torch.where(depth > 0, depth, torch.full_like(depth, 3e38))
    dn = torch.cat(neighbours(d), 1)
    k = torch.argmin(dn, dim=1, keepdim=True)
    mn = torch.stack(neighbours(motion), 1)  # B,9,2,h,w
    return torch.gather(mn, 1, k.unsqueeze(2).expand(-1, 1, 2, -1, -1)).squeeze(1)


def keep_history(depth, prev_depth, mdil, jx, jy, prev_jitter):
    """(B,1,h,w): 1 where one of the four previous samples around where this pixel's sample
    was (its position plus m, the least-depth motion the history is fetched with, in the
    previous frame's sample grid, jitter included; edges clamped) has a depth within
    DISOCCLUSION of the current depth plus its slope (the change to the neighbour on the
    smoother side, in x plus in y: at most a pixel separates the two frames' samples), or
    both are sky; 0 where the history shows another surface (a disocclusion)."""
    B, _, h, w = depth.shape
    dev = depth.device
    ii = torch.arange(w, device=dev, dtype=torch.float32).view(1, 1, 1, w)
    jj = torch.arange(h, device=dev, dtype=torch.float32).view(1, 1, h, 1)
    qx = torch.floor(ii + jx.view(B, 1, 1, 1) + mdil[:, 0:1] - prev_jitter[:, 0].view(B, 1, 1, 1)).long()
    qy = torch.floor(jj + jy.view(B, 1, 1, 1) + mdil[:, 1:2] - prev_jitter[:, 1].view(B, 1, 1, 1)).long()
    dn = neighbours(depth)  # the depth slope: the change to the smoother side's neighbour
    slope = (torch.minimum(torch.abs(dn[3] - depth), torch.abs(dn[5] - depth))
             + torch.minimum(torch.abs(dn[1] - depth), torch.abs(dn[7] - depth)))
    tol = DISOCCLUSION * torch.clamp(depth, min=MIN_DEPTH) + slope
    same = torch.zeros_like(depth, dtype=torch.bool)
    for b in (0, 1):
        for a in (0, 1):
            dq = gather2d(prev_depth, (qx + a).clamp(0, w - 1), (qy + b).clamp(0, h - 1))
            both = (depth > 0) & (dq > 0)
            same |= torch.where(both, torch.abs(dq - depth) <= tol, (depth > 0) == (dq > 0))
    return same.float()


def features(y, depth, mdil, state, f, jx, jy):
    """Low-resolution features (B,8,h,w) and the neighbourhood statistics (mu, sigma)."""
    B, _, h, w = y.shape
    nb = neighbours(y)
    mu = sum(nb) / 9.0
    sigma = torch.sqrt(torch.clamp(sum(n * n for n in nb) / 9.0 - mu * mu, min=0.0))
    L, muL, sigL = luma(y), luma(mu), luma(sigma)
    zero = torch.zeros_like(L)
    dev = y.device
    ii = torch.arange(w, device=dev, dtype=torch.float32).view(1, 1, 1, w)
    jj = torch.arange(h, device=dev, dtype=torch.float32).view(1, 1, h, 1)
    if state is None:
        valid, Lh, dchange = zero, L, zero
    else:
        hist, prev_depth = state[0], state[1]
        H, W = hist.shape[2:]
        hx = f * (ii + jx.view(B, 1, 1, 1) + mdil[:, 0:1])
        hy = f * (jj + jy.view(B, 1, 1, 1) + mdil[:, 1:2])
        valid = ((hx >= 0) & (hx < W) & (hy >= 0) & (hy < H)).float()
        Lh = luma(bilinear_at(hist, hx, hy))
        px = torch.floor(ii + 0.5 + mdil[:, 0:1]).clamp(0, w - 1).long()
        py = torch.floor(jj + 0.5 + mdil[:, 1:2]).clamp(0, h - 1).long()
        dp = gather2d(prev_depth, px, py)
        both = (depth > 0) & (dp > 0)
        one = (depth > 0) != (dp > 0)
        rel = torch.clamp((dp - depth) / torch.clamp(depth, min=MIN_DEPTH), -1.0, 1.0)
        dchange = torch.where(both, rel, torch.where(one, torch.ones_like(rel), zero))
    mmag = torch.clamp(torch.sqrt(mdil[:, 0:1] ** 2 + mdil[:, 1:2] ** 2) / 8.0, max=1.0)
    dn = neighbours(depth)
    edge = torch.abs(dn[1] - depth)
    for k in (3, 5, 7):
        edge = torch.maximum(edge, torch.abs(dn[k] - depth))
    edge = torch.clamp(edge / torch.clamp(depth, min=MIN_DEPTH), max=1.0)
    feat = torch.cat([L, (Lh - L) * valid, sigL, (Lh - muL) * valid, dchange * valid, mmag, valid, edge], 1)
    return feat, mu, sigma


def pool_features(feat, f):
    """Low-resolution features -> the grid at 1/4 of the output: 8 means, 2 max-abs, f/4."""
    absf = torch.abs(feat[:, [1, 4]])
    if f == 2:
        h, w = feat.shape[2:]
        pad = (0, w % 2, 0, h % 2)
        feat = F.avg_pool2d(F.pad(feat, pad, mode="replicate"), 2)
        absf = F.max_pool2d(F.pad(absf, pad, mode="replicate"), 2)
    const = torch.full_like(feat[:, :1], f / 4.0)
    return torch.cat([feat, absf, const], 1)


class Upsampler(nn.Module):
    def __init__(self, width=16):
        super().__init__()
        self.c1 = nn.Conv2d(FEATURES, width, 3, padding=1)
        self.c2 = nn.Conv2d(width, width, 3, padding=1)
        self.c3 = nn.Conv2d(width, width, 3, padding=1)
        self.head = nn.Conv2d(width, OUTPUTS, 3, padding=1)
        self.set_constants(**TAAU)

    def set_constants(self, a, gamma, kappa):
        """Starts the network at the TAAU-like baseline: a zero head with these biases."""
        with torch.no_grad():
            self.head.weight.zero_()
            self.head.bias.copy_(torch.tensor(raw_params(a, gamma, kappa)))

    def params(self, grid):
        x = F.relu(self.c1(grid))
        x = F.relu(self.c2(x))
        x = F.relu(self.c3(x))
        return self.head(x)


def softplus(x):
    return torch.where(x > 20, x, torch.log1p(torch.exp(torch.clamp(x, max=20))))


def raw_params(a, gamma, kappa):
    import math
    inv_softplus = lambda v: math.log(math.expm1(v))
    return [math.log(a / (1 - a)), inv_softplus(gamma), inv_softplus(kappa)]


def decode(p):
    """Raw outputs -> (a, gamma, kappa)."""
    return torch.sigmoid(p[:, 0:1]), softplus(p[:, 1:2]), softplus(p[:, 2:3])


def upsample_params(p, H, W):
    """Grid (1/4 of the output) -> output resolution, bilinear, edges clamped."""
    dev = p.device
    X = torch.arange(W, device=dev, dtype=torch.float32).view(1, 1, 1, W).expand(p.shape[0], 1, H, W)
    Y = torch.arange(H, device=dev, dtype=torch.float32).view(1, 1, H, 1).expand(p.shape[0], 1, H, W)
    return bilinear_at(p, (X + 0.5) / 4.0, (Y + 0.5) / 4.0)


def step(color, depth, motion, jitter, f, state, model=None, constants=None):
    """One frame. color (B,3,h,w) linear, depth (B,1,h,w), motion (B,2,h,w), jitter (B,2),
    f in {2, 4}; state: None or (history y (B,3,fh,fw), previous depth, previous jitter). Returns the linear
    output (B,3,fh,fw), its y and the new state."""
    B, _, h, w = color.shape
    H, W = f * h, f * w
    dev = color.device
    y = to_y(color)
    depth = torch.nan_to_num(depth, nan=0.0, posinf=0.0, neginf=0.0).clamp(min=0.0)
    motion = torch.nan_to_num(motion, nan=0.0, posinf=0.0, neginf=0.0).clamp(-65536.0, 65536.0)
    jx, jy = jitter[:, 0].float(), jitter[:, 1].float()
    mdil = dilate_motion(depth, motion)
    feat, mu, sigma = features(y, depth, mdil, state, f, jx, jy)
    if model is not None:
        q = upsample_params(torch.cat(decode(model.params(pool_features(feat, f))), 1), H, W)
        a, gamma, kappa = q[:, 0:1], q[:, 1:2], q[:, 2:3]
    else:
        c = constants or TAAU
        a, gamma, kappa = (torch.full((B, 1, H, W), c[k], device=dev) for k in ("a", "gamma", "kappa"))
    X = torch.arange(W, device=dev, dtype=torch.float32).view(1, 1, 1, W)
    Y = torch.arange(H, device=dev, dtype=torch.float32).view(1, 1, H, 1)
    u = (X + 0.5) / f - jx.view(B, 1, 1, 1)  # output centre relative to the sample grid
    v = (Y + 0.5) / f - jy.view(B, 1, 1, 1)
    i0 = torch.floor(u + 0.5).clamp(0, w - 1)
    j0 = torch.floor(v + 0.5).clamp(0, h - 1)
    i0l, j0l = i0.long().expand(B, 1, H, W), j0.long().expand(B, 1, H, W)
    # Current frame: Gaussian-weighted 3x3 samples (separable weights).
    num, den = 0, 0
    for dj in (-1, 0, 1):
        wy = torch.exp(-CURRENT_SHARPNESS * (v - (j0 + dj)) ** 2)
        for di in (-1, 0, 1):
            wgt = wy * torch.exp(-CURRENT_SHARPNESS * (u - (i0 + di)) ** 2)
            num = num + wgt * gather2d(y, (i0l + di).clamp(0, w - 1), (j0l + dj).clamp(0, h - 1))
            den = den + wgt
    cur = num / den
    d0 = (u - i0) ** 2 + (v - j0) ** 2
    conf = torch.exp(-kappa * (f * f) * d0)
    m = gather2d(mdil, i0l, j0l)
    mu_p, sig_p = gather2d(mu, i0l, j0l), gather2d(sigma, i0l, j0l)
    if state is None:
        out_y = cur
    else:
        hist = state[0]
        hx = X + 0.5 + f * m[:, 0:1]
        hy = Y + 0.5 + f * m[:, 1:2]
        keep = gather2d(keep_history(depth, state[1], mdil, jx, jy, state[2]), i0l, j0l)
        valid = ((hx >= 0) & (hx < W) & (hy >= 0) & (hy < H)).float() * keep
        hc = catmull_rom_at(hist, hx, hy, footprint=True)
        hc = torch.minimum(torch.maximum(hc, mu_p - gamma * sig_p), mu_p + gamma * sig_p)
        alpha = valid * (a * conf) + (1 - valid)
        out_y = hc + alpha * (cur - hc)
    return from_y(out_y), out_y, (out_y, depth, jitter.float())


def run_sequence(seq, jit, f, model=None, constants=None):
    """step over a whole sequence from its first frame: seq (B,T,6,h,w) (colour, depth,
    motion), jit (B,T,2) -> list of y outputs per frame."""
    state, outs = None, []
    for t in range(seq.shape[1]):
        x = seq[:, t]
        _, y, state = step(x[:, 0:3], x[:, 3:4], x[:, 4:6], jit[:, t], f, state, model=model, constants=constants)
        outs.append(y)
    return outs


def bilinear_upscale(color, jitter, f, cubic=False):
    """The spatial baselines: the current frame alone, bilinear or Catmull-Rom bicubic, with
    the jitter accounted for (sample (i, j) sits at (i + jx, j + jy))."""
    B, _, h, w = color.shape
    H, W = f * h, f * w
    c = torch.clamp(torch.nan_to_num(color, nan=0.0, posinf=0.0, neginf=0.0), min=0.0)
    X = torch.arange(W, dtype=torch.float32).view(1, 1, 1, W).expand(B, 1, H, W)
    Y = torch.arange(H, dtype=torch.float32).view(1, 1, H, 1).expand(B, 1, H, W)
    x = (X + 0.5) / f - jitter[:, 0].view(B, 1, 1, 1) + 0.5
    y = (Y + 0.5) / f - jitter[:, 1].view(B, 1, 1, 1) + 0.5
    out = catmull_rom_at(c, x, y) if cubic else bilinear_at(c, x, y)
    return torch.clamp(out, min=0.0)


def halton(base, index):
    f, r = 1.0, 0.0
    while index > 0:
        f /= base
        r += f * (index % base)
        index //= base
    return r


def jitter_of(frame):
    """kestrel's 1-spp / --fixed-jitter sample position of a frame (Halton 2, 3 at frame + 1)."""
    return halton(2, frame + 1), halton(3, frame + 1)
