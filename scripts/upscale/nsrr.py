"""kestrel's `nsrr` upsampler, the reference definition: neural supersampling as Xiao et al.
2020 describe it (align several recent frames, reweight them, reconstruct with a U-Net). The
engine computes the same function (src/upscale/nsrr.cpp, convolutions through oneDNN);
docs/upscaler.md explains the design and what it costs.

Per frame t (low resolution h x w, point-sampled at its jitter (jx, jy): pixel (i, j) holds
the sample at (i + jx, j + jy); depth z, 0 = sky; motion m in low-resolution pixels, "p + m is
where the surface was in the previous frame"), output f h x f w, f in {2, 4}:

  x      = [y(c), d(z)]              y(c) = c / (1 + L(c)); d(z) = z / (z + s), 1 for the sky;
                                     s = mean depth of the current frame's non-sky pixels (1 if
                                     none), shared by the whole window
  F      = [x, E(x)]                 E: 3 convolutions 3x3 (4 -> 32 -> 32 -> 8, ReLU), the same
                                     weights for every frame: 12 channels at low resolution
  Z_k    = F of frame t-k zero-upsampled: its sample (i, j) is written to the output pixel
           (floor(f (i + jx)), floor(f (j + jy))) of its own jitter, every other pixel 0
  P_0    = X + 1/2;  P_k = P_{k-1} + f m_{t-k+1}(P_{k-1} / f)   (bilinear m, in output pixels)
  W_k    = Z_k at floor(P_k) (0 off screen or where frame t-k does not exist), k = 1..N
  w      = 5 (1 + tanh R([Z_0[:4], W_1[:4], ..., W_N[:4]]))   R: 3 convolutions 3x3
           (4 (N+1) -> 32 -> 32 -> N, ReLU between): the feature reweighting, w_k in [0, 10]
  Hy     = y of the learned TAAU's output for frame t (model.step with weights/upscaler.kdw,
           run over the whole sequence: its reprojected, clamped, disocclusion-rejected
           history is the long memory the window of N + 1 frames lacks)
  l      = U([Z_0, w_1 W_1, ..., w_N W_N, f / 4, Hy])   U: the U-Net below, 2 + 9 (N + 1) logits
  out    = from_y(blend(l, B, Hy, [Z_0, W_1, ..., W_N]))   the kernel-predicting
           reconstruction: a softmax over the candidates present of B (the current frame's y
           bilinearly upsampled, bilinear_base), the y of every frame's sample in the 3 x 3
           output pixels around X, and Hy, weighted by the logits: a convex combination of what
           was sampled and what the history holds

U (as Xiao et al.'s, channels 64, 32 | 64, 64 | 128, 128 | 64, 64 | 32, 38 logits): two 3x3
convolutions per level, ReLU, 2x2 max pooling down, bilinear 2x upsampling up (edges
clamped), skip connections by concatenation; the input is padded with zeros to multiples of
4 (the output cropped back); blend's y is clamped to [0, 0.999]. Its last layer starts at a
tenth of PyTorch's initialisation and bias 0: before training every candidate present weighs
alike. (Architecture 4 added a correction to B instead: trained, the correction stayed about
zero; on a synthetic static sequence whose samples hold the exact answer it had learned a
fifth of it after 600 steps, the blend nine tenths after 200. Architectures 5 and 6 had no Hy:
the window alone stayed below TAAU-like on most held-out families.)
"""
import torch
import torch.nn as nn
import torch.nn.functional as F

import model as M

FRAMES = 3  # previous frames (N); the current frame makes N + 1
KERNEL_RADIUS = 1  # the blend's candidates: every frame's samples in the 3 x 3 output pixels
FEATURE_CHANNELS = 12
REWEIGHT_MAX = 10.0
Y_MAX = 0.999


def depth_scale(depth):
    """s: the mean depth of the non-sky pixels (depth (B,1,h,w)) -> (B,1,1,1); 1 if none."""
    valid = (depth > 0).float()
    n = valid.sum(dim=(1, 2, 3), keepdim=True)
    total = (depth * valid).sum(dim=(1, 2, 3), keepdim=True)
    return torch.where(n > 0, total / torch.clamp(n, min=1.0), torch.ones_like(n))


