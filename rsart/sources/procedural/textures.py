"""Procedural texture images (wood grain, basket weave, noise, brushed metal, printed patterns).

Photometric methods and SfM need texture, so procedural twins are not flat-coloured: each
material is an RGB image generated deterministically from a seed, mapped onto the part by
box-projected UVs (see :mod:`rsart.sources.procedural.builder`). Images are (H, W, 3) uint8,
returned as PIL images (what trimesh's ``TextureVisuals`` carries).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from PIL import Image

KINDS = ("wood", "weave", "noise", "metal", "print", "glass")


@dataclass(frozen=True)
class Material:
    """A procedural material: ``kind`` (one of KINDS), base ``color`` (RGB in [0, 1]), ``seed``.

    ``params``: kind-specific options (e.g. ``{"accent": (r, g, b)}`` for prints), as a tuple of pairs.
    """

    name: str
    kind: str
    color: tuple[float, float, float]
    seed: int
    params: tuple = field(default_factory=tuple)

    def param(self, key: str, default=None):
        return dict(self.params).get(key, default)


def value_noise(rng: np.random.Generator, size: int, cells: int, aspect: tuple[int, int] = (1, 1)) -> np.ndarray:
    """(size, size) smooth noise in [0, 1]: a random ``cells`` grid upsampled bicubically (PIL)."""
    cy, cx = max(2, cells * aspect[0]), max(2, cells * aspect[1])
    g = rng.random((cy, cx)).astype(np.float32)
    img = Image.fromarray(g, mode="F").resize((size, size), Image.BICUBIC)
    return np.clip(np.asarray(img), 0.0, 1.0)


def fractal_noise(rng: np.random.Generator, size: int, base_cells: int = 4, octaves: int = 4) -> np.ndarray:
    """(size, size) multi-octave value noise in [0, 1]."""
    out = np.zeros((size, size), np.float32)
    amp, tot = 1.0, 0.0
    for k in range(octaves):
        out += amp * value_noise(rng, size, base_cells * 2**k)
        tot += amp
        amp *= 0.5
    return out / tot


def _rgb(img01: np.ndarray) -> Image.Image:
    return Image.fromarray((np.clip(img01, 0, 1) * 255 + 0.5).astype(np.uint8), mode="RGB")


def _mix(c0: np.ndarray, c1: np.ndarray, t: np.ndarray) -> np.ndarray:
    return c0[None, None, :] * (1 - t[..., None]) + c1[None, None, :] * t[..., None]


def wood(m: Material, size: int) -> Image.Image:
    """Wood grain: noisy growth rings stretched along u, with fine fibres."""
    rng = np.random.default_rng(m.seed)
    base = np.asarray(m.color, np.float32)
    dark = base * 0.62
    v = np.linspace(0, 1, size, dtype=np.float32)[:, None]
    warp = fractal_noise(rng, size, 2, 3)
    rings = 0.5 + 0.5 * np.sin(2 * np.pi * (v * rng.uniform(9, 16) + 2.2 * warp))
    rings = rings**3
    fibre = value_noise(rng, size, 48, (8, 1))[:, :]
    t = np.clip(0.75 * rings + 0.35 * fibre - 0.1, 0, 1)
    return _rgb(_mix(base, dark, t))


def weave(m: Material, size: int) -> Image.Image:
    """Basket weave: alternating blocks of horizontal and vertical strands with shading and gaps."""
    rng = np.random.default_rng(m.seed)
    base = np.asarray(m.color, np.float32)
    n_blocks = int(m.param("blocks", 10))
    strands = 3
    y, x = np.mgrid[0:size, 0:size].astype(np.float32) / size * n_blocks
    bx, by = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = x - bx, y - by
    horizontal = (bx + by) % 2 == 0
    across = np.where(horizontal, fy, fx) * strands
    along = np.where(horizontal, fx, fy)
    s = across - np.floor(across)
    shade = np.sin(np.pi * s) ** 0.6                      # round strands
    shade *= 0.85 + 0.15 * np.sin(np.pi * along)          # dips where strands pass under
    gap = (s < 0.08) | (s > 0.92)
    fib = value_noise(rng, size, 64)
    t = np.clip(0.25 + 0.75 * shade + 0.12 * (fib - 0.5), 0, 1)
    t[gap] *= 0.35
    col = base[None, None, :] * t[..., None]
    jitter = 1 + 0.12 * (value_noise(rng, size, n_blocks) - 0.5)
    return _rgb(col * jitter[..., None])


def noise(m: Material, size: int) -> Image.Image:
    """Speckled plastic / painted surface: base colour modulated by fractal noise and fine grain."""
    rng = np.random.default_rng(m.seed)
    base = np.asarray(m.color, np.float32)
    n = fractal_noise(rng, size, 3, 5)
    grain = rng.random((size, size)).astype(np.float32)
    t = 0.8 + 0.55 * (n - 0.5) + 0.08 * (grain - 0.5)
    speck = value_noise(rng, size, max(8, size // 6)) > 0.95       # sparse flecks: trackable features
    t[speck] *= 0.75
    return _rgb(base[None, None, :] * t[..., None])


def metal(m: Material, size: int) -> Image.Image:
    """Brushed metal: fine streaks along u plus low-frequency sheen."""
    rng = np.random.default_rng(m.seed)
    base = np.asarray(m.color, np.float32)
    streak = value_noise(rng, size, 4, (64, 1))
    sheen = value_noise(rng, size, 2)
    t = 0.82 + 0.22 * (streak - 0.5) + 0.2 * (sheen - 0.5)
    return _rgb(base[None, None, :] * t[..., None])


def printed(m: Material, size: int) -> Image.Image:
    """A printed pattern (labels, packaging): a grid of random shapes in an accent colour on a noisy base."""
    rng = np.random.default_rng(m.seed)
    base = np.asarray(m.color, np.float32)
    accent = np.asarray(m.param("accent", (0.1, 0.2, 0.6)), np.float32)
    accent2 = np.asarray(m.param("accent2", (0.8, 0.2, 0.1)), np.float32)
    img = np.broadcast_to(base, (size, size, 3)).copy()
    img *= (0.9 + 0.2 * (fractal_noise(rng, size, 4, 3) - 0.5))[..., None]
    y, x = np.mgrid[0:size, 0:size].astype(np.float32) / size
    cells = int(m.param("cells", 6))
    for i in range(cells):
        for j in range(cells):
            cx, cy = (j + 0.5) / cells, (i + 0.5) / cells
            r = rng.uniform(0.15, 0.4) / cells
            col = accent if rng.random() < 0.6 else accent2
            kind = rng.integers(3)
            if kind == 0:
                mask = (x - cx) ** 2 + (y - cy) ** 2 < r * r
            elif kind == 1:
                mask = (np.abs(x - cx) < r) & (np.abs(y - cy) < r * 0.5)
            else:
                mask = (np.abs(x - cx) + np.abs(y - cy)) < r
            img[mask] = col
    # thin stripes (text-like lines)
    lines = np.sin(y * size * 0.9) > 0.96
    img[lines] *= 0.7
    return _rgb(img)


def glass(m: Material, size: int) -> Image.Image:
    """Tinted glass / lens: smooth gradient with a faint reflection band."""
    rng = np.random.default_rng(m.seed)
    base = np.asarray(m.color, np.float32)
    y, x = np.mgrid[0:size, 0:size].astype(np.float32) / size
    band = np.exp(-(((x + y) - rng.uniform(0.6, 1.4)) ** 2) / 0.01)
    t = 0.85 + 0.15 * y + 0.4 * band
    return _rgb(base[None, None, :] * t[..., None])


_MAKERS = {"wood": wood, "weave": weave, "noise": noise, "metal": metal, "print": printed, "glass": glass}


def texture_image(m: Material, size: int = 256) -> Image.Image:
    """The (size, size) RGB image of material ``m`` (deterministic in ``m``)."""
    if m.kind not in _MAKERS:
        raise ValueError(f"unknown material kind {m.kind!r} (known: {list(_MAKERS)})")
    return _MAKERS[m.kind](m, size)
