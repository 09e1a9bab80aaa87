"""kestrel's denoiser, the reference definition (training; the C++ engine in
src/denoise/kernels.inl computes the same function, checked by tests/denoise parity).

Architecture 4. Per frame, at full resolution H x W (padded to multiples of 8 by edge
replication):
  d  = albedo + EPS, or 1 where the albedo is (nearly) black (max < 0.02): demodulation only
       where it is safe (emitters, black and mirror-black pixels are filtered as colour)
  r  = colour / d                                  demodulated irradiance (linear)
  x  = log(1 + r)                                  its HDR transfer (features, guides)
  yw, zw, nw = the previous frame's state (accumulated irradiance after the first filter
           level, depth, history length) warped
           by the motion vectors (bilinear, clamped); valid = the previous position lies
           inside the image, its depth is within 10 % (disocclusion: the history is
           rejected, 0 on frame 0) and its warped black flag equals this pixel's (every tap
           of the bilinear warp demodulated as p is: no irradiance in a black pixel's
           radiance history, nor the reverse); nw = 0 where not valid
  yw = clamp(yw, A, B): the history clamped to the darkest and brightest current samples
       near p (A = 3x3 min over quarter-res cells of the 4x4 block minima of r, per channel:
       a 12x12 window; B = 5x5 max over the block maxima, a 20x20 window: since 2026-12-05,
       where a 12x12 window that held no bright sample in a frame cut sparse light's history
       down, 0.69 of its mean after 8 frames of 1 sample in 64 carrying it, 0.86 with 20x20),
       which rejects history that a lighting change made too bright (a light went out) or
       too dark (a light came on; at 1 spp A is 0 in most windows, but not where every
       sample is lit), and bounds the state
  features (18): x, albedo, normal, roughness, log(1 + yw), valid, |zw - z| / z, relative
                 depth gradient, mean(x)^2, 1 / (1 + nw)
A small CNN at 1/4 and 1/8 resolution (4x4 average pool in) predicts 18 maps per
quarter-res pixel, activated there (sigmoid / softplus) and bilinearly upsampled: a temporal
blend weight alpha, for each of 4 a-trous levels (3x3 taps, dilation 1, 2, 4, 8)
edge-stopping strengths for colour, normal (at least SN_MIN = 2) and depth (at least
SZ_MIN = 3) and a mix weight beta, and a firefly allowance kappa.
  rc = min(r, max(m + kappa * mo, 4 yw valid))     fireflies of this frame: m = the second
       largest of the 8 neighbours' r (per channel; neighbours outside the image count as 0,
       so a firefly on the border is not its own neighbour, and a pair does not shield
       itself), mu = the mean r of a 12x12 window (3x3 box over quarter-res cells of 4x4
       block means), mo = max(mu - (r + m1) s, 0) that mean without r's own share s
       (own_share: 1/144 inside; more on the border, where the box counts edge cells twice
       and the padding holds copies of the edge pixels) nor, at the same weight, its largest
       neighbour m1's (two adjacent fireflies do not raise each other's allowance): a
       firefly does not raise its own allowance (since 2026-12-04, a fixed rule added after
       the weights were trained: a 2-spp sample 3e4 times its neighbours had made mu ~200x
       their level); kappa -> 0 is a full neighbourhood clamp, kappa large leaves r alone;
       where the history is valid nothing up to 4x it is cut (ordinary noise of a static
       scene passes, so its mean converges; a firefly 100x the history is cut to 4x).
       Cut before it enters the history: a firefly in the state would be smeared over 2x2
       pixels by the next warp, where no neighbourhood test finds it
  rc += min(mean12(r - rc), REDISTRIBUTE_CAP mean12(rc)), then at most max12(r)
                                                   the cut energy spread over the 12x12
       window (redistribute; since 2026-12-05): the cut alone dropped it (outputs 5-8 %
       dark on held-out clips, 19-23 % on sunlit interiors)
  a  = alpha * nw / (1 + nw)                       the history's weight: at most a running
                                                   mean over the frames it holds
  r0 = rc + a * (yw - rc),  n = min(1 / (1 - a), NMAX)
The filter averages *linear* irradiance (no log-domain bias) with weights from log irradiance:
  r_{l+1} = r_l + beta_l * (sum_q h_q w_q r_l(q) / sum_q h_q w_q - r_l),  from r0
  w_q = exp(-sc |g(p) - g(q)|^2 - sn max(0, n_p.n_p - n_p.n_q) - sz |z_p - z_q| / max(z_p, 1e-3)),
  g = log(1 + r_l), and w_q = 0 where q and p differ in demodulation (one black, one not): a
  black pixel's r is radiance, its neighbours' irradiance, and the two do not mix (a dark
  car window among white paint took the paint's irradiance, x 1, and came out grey)
  (n_p.n_p rather than 1: the centre tap weighs exactly 1 even where there is no normal, so
  the sum of weights never vanishes)
  ro = min(r_4, max(m4, yw [n >= 2]))             the output's isolated bright pixels: m4 = the
       second largest of r_4's 8 neighbours (inside the image, as for rc), so a pixel that
       the edge stops kept brighter than all but one of its neighbours, and than its valid
       history, comes out at that level (since 2026-12-06, a fixed rule added after the
       weights were trained: fireflies on edges and in disocclusions survived the filter,
       up to 7x the reference's brightest pixel on held-out clips); a line or a blob keeps
       its level, a pixel that was as bright in a history of at least HISTORY_EVIDENCE = 2
       frames (the warped length n: a small lamp) keeps it; the state is r_1, before this
       step. (Earlier on 2026-12-06 any valid history counted: a history of one frame is
       one sample, no more evidence than the pixel's own, and a held-out gallery clip's
       sparse light kept a 1-spp sample at 2.2x the reference's brightest pixel through it.)
The output colour is max(ro, 0) * d; (r_1, z, n, black) is the recurrent state: the first level's
output, as SVGF's first pass (architecture 3 fed back r_4, filtered at dilations up to 8,
which blurs more every frame, so the network had kept its weight small; r0 itself converged
~5x slower on a static noisy sequence). Every step is a convex combination or a clamp from above (alpha,
beta in (0, 1), normalised positive weights, bilinear warps, rc <= max12(r)), so no output
irradiance exceeds the brightest current sample of its 20x20 window or of the filter's
footprint: the recurrence cannot amplify.
"""
import torch
import torch.nn as nn
import torch.nn.functional as F

