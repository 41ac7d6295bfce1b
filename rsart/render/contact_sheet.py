"""Contact sheets of rendered captures: per state, views as RGB | depth (colour-mapped) | part mask,
with the joint axes projected into the RGB (revolute: red line through the axis, prismatic: yellow
arrow along it, both drawn at the joint's pose in that state), and a legend strip at the bottom naming
each part's mask colour and the axis styles."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from ..camera import Camera
from ..errors import RsartError
from ..format import read_cameras, read_meta
from ..io import read_depth_png, read_mask_png, read_png_rgb, write_png_rgb

#: Mask colours (RGB) for part index + 1 = 1, 2, ...; background stays black.
PALETTE = np.array([[0, 0, 0], [230, 159, 0], [86, 180, 233], [0, 158, 115], [240, 228, 66], [0, 114, 178],
                    [213, 94, 0], [204, 121, 167], [153, 153, 153], [255, 255, 255]], dtype=np.uint8)


def colour_mask(mask: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 colours of an (H, W) part mask."""
    idx = np.where(mask == 0, 0, (mask.astype(np.int64) - 1) % (len(PALETTE) - 1) + 1)
    return PALETTE[idx]


def colour_depth(depth: np.ndarray, lo: float | None = None, hi: float | None = None) -> np.ndarray:
    """(H, W, 3) uint8 turbo colour map of depth (near = red... far = blue); invalid (0) pixels black."""
    valid = depth > 0
    if not valid.any():
        return np.zeros(depth.shape + (3,), np.uint8)
    lo = float(np.percentile(depth[valid], 1)) if lo is None else lo
    hi = float(np.percentile(depth[valid], 99)) if hi is None else hi
    x = np.clip((depth - lo) / max(hi - lo, 1e-9), 0, 1)
    img = cv2.applyColorMap((255 - x * 255).astype(np.uint8), cv2.COLORMAP_TURBO)[..., ::-1]
    img[~valid] = 0
    return np.ascontiguousarray(img)


