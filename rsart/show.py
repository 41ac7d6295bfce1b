"""Contact sheets of a twin: the object drawn in each interaction state, joint axes as arrows.

``show_twin`` draws every state of an object (from its meta.json, or the RS-Art protocol
states for an in-memory twin) as a matplotlib 3-D mesh plot (Poly3DCollection, Lambert-shaded
faces coloured per part), with each joint's axis drawn as an arrow through its origin, all
panels sharing one metric bounding box. World frame, z up, metres.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .errors import RsartError
from .format import State
from .kinematics import Twin
from .states import protocol_states

PART_COLORS = ["#9a9a9a", "#e6550d", "#3182bd", "#31a354", "#d6b300", "#756bb1", "#e377c2", "#17becf"]
_LIGHT = np.array([0.35, -0.55, 0.75]) / np.linalg.norm([0.35, -0.55, 0.75])


def _load(obj: str | Path | Twin) -> tuple[Twin, list[State] | None, str]:
    if isinstance(obj, Twin):
        return obj, None, obj.name
    path = Path(obj)
    if not (path / "meta.json").exists():
        raise RsartError(f"{path}: not an object folder (no meta.json)")
    from .format import read_meta
    from .twin_io import read_twin

    meta = read_meta(path / "meta.json")
    return read_twin(path), meta.states, meta.object_id


def _shaded(colors_rgb: np.ndarray, normals: np.ndarray) -> np.ndarray:
    lam = np.abs(normals @ _LIGHT)
    return np.clip(colors_rgb * (0.35 + 0.65 * lam)[:, None], 0, 1)


def _display_triangles(mesh, max_edge: float) -> tuple[np.ndarray, np.ndarray]:
    """(F, 3, 3) triangles and (F, 3) normals, long triangles split so matplotlib's per-polygon
    depth sort (painter's algorithm) draws fewer wrong overlaps."""
    import trimesh

    normals = mesh.face_normals
    try:
        v, f, idx = trimesh.remesh.subdivide_to_size(mesh.vertices, mesh.faces, max_edge, max_iter=6, return_index=True)
        return v[f], normals[idx]
    except ValueError:
        return mesh.vertices[mesh.faces], normals


def _draw(ax, twin: Twin, values: dict[str, float], lims: np.ndarray, axis_len: float) -> None:
    from matplotlib.colors import to_rgb
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    tris, cols = [], []
    max_edge = float(np.max(lims[1] - lims[0])) / 12
    for i, m in enumerate(twin.posed_meshes(values)):
        base = np.asarray(to_rgb(PART_COLORS[i % len(PART_COLORS)]))
        t, n = _display_triangles(m, max_edge)
        tris.append(t)
        cols.append(_shaded(np.broadcast_to(base, (len(t), 3)), n))
    pc = Poly3DCollection(np.concatenate(tris), facecolors=np.concatenate(cols), edgecolors="none", linewidths=0)
    ax.add_collection3d(pc)
    for name, (o, a) in twin.posed_axes(values).items():
        p0 = o - a * axis_len * 0.5
        ax.quiver(*p0, *(a * axis_len), color="red", linewidth=1.8, arrow_length_ratio=0.18)
    ax.set_xlim(*lims[:, 0])
    ax.set_ylim(*lims[:, 1])
    ax.set_zlim(*lims[:, 2])
    ax.set_box_aspect(lims[1] - lims[0])
    ax.view_init(elev=25, azim=-55)
    ax.set_axis_off()


def show_twin(obj_dir_or_twin: str | Path | Twin, out_png: str | Path, states: list[str] | None = None,
              dpi: int = 90, title: str | None = None) -> Path:
    """Write a contact sheet PNG of the twin in each state to ``out_png``; returns its path.

    ``obj_dir_or_twin``: an object folder (meta.json + twin) or a :class:`Twin`;
    ``states``: state ids to draw (default: all of the object's states; for a bare Twin the
    RS-Art protocol states m0..m3 + single min/max).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .io import atomic_write_bytes

    twin, meta_states, name = _load(obj_dir_or_twin)
    all_states = meta_states if meta_states is not None else protocol_states(twin.joints)[0]
    if states:
        by_id = {s.id: s for s in all_states}
        missing = [s for s in states if s not in by_id]
        if missing:
            raise RsartError(f"{name}: unknown states {missing} (states: {list(by_id)})")
        all_states = [by_id[s] for s in states]
    boxes = np.array([twin.bounds(s.values) for s in all_states])
    lo, hi = boxes[:, 0].min(0), boxes[:, 1].max(0)
    pad = 0.06 * float(np.max(hi - lo))
    lims = np.array([lo - pad, hi + pad])
    axis_len = 0.25 * float(np.max(hi - lo))
    ncols = min(4, len(all_states))
    nrows = math.ceil(len(all_states) / ncols)
    fig = plt.figure(figsize=(3.2 * ncols, 3.2 * nrows + 0.4))
    for k, s in enumerate(all_states):
        ax = fig.add_subplot(nrows, ncols, k + 1, projection="3d")
        _draw(ax, twin, s.values, lims, axis_len)
        label = s.id if s.kind == "multi" else f"{s.id} ({s.joint} {s.extreme})"
        ax.set_title(label, fontsize=8)
    fig.suptitle(title or f"{name}: {len(twin.parts) - 1} movable parts, {len(twin.joints)} joints", fontsize=10)
    fig.subplots_adjust(left=0, right=1, bottom=0, top=0.92, wspace=0, hspace=0.08)
    import io

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    plt.close(fig)
    out = Path(out_png)
    atomic_write_bytes(out, buf.getvalue())
    return out