EPS = 0.01
BLACK = 0.02  # albedo below this (every channel): no demodulation
DISOCCLUDED = 0.1  # relative depth change that rejects the history
LEVELS = 4
FEATURES = 18
OUTPUTS = 2 + 4 * LEVELS  # alpha, 4 x (sc, sn, sz, beta), kappa
ZMIN = 1e-3
NMAX = 32.0  # the longest history (frames) the state counts
SN_MIN, SZ_MIN = 2.0, 3.0  # the weakest normal and depth edge stops: geometry edges always hold
REDISTRIBUTE_CAP = 1.0  # the cut energy spread over a window raises its mean at most this much (x its cut mean)
HISTORY_MAX_CELLS = 5  # the history's upper clamp: the brightest sample of a 20x20 window (5x5 cells)
HISTORY_ALLOWANCE = 4.0  # a sample up to 4x its (valid) history is never cut as a firefly
HISTORY_EVIDENCE = 2.0  # the output's last step takes a history as evidence from this length (frames)
# 3x3 a-trous taps (dy, dx, h): h = (1/4, 1/2, 1/4) x (1/4, 1/2, 1/4), times 4 (centre 1).
TAPS = [(dy, dx, (2.0 if dy == 0 else 1.0) * (2.0 if dx == 0 else 1.0) / 4.0) for dy in (-1, 0, 1) for dx in (-1, 0, 1)]


def pad8(t):
    h, w = t.shape[-2:]
    ph, pw = (-h) % 8, (-w) % 8
    return F.pad(t, (0, pw, 0, ph), mode="replicate") if (ph or pw) else t


def warp(img, motion):
    """img (B,C,H,W) sampled at p + motion (pixels), bilinear with clamped coordinates;
    returns the warped image and the in-bounds mask (B,1,H,W)."""
    b, _, h, w = img.shape
    ys, xs = torch.meshgrid(torch.arange(h, dtype=img.dtype), torch.arange(w, dtype=img.dtype), indexing="ij")
    px = xs[None] + motion[:, 0]
    py = ys[None] + motion[:, 1]
    valid = ((px >= -0.5) & (px <= w - 0.5) & (py >= -0.5) & (py <= h - 0.5)).to(img.dtype)[:, None]
    gx = 2 * px.clamp(0, w - 1) / max(w - 1, 1) - 1
    gy = 2 * py.clamp(0, h - 1) / max(h - 1, 1) - 1
    grid = torch.stack([gx, gy], dim=-1)
    out = F.grid_sample(img, grid, mode="bilinear", padding_mode="border", align_corners=True)
    return out, valid


