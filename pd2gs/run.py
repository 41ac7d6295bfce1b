"""``pd2gs run``: train -> discover parts -> kinematics -> meshes -> an rsart-submission/1, per object.

Glue between the trainer (:mod:`pd2gs.train`) and part discovery (:mod:`pd2gs.discovery`); an object
that fails anywhere becomes ``null`` in the submission with its reason logged, never a crash.
"""
from __future__ import annotations

import dataclasses
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


def run(data: str | Path, out: str | Path, objects: list[str] | None = None, split: str | None = None,
        train_cfg=None, discovery_cfg=None, progress: bool = True) -> Path:
    """Run PD²GS on every object (of ``split`` / ``objects``) under ``data``; write ``out/submission/``.

    Training runs go to ``out/runs/<object_id>/`` (a re-run reuses finished runs); the submission (meshes +
    ``submission.json``, scored by ``rsart-eval``) to ``out/submission/``. Returns the submission.json path.
    """
    import rsart

    from .discovery.config import DiscoveryConfig
    from .discovery.pipeline import dataset_block, discover_safe, method_block
    from .discovery.submission import ObjectFailure, write_submission
    from .train import TrainConfig

    data, out = Path(data), Path(out)
    d = rsart.load(data)
    if isinstance(d, rsart.RSArtObject):
        objs = [d]
    else:
        ids = objects or (d.splits[split] if split else list(d))
        unknown = [i for i in ids if i not in d]
        if unknown:
            raise RsartError(f"{data}: unknown objects {unknown}")
        objs = [d[i] for i in ids]
    dcfg = discovery_cfg or DiscoveryConfig()
    results = {}
    for obj in objs:
        t0 = time.perf_counter()
        cfg = TrainConfig.from_json(asdict(train_cfg)) if train_cfg is not None else TrainConfig()
        try:
            model = train_object(obj.path, out / "runs" / obj.id, cfg, progress=progress)
            ocfg = dcfg if dcfg.background is not None else dataclasses.replace(dcfg, background=model.background)
            results[obj.id] = discover_safe(model, obj, ocfg)
        except Exception as e:  # a failed object is a null entry, never a crash
            log.error("%s: %s: %s", obj.id, type(e).__name__, e)
            results[obj.id] = e if isinstance(e, ObjectFailure) else ObjectFailure(f"{type(e).__name__}: {e}")
        status = "failed: " + str(results[obj.id]) if isinstance(results[obj.id], BaseException) else "ok"
        print(f"[pd2gs] {obj.id}: {status} ({time.perf_counter() - t0:.0f} s)", flush=True)
    n_states = dcfg.n_states or len(train_cfg.states if train_cfg is not None and train_cfg.states else
                                    [s for s in objs[0].meta.states if s.kind == "multi"])
    return write_submission(results, out / "submission", method_block(dcfg, n_states), dataset_block(str(data)),
                            overwrite=True)