def clean(color, depth, motion):
    color = torch.clamp(torch.nan_to_num(color, nan=0.0, posinf=0.0, neginf=0.0), min=0.0)
    depth = torch.nan_to_num(depth, nan=0.0, posinf=0.0, neginf=0.0).clamp(min=0.0)
    motion = torch.nan_to_num(motion, nan=0.0, posinf=0.0, neginf=0.0).clamp(-65536.0, 65536.0)
    return color, depth, motion


def zero_upsample(feat, jx, jy, f):
    """(B,C,h,w) at jitter (jx, jy) (B,) -> (B,C,f h,f w): each sample in the output pixel
    that contains it, zeros elsewhere."""
    B, C, h, w = feat.shape
    dev = feat.device
    ii = torch.arange(w, device=dev, dtype=torch.float32).view(1, 1, w).expand(B, h, w)
    jj = torch.arange(h, device=dev, dtype=torch.float32).view(1, h, 1).expand(B, h, w)
    X = torch.floor(f * (ii + jx.view(B, 1, 1))).long().clamp(0, f * w - 1)
    Y = torch.floor(f * (jj + jy.view(B, 1, 1))).long().clamp(0, f * h - 1)
    idx = (Y * (f * w) + X).view(B, 1, -1).expand(B, C, -1)
    out = torch.zeros(B, C, f * h * f * w, device=dev, dtype=feat.dtype)
    out.scatter_(2, idx, feat.reshape(B, C, -1))
    return out.view(B, C, f * h, f * w)


def warp_positions(motions, f, H, W):
    """motions: [m_t, m_{t-1}, ...] (B,2,h,w) -> [P_1, P_2, ...] (each (B,2,H,W), output
    pixels): P_k = P_{k-1} + f m_{t-k+1}(P_{k-1} / f), bilinear, P_0 = pixel centres."""
    B = motions[0].shape[0]
    dev = motions[0].device
    X = torch.arange(W, device=dev, dtype=torch.float32).view(1, 1, 1, W).expand(B, 1, H, W) + 0.5
    Y = torch.arange(H, device=dev, dtype=torch.float32).view(1, 1, H, 1).expand(B, 1, H, W) + 0.5
    out = []
    for m in motions:
        mv = M.bilinear_at(m, X / f, Y / f)
        X, Y = X + f * mv[:, 0:1], Y + f * mv[:, 1:2]
        out.append(torch.cat([X, Y], 1))
    return out


def gather_nearest(img, pos):
    """img (B,C,H,W), pos (B,2,H,W) continuous -> img at floor(pos), 0 off screen."""
    B, C, H, W = img.shape
    x, y = torch.floor(pos[:, 0:1]), torch.floor(pos[:, 1:2])
    inside = ((x >= 0) & (x < W) & (y >= 0) & (y < H)).float()
    g = M.gather2d(img, x.long().clamp(0, W - 1), y.long().clamp(0, H - 1))
    return g * inside


def conv(cin, cout):
    return nn.Conv2d(cin, cout, 3, padding=1)


def bilinear_base(color, jitter, f):
    """The current frame's y bilinearly upsampled (model.bilinear_at at (X + 1/2) / f - j + 1/2:
    its samples where they were taken), what both networks predict a correction of."""
    B, _, h, w = color.shape
    H, W = f * h, f * w
    X = torch.arange(W, dtype=torch.float32).view(1, 1, 1, W).expand(B, 1, H, W)
    Y = torch.arange(H, dtype=torch.float32).view(1, 1, H, 1).expand(B, 1, H, W)
    jx, jy = jitter[:, 0].float().view(B, 1, 1, 1), jitter[:, 1].float().view(B, 1, 1, 1)
    return M.bilinear_at(M.to_y(color), (X + 0.5) / f - jx + 0.5, (Y + 0.5) / f - jy + 0.5)


