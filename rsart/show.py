"""Contact sheets of a twin: the object drawn in each interaction state, joint axes as arrows.

``show_twin`` draws every state of an object (from its meta.json, or the RS-Art protocol
states for an in-memory twin) as a matplotlib 3-D mesh plot (Poly3DCollection, Lambert-shaded
faces coloured per part), all panels sharing one bounding box (world frame, z up, the object's
units). The viewpoint is chosen from the object (:func:`choose_view`): a three-quarter view of the
side its parts move towards. Joint axes are drawn on top of the meshes (never hidden), through
their moving part, with a length scaled to that part; a legend names each part colour and the
axis styles.
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


AXIS_STYLE = {"revolute": dict(color="#d00000", label="revolute axis"),
              "prismatic": dict(color="#7a00c4", label="prismatic axis (direction of travel)")}


def _joint_span(j) -> tuple[float, float]:
    """(from, to) values to probe a joint's motion: its limits, or a quarter turn from 0 without limits."""
    if j.limits is not None:
        return float(j.limits[0]), float(j.limits[1])
    return 0.0, math.pi / 2


def _front_vector(twin: Twin, rest: dict[str, float]) -> np.ndarray:
    """Horizontal (x, y) direction that the object's parts move towards (zero if none stands out).

    Per movable part, from ``rest`` with only its joint moved across its span: a prismatic part contributes
    its centroid's displacement; a part turning about a horizontal axis the direction from the hinge to its
    centroid (a lid hinged at the back points to the front), or its displacement when the hinge lies under
    its centroid (an oven door); a part turning about a near-vertical axis (a door) the direction its
    centroid starts to move in (out of the door's plane). Each contribution is a unit vector weighted by the
    part's size, so knobs spinning in place count little. When the contributions cancel out (two eyeglass
    legs folding towards each other) the displacements of all parts decide instead; when those cancel too
    (a box with four flaps) the result is zero."""
    start = twin.posed_meshes(rest)
    first, disp, weights = np.zeros(2), np.zeros(2), 0.0
    for j in twin.joints:
        lo, hi = _joint_span(j)
        frm = {**rest, j.name: lo}
        c0 = twin.posed_meshes(frm)[j.child].centroid
        c1 = twin.posed_meshes({**rest, j.name: hi})[j.child].centroid
        size = float(np.linalg.norm(start[j.child].extents))
        d = (c1 - c0)[:2]
        vec = d
        if j.type == "revolute":
            o, ax = twin.posed_axes(frm)[j.name]
            r = c0 - o
            r = r - ax * float(r @ ax)  # hinge -> centroid, perpendicular to the axis
            if abs(float(ax[2])) >= 0.7:
                vec = (np.cross(ax, r) * np.sign(hi - lo))[:2]  # the centroid's velocity as it starts to open
            elif np.linalg.norm(r[:2]) > 0.25 * max(np.linalg.norm(r), 1e-12):
                vec = r[:2]
        tiny = 1e-3 * max(size, 1e-12)
        if np.linalg.norm(vec) > tiny:
            first += vec / np.linalg.norm(vec) * size
        if np.linalg.norm(d) > tiny:
            disp += d / np.linalg.norm(d) * size
        weights += size
    for total in (first, disp):
        if weights > 0 and np.linalg.norm(total) > 0.3 * weights:  # the parts agree on a side
            return total
    return np.zeros(2)


def choose_view(twin: Twin, rest: dict[str, float] | None = None) -> tuple[float, float]:
    """(elevation, azimuth) in degrees for matplotlib's ``view_init``: 30° to the side of the direction the
    parts move towards (:func:`_front_vector`), 25° up (35° when a part turns about a horizontal axis, so
    the inside of a box under its lid shows). Falls back to (25, -55) when no direction stands out."""
    if rest is None:
        rest = {j.name: float(np.clip(0.0, *sorted(_joint_span(j)))) for j in twin.joints}
    f = _front_vector(twin, rest)
    lids = any(j.type == "revolute" and abs(float(j.axis[2])) < 0.7 for j in twin.joints)
    elev = 35.0 if lids else 25.0
    if float(np.linalg.norm(f)) < 1e-9:
        return elev, -55.0
    return elev, math.degrees(math.atan2(f[1], f[0])) + 30.0


