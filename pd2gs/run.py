"""``pd2gs run``: train -> discover parts -> kinematics -> meshes -> an rsart-submission/1, per object.

Glue between the trainer (:mod:`pd2gs.train`) and part discovery (:mod:`pd2gs.discovery`); an object
that fails anywhere becomes ``null`` in the submission with its reason logged, never a crash.
"""
from __future__ import annotations

import logging
import time
from dataclasses import asdict
from pathlib import Path

import torch

from rsart.errors import RsartError

log = logging.getLogger(__name__)


class TrainedModel:
    """A trained :class:`~pd2gs.deform.DeformableField` seen as per-state Gaussians (what discovery reads).

    ``state_gaussians(sid)`` -> dict of numpy-able tensors: means (N, 3) m, quats (N, 4) wxyz, scales (N, 3)
    standard deviations, colors (N, 3), opacities (N,); ``interpolate(a, b, t)`` the same at the latent
    lerp(α_a, α_b, t).
    """

    def __init__(self, field, state_ids: list[str], background: tuple[float, float, float] | None = None):
        self.field = field
        self.state_ids = list(state_ids)
        self.background = background  # the trainer's render background (RGB in [0, 1])

    def _gaussians(self, latent: torch.Tensor) -> dict:
        with torch.no_grad():
            d = self.field.deform(latent)
            g = self.field.gaussians
            return {"means": d.means, "quats": d.quats, "scales": d.log_scales.exp(), "colors": g.colors,
                    "opacities": g.opacities}

    def state_gaussians(self, sid: str) -> dict:
        return self._gaussians(self.field.latent(self.state_ids.index(sid)))

    def interpolate(self, a: str, b: str, t: float) -> dict:
        return self._gaussians(self.field.interpolate(self.state_ids.index(a), self.state_ids.index(b), t))


def train_object(obj_dir: Path, run_dir: Path, cfg, progress: bool = True) -> TrainedModel:
    """Train (or resume / reuse a finished run in ``run_dir``) and return the trained model."""
    from .data import load_frames
    from .train import Trainer, load_field, write_json_atomic

    done = run_dir / "metrics.json"
    if done.is_file() and (run_dir / "checkpoint.pt").is_file():
        tcfg, field = load_field(run_dir)
        return TrainedModel(field, tcfg.states, tcfg.background)
    cfg.object_dir = str(obj_dir)
    cfg.states, frames = load_frames(obj_dir, cfg.states or None, cfg.size, with_depth=cfg.depth_init)
    trainer = Trainer(cfg, frames, run_dir)
    if (run_dir / "checkpoint.pt").is_file():
        trainer.load_state_dict(torch.load(run_dir / "checkpoint.pt", weights_only=False))
    run_dir.mkdir(parents=True, exist_ok=True)
    write_json_atomic(run_dir / "config.json", asdict(cfg))
    t0 = time.perf_counter()
    trainer.run(progress=progress)
    write_json_atomic(done, {"test_psnr": trainer.evaluate("test"), "train_psnr": trainer.evaluate("train"),
                             "iterations": trainer.iteration, "seconds": time.perf_counter() - t0,
                             "gaussians": trainer.field.gaussians.num})
    return TrainedModel(trainer.field, cfg.states, cfg.background)


def select_objects(data: str | Path, objects: list[str] | None = None, split: str | None = None) -> list:
    """The RSArtObjects to run: ``data`` is one object folder, or a dataset (all objects, a split, or ids)."""
    import rsart

    d = rsart.load(Path(data))
    if isinstance(d, rsart.RSArtObject):
        return [d]
    if split is not None and split not in d.splits:
        raise RsartError(f"{data}: unknown split {split!r} (index.json has {sorted(d.splits)})")
    ids = objects or (d.splits[split] if split else list(d))
    unknown = [i for i in ids if i not in d]
    if unknown:
        raise RsartError(f"{data}: unknown objects {unknown}")
    return [d[i] for i in ids]


def run(data: str | Path, out: str | Path, objects: list[str] | None = None, split: str | None = None,
        train_cfg=None, discovery_cfg=None, progress: bool = True, backend: str = "process",
        workers: int | None = None, address: str | None = None, threads: int | None = None) -> Path:
    """Run PD²GS on every object (of ``split`` / ``objects``) under ``data``; write ``out/submission/``.

    One task per object (:mod:`pd2gs.runner`: ``backend`` "process" with ``workers`` local processes, or
    "ray" on the cluster at ``address`` / a local Ray), ``threads`` CPU threads each (default: this
    machine's cores / workers; 1 on a Ray cluster). Training runs and per-object results go to
    ``out/runs/<object_id>/`` (a re-run skips finished objects and reuses finished stages); the
    submission (meshes + ``submission.json``, scored by ``rsart-eval``) to ``out/submission/``, and the
    done / failed / skipped summary to ``out/summary.json``. Returns the submission.json path.
    """
    from .discovery.config import DiscoveryConfig
    from .discovery.pipeline import dataset_block, method_block
    from .runner import ObjectTask, assemble, default_threads, execute, import_ray, summarize
    from .train import TrainConfig

    if backend == "ray":
        import_ray()  # before anything else: without ray, say how to install it
    data, out = Path(data), Path(out)
    objs = select_objects(data, objects, split)
    dcfg = discovery_cfg or DiscoveryConfig()
    tcfg = train_cfg or TrainConfig()
    if threads is None:
        threads = 1 if (backend == "ray" and address) else default_threads(workers or 1)
    if threads < 1:
        raise RsartError(f"threads must be at least 1, got {threads}")
    # absolute paths: a worker (a Ray node) need not share this process's working directory
    tasks = [ObjectTask(str(data.resolve()), o.id, str(out.resolve() / "runs" / o.id), tcfg, {"default": dcfg},
                        threads) for o in objs]
    outcomes = execute(tasks, backend, workers, address, progress)
    n_states = dcfg.n_states or len(tcfg.states or [s for s in objs[0].meta.states if s.kind == "multi"])
    sub = assemble(tasks, "default", outcomes, out / "submission", method_block(dcfg, n_states),
                   dataset_block(str(data)))
    summarize(outcomes, out / "summary.json")
    return sub
