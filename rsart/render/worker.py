"""What runs inside a render worker (a pool process, a Ray worker, or this process): one task at a time.

:func:`render_task` renders and writes the views of one :class:`rsart.render.runner.ViewTask`; each
worker keeps its scene between tasks of the same state. Its own module so that the planner
(:mod:`.runner`) and the optional Ray backend (:mod:`.ray_backend`) both call it without importing
each other.
"""
from __future__ import annotations

import zlib
from pathlib import Path

import numpy as np

from ..errors import RsartError
from ..io import write_depth_png, write_mask_png, write_png_rgb


def stable_seed(*parts: object) -> np.random.SeedSequence:
    """A seed sequence from ints and strings (CRC32 of strings: stable across runs, unlike ``hash``)."""
    ints = [p if isinstance(p, int) else zlib.crc32(str(p).encode()) for p in parts]
    return np.random.SeedSequence(ints)


_WORKER: dict = {"key": None, "renderer": None, "nthreads": 0}


def init_worker(nthreads: int) -> None:
    """Per-process setup: ray-casting threads (0 = all cores)."""
    _WORKER["nthreads"] = nthreads


def render_task(task: "ViewTask") -> int:
    """Render and write the views of ``task``; returns the number of views written.

    Any failure is re-raised as :class:`RsartError` naming the object, state and view.
    """
    try:
        return _render_task(task)
    except RsartError:
        raise
    except Exception as e:  # a worker's traceback is no use to a CLI user: say what failed where
        raise RsartError(f"{task.obj_dir}: state {task.state_id}: rendering failed "
                         f"({type(e).__name__}: {e})") from e


def _render_task(task: "ViewTask") -> int:
    from .frame import StateRenderer

    job = task.job
    key = (task.obj_dir, task.state_id, repr(job.options), sorted(task.values.items()), task.radius)
    if _WORKER["key"] != key:  # scenes are built once per state and process
        sr = StateRenderer(task.twin, task.values, job.options, task.bounds, task.radius,
                           nthreads=_WORKER["nthreads"])
        _WORKER.update(key=key, renderer=sr)
    sr = _WORKER["renderer"]
    sdir = Path(task.obj_dir) / "states" / task.state_id
    for vid, c2w in task.views:
        rng = np.random.default_rng(stable_seed(job.seed, task.object_id, task.state_id, vid, "view"))
        f = sr.render(c2w, rng)
        scale = job.options.depth_scale
        if job.options.sensor:
            write_png_rgb(sdir / "rgb_clean" / f"{vid}.png", f.rgb_clean)
            write_depth_png(sdir / "depth_clean" / f"{vid}.png", f.depth_clean, scale)
        write_mask_png(sdir / "mask" / f"{vid}.png", f.mask)
        write_depth_png(sdir / "depth" / f"{vid}.png", f.depth, scale)
        write_png_rgb(sdir / "rgb" / f"{vid}.png", f.rgb)
    return len(task.views)
