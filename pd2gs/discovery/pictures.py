"""Pictures of a discovery result: Gaussians coloured by part with estimated (solid) and true (dashed)
joint axes, and a strip of continuous part-level control (one part moved at a time).

Control strip: with a field that can render interpolated latents (``StateField.deform``), part p's
Gaussians are taken from the field at latent lerp(z_start, z_end, t) and every other part stays at the
start state; without it the estimated joint is applied to part p at value t * v_end (kinematic control).
"""
from __future__ import annotations

import io
import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402
from scipy.spatial.transform import Rotation  # noqa: E402

from rsart.io import atomic_write_bytes  # noqa: E402
from rsart.kinematics import joint_motion  # noqa: E402

from .field import StateField  # noqa: E402
from .submission import ObjectResult  # noqa: E402

PALETTE = np.array([[0.6, 0.6, 0.6], [0.89, 0.1, 0.11], [0.22, 0.49, 0.72], [0.3, 0.69, 0.29],
                    [0.6, 0.31, 0.64], [1.0, 0.5, 0.0], [0.65, 0.34, 0.16], [0.97, 0.51, 0.75]])


def part_colors(labels: np.ndarray) -> np.ndarray:
    """(N, 3) RGB per label (label 0 = grey static)."""
    return PALETTE[np.asarray(labels) % len(PALETTE)]


def controlled_part(fld: StateField, labels: np.ndarray, part: int, t: float, start: str, end: str,
                    joint=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(means, quats, scales) with only ``part`` moved to fraction t of its start->end motion."""
    k = fld.index(start)
    m, q, s = fld.means[k].copy(), fld.quats[k].copy(), fld.scales[k].copy()
    sel = labels == part
    if fld.deform is not None:
        mi, qi, si = fld.deform(start, end, t)
        m[sel], q[sel], s[sel] = mi[sel], qi[sel], si[sel]
    elif joint is not None:
        T = joint_motion(joint.type, joint.axis, joint.origin, t * (joint.values[end] - joint.values[start]))
        m[sel] = m[sel] @ T[:3, :3].T + T[:3, 3]
        r = Rotation.from_matrix(T[:3, :3]) * Rotation.from_quat(q[sel][:, [1, 2, 3, 0]])
        q[sel] = r.as_quat()[:, [3, 0, 1, 2]]
    return m, q, s


def _render(m, q, s, colors, opac, cam) -> np.ndarray:
    from pd2gs.render import rasterize

    f = lambda a: torch.as_tensor(np.ascontiguousarray(a), dtype=torch.float32)  # noqa: E731
    with torch.no_grad():
        out = rasterize(f(m), f(q), f(s), f(colors), f(opac), f(cam.K), f(cam.w2c), cam.width, cam.height,
                        background=torch.ones(3))
    return np.concatenate([out.rgb.clamp(0, 1).numpy(), out.alpha.numpy()[..., None]], axis=-1)


def _axis_line(ax, origin, axis, length, **kw):
    o, a = np.asarray(origin), np.asarray(axis) / np.linalg.norm(axis)
    p = np.stack([o - a * length / 2, o + a * length / 2])
    ax.plot(p[:, 0], p[:, 1], p[:, 2], **kw)


def save_pictures(res: ObjectResult, obj, out_path: str | os.PathLike, steps: int = 5, max_points: int = 6000,
                  max_side: int = 200) -> None:
    """Write one PNG: left, Gaussians (start state) coloured by part with estimated (solid) and true
    (dashed) axes; right, one row per movable part moved through ``steps`` control values."""
    fld: StateField = res.field
    labels = fld.labels
    ev = obj.meta.eval_states
    start, end = ev["start"], ev["end"]
    movable = [p for p in res.parts if p.joint is not None]
    fig = plt.figure(figsize=(4 + 2.2 * steps, max(4.0, 2.2 * len(movable))))
    gs = fig.add_gridspec(max(1, len(movable)), steps + 2)
    ax = fig.add_subplot(gs[:, :2], projection="3d")
    k = fld.index(start)
    rng = np.random.default_rng(0)
    idx = rng.choice(fld.n, min(fld.n, max_points), replace=False)
    P = fld.means[k][idx]
    ax.scatter(P[:, 0], P[:, 1], P[:, 2], c=part_colors(labels[idx]), s=1)
    extent = float(np.linalg.norm(np.ptp(P, axis=0)))
    for p in movable:
        _axis_line(ax, p.joint.origin, p.joint.axis, 0.6 * extent, color=PALETTE[p.label % len(PALETTE)], lw=2.5,
                   label=f"{p.name} ({p.joint.type})")
    true_axes = obj.twin.posed_axes(obj.meta.state(start).values)
    for j in obj.meta.joints:
        o, a = true_axes[j.name]
        _axis_line(ax, o, a, 0.6 * extent, color="k", ls="--", lw=1.2)
    ax.plot([], [], "k--", label="true axes")
    ax.legend(fontsize=7, loc="upper left")
    ax.set_title(f"{res.object_id}: parts and joint axes", fontsize=9)
    st = obj.states[start]
    view = (st.split("train") or st.views)[0]
    cam = view.camera
    sc = min(1.0, max_side / max(cam.width, cam.height))
    cam = cam.scaled(round(cam.width * sc), round(cam.height * sc))
    renders = {(r, c): _render(*controlled_part(fld, labels, p.label, float(t), start, end, p.joint),
                               fld.colors, fld.opacities, cam)
               for r, p in enumerate(movable) for c, t in enumerate(np.linspace(0.0, 1.0, steps))}
    cover = np.any([img[..., 3] > 0.02 for img in renders.values()], axis=0) if renders else None
    if cover is not None and cover.any():  # crop every frame to the union of the object's footprints
        rows, cols = np.flatnonzero(cover.any(1)), np.flatnonzero(cover.any(0))
        pad = 4
        y0, y1 = max(0, rows[0] - pad), min(cover.shape[0], rows[-1] + pad + 1)
        x0, x1 = max(0, cols[0] - pad), min(cover.shape[1], cols[-1] + pad + 1)
    for (r, c), img in renders.items():
        a2 = fig.add_subplot(gs[r, 2 + c])
        a2.imshow(img[y0:y1, x0:x1, :3] if cover is not None and cover.any() else img[..., :3])
        a2.set_axis_off()
        a2.set_title(f"{movable[r].name} t={c / max(1, steps - 1):.2f}", fontsize=7)
    buf = io.BytesIO()
    fig.tight_layout()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    atomic_write_bytes(out_path, buf.getvalue())
