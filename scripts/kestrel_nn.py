"""Shared by the training scripts (scripts/denoise, scripts/upscale): PFM files, kestrel's
weights files (.kdw, format v1: docs/denoiser.md) and the evaluations' tone map."""
import struct

import numpy as np
import torch


def aces_srgb(c):
    """The evaluation's tone map (kestrel::tonemap_aces_srgb) of linear colour."""
    c = torch.clamp(c, min=0.0, max=1e6)
    y = torch.clamp((c * (2.51 * c + 0.03)) / (c * (2.43 * c + 0.59) + 0.14), 0.0, 1.0)
    return torch.where(y <= 0.0031308, 12.92 * y, 1.055 * torch.clamp(y, min=0.0031308) ** (1 / 2.4) - 0.055)


def read_pfm(path):
    """-> float32 (H, W, C), top row first, NaN/Inf as 0."""
    with open(path, "rb") as f:
        kind = f.readline().strip()
        w, h = map(int, f.readline().split())
        scale = float(f.readline())
        c = 3 if kind == b"PF" else 1
        data = np.frombuffer(f.read(w * h * c * 4), dtype="<f4" if scale < 0 else ">f4").reshape(h, w, c)
    return np.nan_to_num(np.ascontiguousarray(data[::-1]).astype(np.float32), nan=0.0, posinf=0.0, neginf=0.0)


def write_pfm(path, img):
    img = np.asarray(img, dtype="<f4")
    if img.ndim == 2:
        img = img[:, :, None]
    h, w, c = img.shape
    with open(path, "wb") as f:
        f.write(b"PF\n" if c == 3 else b"Pf\n")
        f.write(f"{w} {h}\n-1.0\n".encode())
        f.write(np.ascontiguousarray(img[::-1]).tobytes())


def fnv1a(blob):
    h = 0xcbf29ce484222325
    for byte in blob:
        h = ((h ^ byte) * 0x100000001b3) & 0xFFFFFFFFFFFFFFFF
    return h


def export_kdw(model, path, magic, architecture):
    """magic (8 bytes), version 1, architecture, tensor count, tensors (name, rank, shape,
    little-endian f32) in named_parameters order, FNV-1a 64 of all preceding bytes."""
    blob = bytearray(magic)
    blob += struct.pack("<III", 1, architecture, len(list(model.named_parameters())))
    for name, p in model.named_parameters():
        a = p.detach().cpu().numpy().astype("<f4")
        nb = name.encode()
        blob += struct.pack("<I", len(nb)) + nb + struct.pack("<I", a.ndim) + struct.pack(f"<{a.ndim}I", *a.shape)
        blob += a.tobytes()
    blob += struct.pack("<Q", fnv1a(blob))
    with open(path, "wb") as f:
        f.write(blob)


def load_kdw(model, path, magic, architecture, partial=False):
    """Reads a file written by export_kdw into `model` (checks magic, version, hash).
    partial: an initialisation from an older architecture whose tensors are the leading part
    of the model's (more input channels or outputs): the common slice is copied, new input
    channels start at 0, new outputs keep the model's initial values."""
    blob = open(path, "rb").read()
    assert blob[:8] == magic, f"{path}: not a kestrel {magic.decode()} weights file"
    assert struct.unpack("<Q", blob[-8:])[0] == fnv1a(blob[:-8]), f"{path}: checksum mismatch"
    version, arch, count = struct.unpack("<III", blob[8:20])
    assert version == 1 and arch == architecture, f"{path}: version {version}, architecture {arch}"
    at, params = 20, dict(model.named_parameters())
    with torch.no_grad():
        for _ in range(count):
            (n,) = struct.unpack("<I", blob[at:at + 4]); at += 4
            name = blob[at:at + n].decode(); at += n
            (rank,) = struct.unpack("<I", blob[at:at + 4]); at += 4
            dims = struct.unpack(f"<{rank}I", blob[at:at + 4 * rank]); at += 4 * rank
            size = int(np.prod(dims))
            src = torch.from_numpy(np.frombuffer(blob[at:at + 4 * size], dtype="<f4").reshape(dims).copy())
            dst = params[name]
            if partial and tuple(dst.shape) != tuple(dims):
                assert dst.dim() == rank and all(d >= s for d, s in zip(dst.shape, dims)), f"{path}: {name} {dims}"
                if rank > 1 and dst.shape[1] > dims[1]:
                    dst[:, dims[1]:] = 0
                dst[tuple(slice(0, s) for s in dims)] = src
            else:
                dst.copy_(src)
            at += 4 * size


def plot_loss(history, path, window, label="L1 (tone-mapped)"):
    """history: (step, factor, loss, ...) tuples -> a PNG of each factor's running mean."""
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return
    fig, ax = plt.subplots(figsize=(7, 3.5))
    for fac in sorted({h[1] for h in history}):
        pts = [(h[0], h[2]) for h in history if h[1] == fac]
        ys = np.convolve([p[1] for p in pts], np.ones(window) / window, mode="valid")
        ax.plot([p[0] for p in pts][window - 1:], ys, label=f"x{fac} {label}, {window}-step mean")
    ax.set_xlabel("step"), ax.set_ylabel("loss"), ax.legend(), ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