def shift(t, dy, dx):
    """t(p + (dy, dx)) with edge replication."""
    if dy == 0 and dx == 0:
        return t
    h, w = t.shape[-2:]
    p = max(abs(dy), abs(dx))
    tp = F.pad(t, (p, p, p, p), mode="replicate")
    return tp[..., p + dy:p + dy + h, p + dx:p + dx + w]


def is_black(albedo):
    """1 where every channel of the albedo is below BLACK (not demodulated), else 0."""
    return (albedo.max(dim=1, keepdim=True).values < BLACK).to(albedo.dtype)


def demodulation(albedo):
    """albedo + EPS per channel, 1 where every channel is below BLACK."""
    a = albedo.clamp(min=0)
    black = is_black(albedo)
    return (a + EPS) * (1 - black) + black


def shift0(t, dy, dx):
    """t(p + (dy, dx)), 0 outside."""
    h, w = t.shape[-2:]
    tp = F.pad(t, (1, 1, 1, 1))
    return tp[..., 1 + dy:1 + dy + h, 1 + dx:1 + dx + w]


def own_counts(n, inside):
    """Per position along one axis of n (the image's `inside` first ones, the rest their last
    one replicated by pad8): how many times the value there counts along that axis of its
    12x12 window mean (a pixel's share is the product of its two axes' counts / 144). The window is a 3-cell box (edge cells
    replicated) over 4-pixel cells, so a value counts once per window cell holding one of its
    copies: 1 inside, 2 in a cell on the grid's edge (its replicated neighbour), more where
    pad8 copied an edge pixel into the padding."""
    cells = n // 4
    counts = []
    for x in range(n):
        c = x // 4
        window = [min(max(c - 1, 0), cells - 1), c, min(max(c + 1, 0), cells - 1)]
        copies = [x] if x < inside - 1 else range(inside - 1, n)
        counts.append(float(sum(window.count(q // 4) for q in copies)))
    return counts


def own_share(mu, size=None):
    """The weight of each pixel's own value in the 12x12 window mean mu (.., H, W), its copies
    in the padding included: 1/144 inside the image; more in the cells on the grid's edge and
    next to the padding (since 2026-12-04: fireflies on the image's border had kept their
    own allowance). size: (h, w) of the image inside the padding (None: all)."""
    H, W = mu.shape[-2], mu.shape[-1]
    h, w = size if size is not None else (H, W)
    oy = torch.tensor(own_counts(H, h), dtype=mu.dtype, device=mu.device)
    ox = torch.tensor(own_counts(W, w), dtype=mu.dtype, device=mu.device)
    return (oy[:, None] * ox[None, :]) * (1.0 / 144.0)


def window_mean(t):
    """The 12x12 window mean: a 3x3 box (edge cells replicated) over quarter-res cells of 4x4
    block means, nearest upsampled (every pixel of a cell has its cell's window)."""
    mu = F.avg_pool2d(t, 4)
    mu = F.avg_pool2d(F.pad(mu, (1, 1, 1, 1), mode="replicate"), 3, stride=1)
    return F.interpolate(mu, scale_factor=4, mode="nearest")


def window_max(t, cells=3):
    """The 12x12 window maximum on the same cells (3x3 max over 4x4 block maxima); cells=5:
    the 20x20 window around them."""
    hi = F.max_pool2d(F.max_pool2d(t, 4), cells, stride=1, padding=cells // 2)
    return F.interpolate(hi, scale_factor=4, mode="nearest")


def neighbour_top2(r, size=None):
    """The largest and second largest of each pixel's 8 neighbours (per channel), neighbours
    outside the image (size = (h, w) inside the padding, None: all) counting as 0."""
    inside = r
    if size is not None:
        h, w = size
        mask = torch.zeros_like(r[:, :1])
        mask[..., :h, :w] = 1
        inside = r * mask
    top1, top2 = torch.zeros_like(r), torch.zeros_like(r)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            if dy or dx:
                q = shift0(inside, dy, dx)
                top2 = torch.maximum(top2, torch.minimum(top1, q))
                top1 = torch.maximum(top1, q)
    return top1, top2


def output_clamp(r, size=None, history=None):
    """min(r, max(m, history)): m the second largest of the 8 neighbours inside the image
    (neighbour_top2), history the warped history where valid and at least HISTORY_EVIDENCE
    frames long, 0 elsewhere (None: none). A
    pixel brighter than all but one of its neighbours and than its history -- a firefly the
    edge stops kept -- comes out at its neighbours' level."""
    bound = neighbour_top2(r, size)[1]
    if history is not None:
        bound = torch.maximum(bound, history)
    return torch.minimum(r, bound)


def firefly_clamp(r, kappa, size=None, history=None):
    """min(r, max(m + kappa * max(mu - (r + m1) s, 0), HISTORY_ALLOWANCE * history)) (s =
    own_share, 1/144 away from the border; m1 the largest neighbour): m the second largest of the 8 neighbours inside the image (size
    = (h, w) of the image inside the padding, None: all; outside neighbours count as 0, so a
    firefly on the border is not its own neighbour; the second largest, so a pair of
    fireflies does not shield itself), mu the 12x12 window mean (3x3 box over quarter-res 4x4
    block means, edge replicated, nearest upsampled); history = the warped history where
    valid, 0 elsewhere (None: no history)."""
    top1, top2 = neighbour_top2(r, size)
    mu = window_mean(r)
    # mu without r's own share, nor its brightest neighbour's (at r's weight): a pair of
    # adjacent fireflies does not raise each other's allowance
    bound = top2 + kappa * (mu - (r + top1) * own_share(mu, size)).clamp(min=0)
    if history is not None:
        bound = torch.maximum(bound, HISTORY_ALLOWANCE * history)
    return torch.minimum(r, bound)


def redistribute(r, rc):
    """The energy the firefly cut took, r - rc, spread over its window: rc + min(window_mean(r -
    rc), REDISTRIBUTE_CAP * window_mean(rc)), at most the window's brightest sample. The cut
    alone is biased dark (its excess is dropped: 5-8 % on held-out clips, 19-23 % on sunlit
    interiors, whose light arrives as sparse bright samples); spread over the window, the
    excess keeps the window's mean, as Zirr et al. 2018 re-weight firefly samples into coarser
    estimates. The cap bounds what one rare huge sample adds (a sample 3e4 times its
    neighbours would otherwise lift 144 pixels ~200x)."""
    e = torch.minimum(window_mean(r - rc), REDISTRIBUTE_CAP * window_mean(rc))
    return torch.minimum(rc + e, window_max(r))


class Denoiser(nn.Module):
    def __init__(self):
        super().__init__()
        self.enc1 = nn.Conv2d(FEATURES, 16, 3, padding=1)
        self.enc2 = nn.Conv2d(16, 32, 3, padding=1)
        self.enc3 = nn.Conv2d(32, 32, 3, padding=1)
        self.dec1 = nn.Conv2d(48, 16, 3, padding=1)
        self.head = nn.Conv2d(16, OUTPUTS, 1)
        with torch.no_grad():
            self.head.weight.mul_(0.1)
            b = torch.zeros(OUTPUTS)
            b[0] = 0.0
            for l in range(LEVELS):
                b[1 + 4 * l:5 + 4 * l] = torch.tensor([1.0, 3.0, 3.0, 2.0])
            b[OUTPUTS - 1] = 8.0  # kappa ~ 8: fireflies barely clamped at first
            self.head.bias.copy_(b)

    def params(self, feat):
        h = F.avg_pool2d(feat, 4)
        e1 = F.relu(self.enc1(h))
        e2 = F.relu(self.enc2(F.avg_pool2d(e1, 2)))
        e3 = F.relu(self.enc3(e2))
        u = F.interpolate(e3, scale_factor=2, mode="nearest")
        d1 = F.relu(self.dec1(torch.cat([u, e1], dim=1)))
        o = self.head(d1)
        act = [torch.sigmoid(o[:, 0:1])]
        floor = torch.tensor([0.0, SN_MIN, SZ_MIN], dtype=o.dtype).view(1, 3, 1, 1)
        for l in range(LEVELS):
            act += [F.softplus(o[:, 1 + 4 * l:4 + 4 * l]) + floor, torch.sigmoid(o[:, 4 + 4 * l:5 + 4 * l])]
        act.append(F.softplus(o[:, OUTPUTS - 1:OUTPUTS]))
        return F.interpolate(torch.cat(act, dim=1), scale_factor=4, mode="bilinear", align_corners=False)

    def forward(self, color, albedo, normal, depth, rough, motion, state=None, recurrent=True, size=None):
        """All inputs (B,C,H,W) with H, W multiples of 8 (size: the (h, w) of the image inside
        the padding, None: all of it). state = (h, z, n) of the previous frame or None.
        Returns (colour, new state)."""
        dm = demodulation(albedo)
        x_lin = color.clamp(min=0) / dm
        x = torch.log1p(x_lin)
        z = depth
        zc = z.clamp(min=ZMIN)
        bk = is_black(albedo)
        if state is None or not recurrent:
            yw_lin, zw, valid, nw = x_lin, z, torch.zeros_like(z), torch.zeros_like(z)
        else:
            yw_lin, valid = warp(state[0], motion)
            zw, _ = warp(state[1], motion)
            nw, _ = warp(state[2], motion)
            kw, _ = warp(state[3], motion)
            valid = valid * ((zw - z).abs() <= DISOCCLUDED * zc).to(z.dtype) * ((kw - bk).abs() < 1e-3).to(z.dtype)
            nw = nw * valid
            yw_lin = torch.minimum(yw_lin, window_max(x_lin, HISTORY_MAX_CELLS))
            yw_lin = torch.maximum(yw_lin, -window_max(-x_lin))
        yw = torch.log1p(yw_lin.clamp(min=0))
        dz = ((zw - z).abs() / zc).clamp(max=1.0) * valid
        zg = (((shift(z, 0, 1) - z).abs() + (shift(z, 1, 0) - z).abs()) / zc).clamp(max=1.0)
        xl = x.mean(dim=1, keepdim=True)
        feat = torch.cat([x, albedo, normal, rough, yw, valid, dz, zg, xl * xl, 1.0 / (1.0 + nw)], dim=1)
        o = self.params(feat)
        alpha = o[:, 0:1] * (nw / (1.0 + nw))
        xc = redistribute(x_lin, firefly_clamp(x_lin, o[:, OUTPUTS - 1:OUTPUTS], size, yw_lin * valid))
        r0 = xc + alpha * (yw_lin - xc)
        n_new = (1.0 / (1.0 - alpha)).clamp(max=NMAX)
        xi = r0
        nn_p = (normal * normal).sum(1, keepdim=True)
        for l in range(LEVELS):
            d = 1 << l
            sc = o[:, 1 + 4 * l:2 + 4 * l]
            sn = o[:, 2 + 4 * l:3 + 4 * l]
            sz = o[:, 3 + 4 * l:4 + 4 * l] / zc
            beta = o[:, 4 + 4 * l:5 + 4 * l]
            h, w = xi.shape[-2:]
            lg = torch.log1p(xi.clamp(min=0))  # the edge-stopping guide: log irradiance
            g = F.pad(torch.cat([lg, normal, z, xi, bk], dim=1), (d, d, d, d), mode="replicate")
            acc, wsum = 0, 0
            for dy, dx, hq in TAPS:
                q = g[..., d + dy * d:d + dy * d + h, d + dx * d:d + dx * d + w]
                e = sc * ((lg - q[:, 0:3]) ** 2).sum(1, keepdim=True) \
                    + sn * (nn_p - (normal * q[:, 3:6]).sum(1, keepdim=True)).clamp(min=0) \
                    + sz * (z - q[:, 6:7]).abs()
                wq = hq * torch.exp(-e) * (q[:, 10:11] == bk).to(e.dtype)
                acc = acc + wq * q[:, 7:10]
                wsum = wsum + wq
            xi = xi + beta * (acc / wsum - xi)
            if l == 0:
                h_new = xi
        trusted = yw_lin * (nw >= HISTORY_EVIDENCE).to(xi.dtype)  # nw is 0 where not valid
        out = output_clamp(xi, size, trusted).clamp(min=0) * dm
        return out, (h_new, z, n_new, bk)


def parameter_count(model):
    return sum(p.numel() for p in model.parameters())
