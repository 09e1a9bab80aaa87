"""kestrel's `rae` denoiser, the reference definition: the recurrent denoising autoencoder of
Chaitanya et al. 2017 (a U-Net whose encoder levels are recurrent convolutional blocks;
direct prediction of the colour), the quality mode the fast denoiser (model.py) is measured
against. The engine computes the same function with oneDNN (src/denoise/rae.cpp); the
parity test compares them on a fixture written by train_rae.py. docs/denoiser.md, "The
recurrent autoencoder (rae)", says what it costs.

Per frame, at H x W padded with zeros to multiples of 16 (the padding is part of the
function: the engine pads the same way, the hidden states cover it):
  d   = model.demodulation(albedo)              albedo + 0.01, 1 where it is (nearly) black
  r   = max(colour, 0) / d                      demodulated irradiance
  x   = [log(1 + r), albedo, normal, d(z), roughness, black]     12 channels;
        d(z) = z / (z + s) for z > 0, 1 for the sky (z <= 0); s = the mean depth of the
        frame's non-sky pixels (1 if none); black = model.is_black(albedo)
  encoder level l = 0..4, channels C_l = 24, 32, 48, 64, 80 (input: x, then the pooled
  output of the level above):
        a_l = f(A_l(in_l));   e_l^t = f(C_l(f(B_l([a_l, e_l^{t-1}]))))   e^{-1} = 0
        in_{l+1} = maxpool2(e_l^t)
        e_l^t is the level's recurrent state (not warped: the paper's design; its receptive
        field, 2^l pixels per tap at level l, absorbs the motion of a frame)
  decoder level l = 3..0:  u_l = f(E_l(f(D_l([up2(u_{l+1}), e_l^t]))))   u_4 = e_4^t
  o   = O(u_0)  (3 channels; softplus(o) = log(1 + irradiance), direct prediction)
  out = expm1(min(softplus(o), log(1 + max r))) * d  cropped: no output exceeds the brightest
        demodulated sample of the frame (times its own demodulation); softplus rather than a
        clamp at 0, which stopped every gradient where a fresh network predicted below 0
All convolutions 3x3 with zero padding; f = leaky ReLU (slope 0.1, the paper's); up2 nearest
2x upsampling.
"""
import torch
import torch.nn as nn
import torch.nn.functional as F

import model as M

CHANNELS = (32, 48, 64, 80, 96)
INPUTS = 12
SLOPE = 0.1
MULTIPLE = 16  # 2^(levels - 1)


def f(t):
    return F.leaky_relu(t, SLOPE)


def conv(cin, cout):
    return nn.Conv2d(cin, cout, 3, padding=1)


def depth_feature(depth):
    """d(z) = z / (z + s), 1 for the sky; s the mean depth of the non-sky pixels (1 if none)."""
    valid = (depth > 0).to(depth.dtype)
    n = valid.sum(dim=(1, 2, 3), keepdim=True)
    s = torch.where(n > 0, (depth * valid).sum(dim=(1, 2, 3), keepdim=True) / n.clamp(min=1), torch.ones_like(n))
    return torch.where(depth > 0, depth / (depth + s), torch.ones_like(depth))


class RAE(nn.Module):
    def __init__(self, channels=CHANNELS):
        super().__init__()
        self.channels = channels
        c = channels
        cin = [INPUTS] + list(c[:-1])
        self.enc_a = nn.ModuleList(conv(cin[l], c[l]) for l in range(len(c)))
        self.enc_b = nn.ModuleList(conv(2 * c[l], c[l]) for l in range(len(c)))
        self.enc_c = nn.ModuleList(conv(c[l], c[l]) for l in range(len(c)))
        self.dec_d = nn.ModuleList(conv(c[l + 1] + c[l], c[l]) for l in range(len(c) - 1))
        self.dec_e = nn.ModuleList(conv(c[l], c[l]) for l in range(len(c) - 1))
        self.out = conv(c[0], 3)

    def forward(self, color, albedo, normal, depth, rough, motion=None, state=None, recurrent=True, size=None):
        """Inputs (B,C,h,w), any size (padded here with zeros to multiples of 16). state: the
        previous frame's per-level states (at the padded size) or None. Returns (colour
        (B,3,h,w), new state)."""
        h, w = color.shape[-2:]
        pad = (0, -w % MULTIPLE, 0, -h % MULTIPLE)
        dm = M.demodulation(albedo)
        r = color.clamp(min=0) / dm
        x = torch.cat([torch.log1p(r), albedo, normal, depth_feature(depth), rough, M.is_black(albedo)], 1)
        x = F.pad(x, pad)
        levels = len(self.channels)
        enc, t = [], x
        for l in range(levels):
            a = f(self.enc_a[l](t))
            prev = state[l] if (state is not None and recurrent) else torch.zeros_like(a)
            e = f(self.enc_c[l](f(self.enc_b[l](torch.cat([a, prev], 1)))))
            enc.append(e)
            if l + 1 < levels:
                t = F.max_pool2d(e, 2)
        u = enc[-1]
        for l in range(levels - 2, -1, -1):
            u = F.interpolate(u, scale_factor=2, mode="nearest")
            u = f(self.dec_e[l](f(self.dec_d[l](torch.cat([u, enc[l]], 1)))))
        o = self.out(u)[..., :h, :w]
        top = torch.log1p(r.amax(dim=(1, 2, 3), keepdim=True))
        o = torch.minimum(F.softplus(o), top)
        return torch.expm1(o) * dm, enc


def parameter_count(model):
    return sum(p.numel() for p in model.parameters())