def draw_axes(rgb: np.ndarray, camera: Camera, axes: dict[str, tuple[np.ndarray, np.ndarray, str]],
              length: float) -> np.ndarray:
    """Draw joint axes (name -> (origin (3,), unit axis (3,), type)) of ``length`` world units into ``rgb``:
    a revolute axis as a line centred on its pivot, named beside the pivot (its ends can lie near other
    joints); a prismatic axis as an arrow from its origin, named at the tip."""
    img = np.ascontiguousarray(rgb[..., :3]).copy()
    thick = max(1, img.shape[1] // 240)
    for name, (o, a, kind) in axes.items():
        pts = np.array([o - 0.5 * length * a, o + 0.5 * length * a]) if kind == "revolute" else np.array([o, o + length * a])
        uv, z = camera.project(pts)
        if np.any(z <= 1e-6) or not np.all(np.isfinite(uv)):
            continue
        p0, p1 = (tuple(int(round(c)) for c in p) for p in uv)
        if kind == "revolute":
            cv2.line(img, p0, p1, (255, 40, 40), thick, cv2.LINE_AA)
        else:
            cv2.arrowedLine(img, p0, p1, (255, 230, 0), thick, cv2.LINE_AA, tipLength=0.15)
        at = tuple(int(round(c)) for c in camera.project(o[None])[0][0]) if kind == "revolute" else p1
        cv2.putText(img, name, (at[0] + 4, at[1] - 3), cv2.FONT_HERSHEY_SIMPLEX, 0.25 * thick, (255, 255, 255),
                    max(1, thick // 2), cv2.LINE_AA)
    return img


def legend_strip(part_names: list[str], width: int, joint_types: set[str] = frozenset()) -> np.ndarray:
    """(H, width, 3) uint8 strip naming the mask colour of every part (``part_names`` in part-index order,
    colours as :func:`colour_mask` gives mask value index + 1) and the axis styles drawn in the RGB tiles."""
    entries = [(tuple(int(c) for c in PALETTE[i % (len(PALETTE) - 1) + 1]), f"mask {i + 1}: {n}", "box")
               for i, n in enumerate(part_names)]
    if "revolute" in joint_types:
        entries.append(((255, 40, 40), "revolute axis", "line"))
    if "prismatic" in joint_types:
        entries.append(((255, 230, 0), "prismatic axis", "arrow"))
    font, scale, pad, row_h = cv2.FONT_HERSHEY_SIMPLEX, 0.45, 10, 22
    rows: list[list[tuple]] = [[]]
    x = pad
    for colour, text, kind in entries:
        w = 22 + cv2.getTextSize(text, font, scale, 1)[0][0] + 2 * pad
        if x + w > width and rows[-1]:
            rows.append([])
            x = pad
        rows[-1].append((x, colour, text, kind))
        x += w
    img = np.full((row_h * len(rows) + 6, width, 3), 30, np.uint8)
    for r, row in enumerate(rows):
        y = 4 + r * row_h
        for x0, colour, text, kind in row:
            if kind == "box":
                cv2.rectangle(img, (x0, y + 3), (x0 + 16, y + 17), colour, -1)
            elif kind == "line":
                cv2.line(img, (x0, y + 10), (x0 + 16, y + 10), colour, 2, cv2.LINE_AA)
            else:
                cv2.arrowedLine(img, (x0, y + 10), (x0 + 16, y + 10), colour, 2, cv2.LINE_AA, tipLength=0.4)
            cv2.putText(img, text, (x0 + 22, y + 15), font, scale, (235, 235, 235), 1, cv2.LINE_AA)
    return img


def _label(tile: np.ndarray, text: str) -> np.ndarray:
    out = tile.copy()
    cv2.rectangle(out, (0, 0), (8 + 9 * len(text), 20), (0, 0, 0), -1)
    cv2.putText(out, text, (4, 15), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
    return out


def render_sheet(obj_dir: str | Path, out_png: str | Path, views_per_state: int = 2, tile_width: int = 320,
                 states: list[str] | None = None) -> Path:
    """Write a contact sheet of the rendered states of ``obj_dir`` to ``out_png``; returns its path.

    One row per state (``states`` or every rendered state in meta.json order), ``views_per_state``
    views spread over the state's views, each as RGB (with joint axes) | depth | mask tiles.
    """
    from ..twin_io import read_twin

    obj_dir = Path(obj_dir)
    meta = read_meta(obj_dir)
    sids = [s.id for s in meta.states if (obj_dir / "states" / s.id / "cameras.json").is_file()]
    if states is not None:
        missing = [s for s in states if s not in sids]
        if missing:
            raise RsartError(f"{obj_dir}: states {missing} were not rendered (rendered: {sids})")
        sids = list(states)
    if not sids:
        raise RsartError(f"{obj_dir}: no rendered states (states/<id>/cameras.json)")
    twin = read_twin(obj_dir, meta, visuals=False)
    lo, hi = twin.bounds()
    length = 0.5 * float(np.linalg.norm(hi - lo))
    kinds = {j.name: j.type for j in meta.joints}
    rows = []
    for sid in sids:
        sdir = obj_dir / "states" / sid
        cams = read_cameras(sdir / "cameras.json")
        n = len(cams.views)
        pick = sorted(set(np.linspace(0, n - 1, min(views_per_state, n)).round().astype(int)))
        axes = {k: (o, a, kinds[k]) for k, (o, a) in twin.posed_axes(meta.state(sid).values).items()}
        tiles = []
        for i in pick:
            v = cams.views[i]
            rgb = read_png_rgb(sdir / "rgb" / f"{v.id}.png")
            depth = read_depth_png(sdir / "depth" / f"{v.id}.png", cams.depth_scale)
            mask = read_mask_png(sdir / "mask" / f"{v.id}.png")
            rgb = draw_axes(rgb, cams.camera(i), axes, length)
            obj = depth[(mask > 0) & (depth > 0)]  # colour range of the object's own depth
            lo_d, hi_d = (float(np.percentile(obj, 1)), float(np.percentile(obj, 99))) if obj.size else (None, None)
            row = [_label(rgb, f"{sid} {v.id} {v.split}"), colour_depth(depth, lo_d, hi_d), colour_mask(mask)]
            tiles.extend(row)
        h = int(round(tile_width * rgb.shape[0] / rgb.shape[1]))
        tiles = [cv2.resize(t, (tile_width, h), interpolation=cv2.INTER_AREA) for t in tiles]
        rows.append(np.concatenate(tiles, axis=1))
    width = max(r.shape[1] for r in rows)
    rows = [np.pad(r, ((0, 2), (0, width - r.shape[1]), (0, 0))) for r in rows]
    rows.append(legend_strip([p.name for p in meta.parts], width, set(kinds.values())))
    out = Path(out_png)
    write_png_rgb(out, np.concatenate(rows, axis=0))
    return out