def align(frames, n, f, scale=None, extract=None):
    """The align step both members share. frames as NSRR.forward; n previous frames are used.
    Each frame's x = [y, d(z)] (through `extract` if given) is zero-upsampled at its jitter,
    and the previous ones are warped to the current frame by the accumulated motion.
    -> the current frame's cleaned colour, Z_0, [W_1 .. W_n] (zeros for a missing frame) and
    the presence masks [M_0 .. M_n] (B,1,H,W): 1 where Z_0 / W_k holds a sample."""
    color, depth, motion = clean(*frames[0][:3])
    h, w = color.shape[2:]
    H, W = f * h, f * w
    s = depth_scale(depth) if scale is None else scale
    zs, ms = [], []
    for k in range(n + 1):
        fr = frames[k] if k < len(frames) else None
        if fr is None:
            zs.append(None), ms.append(None)
            continue
        c, z, _ = clean(*fr[:3])
        x = torch.cat([M.to_y(c), torch.where(z > 0, z / (z + s), torch.ones_like(z))], 1)
        jx, jy = fr[3][:, 0].float(), fr[3][:, 1].float()
        zs.append(zero_upsample(extract(x) if extract is not None else x, jx, jy, f))
        ms.append(zero_upsample(torch.ones_like(z), jx, jy, f))
    # Motion of frame t-k+1 moves P_{k-1} (in frame t-k+1) to P_k (in frame t-k).
    motions = [clean(*frames[k - 1][:3])[2] if k - 1 < len(frames) and frames[k - 1] is not None
               else torch.zeros_like(motion) for k in range(1, n + 1)]
    pos = warp_positions(motions, f, H, W)
    warped = [gather_nearest(zs[k], pos[k - 1]) if zs[k] is not None else torch.zeros_like(zs[0])
              for k in range(1, n + 1)]
    masks = [ms[0]] + [gather_nearest(ms[k], pos[k - 1]) if ms[k] is not None else torch.zeros_like(ms[0])
                       for k in range(1, n + 1)]
    return color, zs[0], warped, masks


def blend_logits(radii):
    """The blend's candidates for a window whose frame k offers its samples in the (2 r_k +
    1)^2 output pixels around a pixel (radii: [r_0, r_1, ...]): the base, those, and the history."""
    return 2 + sum((2 * r + 1) ** 2 for r in radii)


def blend(logits, base, history, feats, masks, radii):
    """The kernel-predicting reconstruction both members end with. logits (B,K,H,W), K =
    blend_logits(radii): channel 0 weighs base (B,3,H,W); then (2 r_k + 1)^2 channels per frame
    k, in order, the o-th of them, o = (dy + r_k)(2 r_k + 1) + dx + r_k, weighing the y (channels
    0..2) of feats[k] at the output pixel X + (dx, dy), where masks[k] there is 1 (off the image
    or no sample: not a candidate); the last channel weighs history (B,3,H,W, y).
    -> sum of softmax(logits over the candidates) times their y (B,3,H,W)."""
    B, _, H, W = base.shape
    one = torch.ones_like(masks[0]) > 0
    vals, present = [base.unsqueeze(2)], [one]
    for z, m, r in zip(feats, masks, radii):
        d = 2 * r + 1
        vals.append(F.unfold(z[:, :3], d, padding=r).view(B, 3, d * d, H, W))
        present.append(F.unfold(m, d, padding=r).view(B, d * d, H, W) > 0)
    vals.append(history.unsqueeze(2)), present.append(one)
    v, p = torch.cat(vals, 2), torch.cat(present, 1)
    wts = torch.softmax(logits.float().masked_fill(~p, float("-inf")), 1)
    return (wts.unsqueeze(1) * v).sum(2)


def upsample2(x):
    """Bilinear 2x, pixel centres aligned, edges clamped (oneDNN's resampling, linear)."""
    return F.interpolate(x, scale_factor=2, mode="bilinear", align_corners=False)


