"""Measured: recover the synthetic lid's joint from a perturbed start (``python -m pd2gs.articulated.experiment``).

The start: canonical centres = GT + Gaussian noise, colours jittered, ownership from a labelling with a
fraction of labels flipped, joint axis rotated off the truth, pivot moved, values jittered. The fit sees
the renders (and masks) of every state; the result is the axis error (degrees), the pivot's distance to
the true axis line (m), the joint value errors (degrees) and the ownership accuracy.
"""
from __future__ import annotations

import argparse
import json
import math
import time
from dataclasses import asdict, dataclass

import numpy as np
import torch

from .fit import FitConfig, evaluate_views, fit_articulated
from .model import ArticulatedGaussians, canonical_gaussians
from .scenes import angle_between_deg, line_distance, make_scene, render_scene


@dataclass
class Perturbation:
    """How far the start is from the truth: axis tilt (deg), pivot offset (m), value jitter (deg),
    centre noise (m, std), colour jitter (std), fraction of flipped ownership labels."""

    axis_deg: float = 15.0
    pivot_m: float = 0.05
    values_deg: float = 5.0
    means_m: float = 0.005
    colors: float = 0.1
    flip: float = 0.15
    seed: int = 0


def perturbed_lid_model(scene, p: Perturbation) -> ArticulatedGaussians:
    """The lid scene's model with every quantity perturbed as ``p`` says."""
    g = torch.Generator().manual_seed(p.seed)
    rng = np.random.default_rng(p.seed)
    n = scene.means.shape[0]
    means = scene.means + p.means_m * torch.randn(n, 3, generator=g)
    colors = (scene.colors + p.colors * torch.randn(n, 3, generator=g)).clamp(0.05, 0.95)
    labels = scene.labels.clone()
    flip = torch.from_numpy(rng.random(n) < p.flip)
    labels[flip] = 1 - labels[flip]
    axis = scene.axes[0]
    ortho = np.cross(axis, rng.normal(size=3))
    ortho /= np.linalg.norm(ortho)
    a = math.radians(p.axis_deg)
    tilted = math.cos(a) * axis + math.sin(a) * ortho
    d = rng.normal(size=3)
    d -= axis * (d @ axis)  # move the pivot off the axis line, not along it
    pivot = scene.pivots[0] + p.pivot_m * d / np.linalg.norm(d)
    values = scene.values + np.radians(p.values_deg) * rng.normal(size=scene.values.shape)
    values[0] = scene.values[0]
    gauss = canonical_gaussians(means, scene.quats, scene.scales, colors, scene.opacities)
    return ArticulatedGaussians(gauss, scene.parent, scene.joint_types, tilted[None], pivot[None], values, labels,
                                confidence=4.0)


def joint_errors(model: ArticulatedGaussians, scene) -> dict:
    """Axis angle (deg), pivot-to-true-axis distance (m), max value error (deg), ownership accuracy."""
    j = model.joint_dict(1)
    return {"axis_deg": angle_between_deg(j["axis"], scene.axes[0]),
            "pivot_m": line_distance(scene.pivots[0], scene.axes[0], j["pivot"]),
            "values_deg": float(np.degrees(np.max(np.abs(np.sign(np.dot(j["axis"], scene.axes[0]))
                                                           * np.asarray(j["values"]) - scene.values[:, 0])))),
            "ownership_acc": float((model.labels() == scene.labels).float().mean())}


def run(n: int = 3000, views: int = 12, size=(64, 48), iters: int = 600, p: Perturbation | None = None,
        cfg: FitConfig | None = None, seed: int = 0) -> dict:
    """One measured recovery -> dict of the start's and the fit's errors, seconds and test L1."""
    p = p or Perturbation(seed=seed)
    scene = make_scene("lid", n=n, seed=seed)
    frames, masks = render_scene(scene, views=views, size=size)
    model = perturbed_lid_model(scene, p)
    before = joint_errors(model, scene)
    cfg = cfg or FitConfig(iters=iters, seed=seed)
    res = fit_articulated(model, frames, masks, cfg)
    after = joint_errors(model, scene)
    return {"threads": torch.get_num_threads(), "n": n, "views": views, "size": list(size), "iters": cfg.iters,
            "perturbation": asdict(p), "start": before, "fit": after, "seconds": round(res.seconds, 1),
            "test_l1": evaluate_views(model, frames), "loss_first_last": [res.losses[0], res.losses[-1]]}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=3000)
    ap.add_argument("--iters", type=int, default=600)
    ap.add_argument("--views", type=int, default=12)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args(argv)
    torch.set_num_threads(args.threads)
    t = time.perf_counter()
    out = run(args.n, args.views, iters=args.iters, seed=args.seed)
    out["total_seconds"] = round(time.perf_counter() - t, 1)
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