def _draw(ax, twin: Twin, values: dict[str, float], lims: np.ndarray, view: tuple[float, float]) -> None:
    from matplotlib import patheffects
    from matplotlib.colors import to_rgb
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    tris, cols = [], []
    size = float(np.max(lims[1] - lims[0]))
    max_edge = size / 12
    meshes = twin.posed_meshes(values)
    for i, m in enumerate(meshes):
        base = np.asarray(to_rgb(PART_COLORS[i % len(PART_COLORS)]))
        t, n = _display_triangles(m, max_edge)
        tris.append(t)
        cols.append(_shaded(np.broadcast_to(base, (len(t), 3)), n))
    ax.computed_zorder = False  # draw order = zorder: the axes below always come after the meshes
    pc = Poly3DCollection(np.concatenate(tris), facecolors=np.concatenate(cols), edgecolors="none", linewidths=0,
                          zorder=1)
    ax.add_collection3d(pc)
    outline = [patheffects.withStroke(linewidth=4.2, foreground="white")]
    for j in twin.joints:
        o, a = twin.posed_axes(values)[j.name]
        part = meshes[j.child]
        c = part.centroid
        # through the moving part: the revolute axis at the point nearest the part's centroid, the
        # prismatic axis through the centroid; as long as the part along the axis (a door's height, a
        # lid's width), within 12-45 % of the object
        p = o + a * float((c - o) @ a) if j.type == "revolute" else c
        along = float(np.ptp(part.vertices @ a))
        length = float(np.clip(1.3 * along, 0.12 * size, 0.45 * size))
        st = AXIS_STYLE.get(j.type, AXIS_STYLE["revolute"])
        p0 = p - a * length * (0.5 if j.type == "revolute" else 0.0)
        q = ax.quiver(*p0, *(a * length), color=st["color"], linewidth=2.2, arrow_length_ratio=0.22, zorder=10)
        q.set_path_effects(outline)
    ax.set_xlim(*lims[:, 0])
    ax.set_ylim(*lims[:, 1])
    ax.set_zlim(*lims[:, 2])
    ax.set_box_aspect(lims[1] - lims[0], zoom=0.9)
    ax.view_init(elev=view[0], azim=view[1])
    ax.set_axis_off()


def _plural(n: int, word: str) -> str:
    return f"{n} {word}{'' if n == 1 else 's'}"


def _legend_handles(twin: Twin):
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    handles = []
    for i, p in enumerate(twin.parts):
        what = "static" if i == 0 else twin.joint_of_part(i).type
        handles.append(Patch(facecolor=PART_COLORS[i % len(PART_COLORS)], label=f"{p.name} ({what})"))
    for t in sorted({j.type for j in twin.joints}):
        st = AXIS_STYLE.get(t, AXIS_STYLE["revolute"])
        handles.append(Line2D([], [], color=st["color"], linewidth=2.2, label=st["label"]))
    return handles


def show_twin(obj_dir_or_twin: str | Path | Twin, out_png: str | Path, states: list[str] | None = None,
              dpi: int = 90, title: str | None = None, view: tuple[float, float] | None = None) -> Path:
    """Write a contact sheet PNG of the twin in each state to ``out_png``; returns its path.

    ``obj_dir_or_twin``: an object folder (meta.json + twin) or a :class:`Twin`;
    ``states``: state ids to draw (default: all of the object's states; for a bare Twin the
    RS-Art protocol states m0..m3 + single min/max); ``view``: (elevation, azimuth) in degrees
    (default :func:`choose_view`).
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
    view = view if view is not None else choose_view(twin, dict(all_states[0].values))
    ncols = min(4, len(all_states))
    nrows = math.ceil(len(all_states) / ncols)
    handles = _legend_handles(twin)
    leg_cols = min(len(handles), max(2, ncols * 2))
    leg_h = 0.28 * math.ceil(len(handles) / leg_cols) + 0.15  # inches
    title_h = 0.45  # inches for the title, above the panel titles
    height = 3.2 * nrows + title_h + leg_h
    fig = plt.figure(figsize=(3.2 * ncols, height))
    for k, s in enumerate(all_states):
        ax = fig.add_subplot(nrows, ncols, k + 1, projection="3d")
        _draw(ax, twin, s.values, lims, view)
        label = s.id if s.kind == "multi" else f"{s.id} ({s.joint} {s.extreme})"
        ax.set_title(label, fontsize=8, pad=0)
    n_mov = len(twin.parts) - 1
    fig.suptitle(title or f"{name}: {_plural(n_mov, 'movable part')}, {_plural(len(twin.joints), 'joint')}",
                 fontsize=10, y=1 - 0.12 / height, va="top")
    fig.legend(handles=handles, loc="lower center", ncol=leg_cols, fontsize=7, frameon=False,
               bbox_to_anchor=(0.5, 0.02 / height))
    fig.subplots_adjust(left=0, right=1, bottom=leg_h / height, top=1 - title_h / height, wspace=0, hspace=0.08)
    import io

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    plt.close(fig)
    out = Path(out_png)
    atomic_write_bytes(out, buf.getvalue())
    return out
