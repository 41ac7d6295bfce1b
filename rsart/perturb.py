"""Camera-pose robustness copies of an object folder (the PD²GS paper's pose-error study).

:func:`perturb_object` copies an object folder and rewrites every ``cameras.json``:

* Gaussian pose noise ``(rot_deg, trans)`` -- each camera is rotated by ``exp([ω]×)`` in its own frame with
  ``ω ~ N(0, (rot_deg·π/180)² I₃)`` (each rotation-vector component has standard deviation ``rot_deg``
  degrees) and its centre moved by ``N(0, trans² I₃)`` in the object's units (metres or scene units). The
  paper's settings are (1°, 0.02) and (3°, 0.05).
* ``poses="colmap"``: the true poses are replaced by SfM estimates (``capture_tools.object_poses``; needs the
  capture_tools package), expressed in the object frame by a similarity fitted to the true camera centres
  (the gauge every pose-free evaluation fixes); views SfM did not register are left out of cameras.json.

Draws come from ``numpy.random.default_rng(seed)`` in meta.json's state order and cameras.json's view
order, so a copy is reproducible. What was done is recorded in ``meta.json`` (``camera_poses``) and in each
``cameras.json`` (``pose_perturbation``). Images are copied unchanged.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .errors import RsartError
from .format import CamerasFile, read_cameras, read_meta, write_cameras, write_meta
from .io import atomic_dir, copy_folder_contents
from .kinematics import rotation_matrix

POSE_SOURCES = ("gt", "colmap")


def perturb_c2w(c2w: np.ndarray, rot_deg: float, trans: float, rng: np.random.Generator) -> np.ndarray:
    """(4, 4) ``c2w`` with camera-frame rotation noise (σ ``rot_deg`` per axis) and centre noise (σ ``trans``)."""
    out = np.array(c2w, dtype=np.float64, copy=True)
    w = rng.normal(0.0, math.radians(rot_deg), size=3)
    t = rng.normal(0.0, trans, size=3)
    ang = float(np.linalg.norm(w))
    if ang > 0:
        out[:3, :3] = out[:3, :3] @ rotation_matrix(w / ang, ang)
    out[:3, 3] = out[:3, 3] + t
    return out


def _check(rot_deg: float, trans: float, poses: str) -> None:
    if not (math.isfinite(rot_deg) and rot_deg >= 0):
        raise RsartError(f"--rot-deg must be a finite number >= 0 (degrees), got {rot_deg}")
    if not (math.isfinite(trans) and trans >= 0):
        raise RsartError(f"--trans must be a finite number >= 0 (object units), got {trans}")
    if poses not in POSE_SOURCES:
        raise RsartError(f"--poses {poses!r} is not one of {POSE_SOURCES}")


def perturb_object(src: str | Path, out: str | Path, rot_deg: float = 0.0, trans: float = 0.0, seed: int = 0,
                   poses: str = "gt", overwrite: bool = False) -> dict:
    """Write the perturbed copy ``out`` of object folder ``src``; returns a summary (views per state, settings)."""
    _check(rot_deg, trans, poses)
    src, out = Path(src), Path(out)
    if not (src / "meta.json").is_file():
        raise RsartError(f"{src}: not an object folder (no meta.json)")
    if out.resolve() == src.resolve() or out.resolve().is_relative_to(src.resolve()):
        raise RsartError(f"{out}: the copy must lie outside the source object folder {src}")
    meta = read_meta(src)
    states = [s.id for s in meta.states if (src / "states" / s.id / "cameras.json").is_file()]
    if not states:
        raise RsartError(f"{src}: no captured states (states/<id>/cameras.json) to perturb")
    estimate = None
    if poses != "gt":
        # pose estimators are plug-ins (entry-point group rsart.pose_estimators; capture_tools provides
        # "colmap"), so rsart never imports capture_tools itself
        from importlib.metadata import entry_points

        eps = {ep.name: ep for ep in entry_points(group="rsart.pose_estimators")}
        if poses not in eps:
            raise RsartError(f"--poses {poses} needs a pose estimator plug-in named {poses!r} "
                             f"(installed: {sorted(eps) or 'none'}; capture_tools provides 'colmap')")
        try:
            estimate = eps[poses].load()
        except ImportError as e:
            raise RsartError(f"--poses {poses}: the estimator could not be loaded: {e}") from None
    rng = np.random.default_rng(seed)
    summary: dict = {"rot_deg": rot_deg, "trans": trans, "seed": seed, "poses": poses, "states": {}}
    record = {"source": poses, "rot_deg": rot_deg, "trans": trans, "seed": seed, "units": meta.units,
              "noise": "camera-frame rotation vector ~ N(0, rot_deg^2 I3) degrees; centre ~ N(0, trans^2 I3)"}
    with atomic_dir(out, overwrite=overwrite) as tmp:
        copy_folder_contents(src, tmp)
        for sid in states:
            cams = read_cameras(src / "states" / sid / "cameras.json")
            views = list(cams.views)
            info: dict = {"views": len(views)}
            if estimate is not None:
                est, est_info = estimate(src, sid)
                views = [v for v in views if v.id in est]
                for v in views:
                    v.c2w = est[v.id]
                info.update(est_info, views=len(views), dropped=len(cams.views) - len(views))
            for v in views:
                v.c2w = perturb_c2w(v.c2w, rot_deg, trans, rng) if (rot_deg or trans) else v.c2w
            extra = dict(cams.extra, pose_perturbation=record)
            write_cameras(CamerasFile(cams.intrinsics, cams.depth_scale, views, extra),
                          tmp / "states" / sid / "cameras.json")
            summary["states"][sid] = info
        meta.extra = dict(meta.extra, camera_poses=record)
        write_meta(meta, tmp / "meta.json")
    return summary
