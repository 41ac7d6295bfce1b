"""Numba's on-disk cache of the ``cpu`` backend's kernels, filled by a throwaway process.

Why: a process that loads the cached compositing kernels renders with slightly different float rounding than
one that compiled them (measured, storage-0001, 40 training iterations, 1 thread: latents up to 6e-3 apart),
while any two loading processes agree bit for bit. ``pd2gs run`` calls :func:`warm_in_subprocess` in each
worker process before it renders, so every task loads the same compiled kernels: the same
submission from any worker, on a rerun and after a retried task, and one compile per cache (33 s measured on 2
cores, both float types) instead of one per worker process.

``python -m pd2gs.render.kernel_cache`` fills the cache (the folder numba picks: ``NUMBA_CACHE_DIR`` or
``__pycache__`` beside the kernels).
"""
from __future__ import annotations

import logging
import subprocess
import sys

log = logging.getLogger(__name__)

_WARMED = False


def exercise() -> None:
    """Render a few Gaussians forward and backward with every kernel variant the pipeline calls: float32 and
    float64, with and without per-label weights and per-Gaussian max weights (numba compiles, or loads, one
    entry per argument-type signature)."""
    import torch

    from pd2gs.render import rasterize

    g = torch.Generator().manual_seed(0)
    for dtype in (torch.float32, torch.float64):
        n = 16
        means = (torch.rand(n, 3, generator=g, dtype=dtype) - 0.5) * 0.4
        quats = torch.randn(n, 4, generator=g, dtype=dtype)
        scales = torch.full((n, 3), 0.05, dtype=dtype)
        colors = torch.rand(n, 3, generator=g, dtype=dtype)
        opac = torch.full((n,), 0.8, dtype=dtype)
        K = torch.tensor([[40.0, 0.0, 16.0], [0.0, 40.0, 12.0], [0.0, 0.0, 1.0]], dtype=dtype)
        w2c = torch.eye(4, dtype=dtype)
        w2c[2, 3] = 2.0
        for labelled in (False, True):
            params = [t.clone().requires_grad_(True) for t in (means, quats, scales, colors, opac)]
            out = rasterize(*params, K, w2c, 32, 24, background=torch.ones(3, dtype=dtype), backend="cpu",
                            labels=torch.arange(n) % 2 if labelled else None, return_max_weight=labelled)
            (out.rgb.sum() + out.alpha.sum() + out.depth.sum()).backward()


def warm_in_subprocess(timeout: float = 900.0) -> bool:
    """Fill the kernel cache from a child process, once per process (later calls return at once) -> whether
    the child succeeded. On failure (a cache folder that cannot be written, say) this process compiles the
    kernels itself, and its outputs may differ in the last bits from those of tasks that loaded them; a
    warning is logged."""
    global _WARMED
    if _WARMED:
        return True
    _WARMED = True
    if "pd2gs.render.cpu_kernels" in sys.modules:  # this process already holds its kernels
        return True
    try:
        r = subprocess.run([sys.executable, "-m", __name__], capture_output=True, text=True, timeout=timeout)
    except (OSError, subprocess.TimeoutExpired) as e:
        log.warning("numba kernel cache not filled (%s); this process compiles the kernels itself", e)
        return False
    if r.returncode != 0:
        log.warning("numba kernel cache not filled (exit %d): %s", r.returncode, r.stderr.strip()[-500:])
        return False
    return True


if __name__ == "__main__":
    exercise()