class NSRR(nn.Module):
    def __init__(self, frames=FRAMES, extract=(32, 32, 8), reweight=(32, 32), unet=(64, 32, 64, 64, 128, 128, 64, 64, 32)):
        super().__init__()
        self.frames = frames
        e1, e2, e3 = extract
        assert 4 + e3 == FEATURE_CHANNELS
        self.e1, self.e2, self.e3 = conv(4, e1), conv(e1, e2), conv(e2, e3)
        r1, r2 = reweight
        self.r1, self.r2, self.r3 = conv(4 * (frames + 1), r1), conv(r1, r2), conv(r2, frames)
        a1, a2, b1, b2, c1, c2, d1, d2, o1 = unet
        cin = FEATURE_CHANNELS * (frames + 1) + 1 + 3
        self.u1a, self.u1b = conv(cin, a1), conv(a1, a2)
        self.u2a, self.u2b = conv(a2, b1), conv(b1, b2)
        self.u3a, self.u3b = conv(b2, c1), conv(c1, c2)
        self.u4a, self.u4b = conv(c2 + b2, d1), conv(d1, d2)
        self.u5a, self.u5b = conv(d2 + a2, o1), conv(o1, blend_logits([KERNEL_RADIUS] * (frames + 1)))
        with torch.no_grad():
            # The blend starts near uniform (not exactly: with a zero last layer no gradient
            # reaches the ones before it).
            self.u5b.weight.mul_(0.1)
            self.u5b.bias.zero_()

    def extract(self, x):
        """x (B,4,h,w) -> the frame's 12 features."""
        e = F.relu(self.e1(x))
        e = F.relu(self.e2(e))
        e = F.relu(self.e3(e))
        return torch.cat([x, e], 1)

    def reweight(self, z0, warped):
        r = torch.cat([z0[:, :4]] + [w[:, :4] for w in warped], 1)
        r = F.relu(self.r1(r))
        r = F.relu(self.r2(r))
        return 0.5 * REWEIGHT_MAX * (1.0 + torch.tanh(self.r3(r)))

    def reconstruct(self, x):
        """The U-Net; the input is padded with zeros to multiples of 4 and the output cropped."""
        H, W = x.shape[2:]
        x = F.pad(x, (0, -W % 4, 0, -H % 4))
        a = F.relu(self.u1b(F.relu(self.u1a(x))))
        b = F.relu(self.u2b(F.relu(self.u2a(F.max_pool2d(a, 2)))))
        c = F.relu(self.u3b(F.relu(self.u3a(F.max_pool2d(b, 2)))))
        d = F.relu(self.u4b(F.relu(self.u4a(torch.cat([upsample2(c), b], 1)))))
        return self.u5b(F.relu(self.u5a(torch.cat([upsample2(d), a], 1))))[:, :, :H, :W]

    def forward(self, frames, f, history, scale=None):
        """frames: [current, previous, ...] (at most N + 1), each (color (B,3,h,w), depth
        (B,1,h,w), motion (B,2,h,w), jitter (B,2)); a frame that does not exist is None.
        history: Hy (B,3,f h,f w), history_sequence's frame t.
        scale: the depth scale s (B,1,1,1), else depth_scale of the current frame.
        -> the linear output (B,3,f h,f w) and its y."""
        color, z0, warped, masks = align(frames, self.frames, f, scale, self.extract)
        wts = self.reweight(z0, warped)
        x = torch.cat([z0] + [wts[:, k:k + 1] * warped[k] for k in range(self.frames)] +
                      [torch.full_like(z0[:, :1], f / 4.0), history], 1)
        base = bilinear_base(color, frames[0][3], f)
        radii = [KERNEL_RADIUS] * (self.frames + 1)
        y = torch.clamp(blend(self.reconstruct(x), base, history, [z0] + warped, masks, radii), 0.0, Y_MAX)
        return M.from_y(y), y


RT_FRAMES = 2  # previous frames of the real-time member
RT_PREVIOUS_RADIUS = 0  # its blend takes the previous frames' samples at the pixel only
GRID = 4  # its networks run on cells of 4 x 4 output pixels
RT_CELLS = GRID * GRID


class NSRRRealTime(nn.Module):
    """`nsrr-rt`, the real-time member of the family: the same align -> reweight -> reconstruct
    structure with fewer frames (N = 2), no extraction network (a frame's features are its
    x = [y, d(z)]) and networks that run on a grid of 4 x 4 output pixels per cell (1/4 of the
    output resolution at either factor), the output pixels of a cell folded into channels:

      Z_k, W_k    as NSRR's, 4 channels, at the output resolution padded to multiples of 8
      G           = [unshuffle([Z_0, W_1, ..., W_N, Hy]), f / 4]   unshuffle: F.pixel_unshuffle(.,
                    4), channel (4 k + c) 16 + s for frame k, channel c, cell pixel s = 4 dy +
                    dx; then Hy's (3 channels: 4 (N + 1) 16 + 16 c + s); Hy as NSRR's
      w           = 5 (1 + tanh R(G))      R: 1x1 convolutions 4 16 (N+1) + 49 -> 16 -> 16 N;
                    w[16 (k-1) + s] weighs W_k at cell pixel s (all 4 channels)
      a           = c2(c1(G'))             G' = G with the W_k weighed; c1 1x1 -> 32, c2 3x3 -> 24
      b           = c3(maxpool2(a))        3x3 24 -> 24 at half the grid
      l           = shuffle(c5(c4([upsample2(b), a])))   c4 1x1 48 -> 24, c5 1x1 24 -> 16 K,
                    shuffle: F.pixel_shuffle(., 4) (channel 16 c + s), cropped: K logits per
                    output pixel, K = blend_logits([r, r', ..., r']), r = KERNEL_RADIUS
      out         = from_y(blend(l, B, Hy, [Z_0, W_1, ..., W_N]))   as NSRR's, the previous frames'
                    samples within r' = prev_radius (0: only the one at the pixel), y clamped
                    to [0, 0.999]

    ReLU after every convolution but R's last and c5."""

    def __init__(self, frames=RT_FRAMES, prev_radius=RT_PREVIOUS_RADIUS):
        super().__init__()
        self.frames, self.radii = frames, [KERNEL_RADIUS] + [prev_radius] * frames
        kernel = blend_logits(self.radii)
        cin = 4 * RT_CELLS * (frames + 1) + 3 * RT_CELLS + 1
        self.r1, self.r2 = nn.Conv2d(cin, 16, 1), nn.Conv2d(16, RT_CELLS * frames, 1)
        self.c1, self.c2 = nn.Conv2d(cin, 32, 1), conv(32, 24)
        self.c3 = conv(24, 24)
        self.c4, self.c5 = nn.Conv2d(48, 24, 1), nn.Conv2d(24, kernel * RT_CELLS, 1)
        with torch.no_grad():  # the blend starts near uniform (see NSRR)
            self.c5.weight.mul_(0.1)
            self.c5.bias.zero_()

    def forward(self, frames, f, history, scale=None):
        """As NSRR.forward (frames beyond the first N + 1 are ignored)."""
        color, z0, warped, masks = align(frames, self.frames, f, scale)
        H, W = z0.shape[2:]
        feats = [z0] + warped
        pad = (0, -W % (2 * GRID), 0, -H % (2 * GRID))
        g = [F.pixel_unshuffle(F.pad(x, pad), GRID) for x in feats]
        gh = F.pixel_unshuffle(F.pad(history, pad), GRID)
        fc = torch.full_like(g[0][:, :1], f / 4.0)
        x = torch.cat(g + [gh, fc], 1)
        wts = 0.5 * REWEIGHT_MAX * (1.0 + torch.tanh(self.r2(F.relu(self.r1(x)))))
        x = torch.cat([g[0]] + [g[k] * wts[:, RT_CELLS * (k - 1):RT_CELLS * k].repeat(1, 4, 1, 1)
                                for k in range(1, self.frames + 1)] + [gh, fc], 1)
        a = F.relu(self.c2(F.relu(self.c1(x))))
        b = F.relu(self.c3(F.max_pool2d(a, 2)))
        o = self.c5(F.relu(self.c4(torch.cat([upsample2(b), a], 1))))
        base = bilinear_base(color, frames[0][3], f)
        y = torch.clamp(blend(F.pixel_shuffle(o, GRID)[:, :, :H, :W], base, history, feats, masks, self.radii), 0.0, Y_MAX)
        return M.from_y(y), y


def history_sequence(ins, jit, f, upsampler):
    """Hy of every frame of a sequence: ins (B,T,6,h,w) (colour, depth, motion), jit (B,T,2);
    the learned TAAU (model.run_sequence with `upsampler`) run from frame 0, its output to
    linear and back to y (as the engine takes it from the TAAU's output image).
    -> (B,T,3,f h,f w)."""
    with torch.no_grad():
        return torch.stack([M.to_y(M.from_y(y)) for y in M.run_sequence(ins, jit, f, model=upsampler)], 1)
