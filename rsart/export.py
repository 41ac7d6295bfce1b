"""Export a captured object to the inputs NeRF / Gaussian-splatting code reads (``rsart export --to``).

Three formats, one folder per exported state (``OUT/<state_id>/``), each self-contained (images are
copied, so the export can be moved or uploaded on its own):

* ``nerfstudio``: ``transforms.json`` with the top-level ``train_filenames`` / ``val_filenames`` /
  ``test_filenames`` lists nerfstudio's dataparser reads (its per-frame ``split`` key is ignored by
  nerfstudio; without the lists it makes its own 90/10 split), ``images/``, ``depth/`` (16-bit PNG,
  ``depth_unit_scale_factor`` metres per unit), ``masks/`` (binary object mask, 255 = object,
  0 = background, written as its own PNG and referenced as ``mask_path``) and ``points3D.ply``
  (``ply_file_path``: back-projected depth, splatfacto's initial points). Poses: OpenGL camera-to-world.
  val = test: nerfstudio evaluates on ``val_filenames`` during training.
* ``colmap``: ``sparse/0/{cameras,images,points3D}.bin`` written with pycolmap's ``Reconstruction``
  (one PINHOLE camera; poses ``cam_from_world`` = rsart's world-to-camera, OpenCV axes as COLMAP uses;
  points from back-projected depth of the training views, coloured by their RGB) and ``images/``. Only
  *training* views are in ``sparse/0`` and ``images/``; the test views are a second model in
  ``test/sparse/0`` with ``test/images/``, so a loader that uses every image of ``sparse/0`` never trains
  on a test view.
* ``blender``: ``transforms_train.json`` / ``transforms_val.json`` (= test) / ``transforms_test.json``
  in the NeRF-synthetic layout: ``camera_angle_x`` (horizontal field of view, radians), frames with
  ``file_path`` *without* extension (readers append ``.png``) and ``transform_matrix`` (OpenGL
  camera-to-world); images are RGBA PNGs whose alpha is the object mask (what ``--white_background``
  style loaders expect). ``fl_x, fl_y, cx, cy, w, h`` are added for readers that use them.

Pixel centres: rsart puts pixel (0, 0)'s centre at (0, 0); nerfstudio, COLMAP and Blender at (0.5, 0.5),
so every exported ``cx, cy`` is rsart's + 0.5. Units are the object's (metres, or PartNet "scene" units);
world frame = the object's base frame. Camera conversions come from :mod:`rsart.camera`.
"""
from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import Callable

import numpy as np

from .camera import corner_origin_intrinsics, horizontal_fov
from .errors import RsartError
from .extras import imported, require
from .io import atomic_dir, check_inside, write_json, write_mask_png, write_png_rgb

FORMATS = ("nerfstudio", "colmap", "blender")
#: at most this many back-projected points per export (evenly subsampled, seeded)
MAX_POINTS = 200_000


def _states(obj, states: list[str] | None) -> list[str]:
    """The states to export: ``states`` (each must exist and be captured) or every captured state."""
    captured = obj.captured_states
    if not states:
        if not captured:
            raise RsartError(f"{obj.path}: no captured state to export (render one with `rsart render`)")
        return captured
    for sid in states:
        if sid not in obj.states:
            raise RsartError(f"{obj.path}: no state {sid!r} (states: {', '.join(obj.states)})")
        if sid not in captured:
            raise RsartError(f"{obj.path}: state {sid!r} has no captured views "
                             f"(captured: {', '.join(captured) or 'none'})")
    return list(states)


def _copy_image(view, kind: str, dst: Path) -> None:
    """Copy a view's ``kind`` PNG byte for byte, after the loader's inside-the-dataset check (no symlink out)."""
    shutil.copyfile(check_inside(view.root or view.state_dir.parent.parent, view.path(kind)), dst)


def _object_mask(view) -> np.ndarray | None:
    """(H, W) bool object mask of a view (part mask > 0), or None if the view has no mask."""
    return view.mask > 0 if view.has_mask else None


def backprojected_points(views, max_points: int = MAX_POINTS, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """World points (N, 3) float64 and colours (N, 3) uint8 from the depth of ``views`` (object pixels only
    where a mask exists; all valid depth otherwise), evenly subsampled to at most ``max_points``."""
    pts, cols = [], []
    for v in views:
        if not v.has_depth:
            continue
        depth = v.depth.copy()
        m = _object_mask(v)
        if m is not None:
            depth[~m] = 0.0
        valid = depth > 0
        pts.append(v.camera.backproject(depth))
        cols.append(v.rgb[valid])
    if not pts:
        return np.zeros((0, 3)), np.zeros((0, 3), np.uint8)
    P, C = np.concatenate(pts), np.concatenate(cols)
    if len(P) > max_points:
        keep = np.sort(np.random.default_rng(seed).choice(len(P), max_points, replace=False))
        P, C = P[keep], C[keep]
    return P, C.astype(np.uint8)


def _write_ply(path: Path, points: np.ndarray, colors: np.ndarray) -> None:
    import trimesh

    from .io import atomic_write_bytes

    pc = trimesh.PointCloud(points, colors=np.hstack([colors, np.full((len(colors), 1), 255, np.uint8)]))
    atomic_write_bytes(path, trimesh.exchange.ply.export_ply(pc, encoding="binary"))


def _intrinsics_px_corner(K) -> dict:
    """fx, fy, cx, cy, w, h with pixel centres at +0.5 (nerfstudio / COLMAP / Blender convention)."""
    fx, fy, cx, cy = corner_origin_intrinsics(K)
    return {"fl_x": fx, "fl_y": fy, "cx": cx, "cy": cy, "w": K.width, "h": K.height}


def _check_splits(st) -> tuple[list, list]:
    train, test = st.split("train"), st.split("test")
    if not train:
        raise RsartError(f"{st.dir}: state {st.id!r} has no training views "
                         f"(splits present: {sorted({v.split for v in st.views})})")
    return train, test


def write_nerfstudio(obj, sid: str, d: Path) -> Path:
    """nerfstudio ``transforms.json`` for state ``sid`` into folder ``d`` (see module docstring)."""
    st = obj.states[sid]
    train, test = _check_splits(st)
    c = st.cameras
    frames, names = [], {"train": [], "test": []}
    for v in train + test:
        fp = f"images/{v.id}.png"
        _copy_image(v, "rgb", d / fp)
        fr = {"file_path": fp, "transform_matrix": v.camera.c2w_opengl().tolist(), "rsart_split": v.split}
        if v.has_depth:
            fr["depth_file_path"] = f"depth/{v.id}.png"
            _copy_image(v, "depth", d / fr["depth_file_path"])
        m = _object_mask(v)
        if m is not None:
            fr["mask_path"] = f"masks/{v.id}.png"
            write_mask_png(d / fr["mask_path"], (m * 255).astype(np.uint8))
        frames.append(fr)
        names["train" if v.split == "train" else "test"].append(fp)
    tf = {"camera_model": "OPENCV", **_intrinsics_px_corner(c.intrinsics),
          "k1": 0.0, "k2": 0.0, "p1": 0.0, "p2": 0.0, "depth_unit_scale_factor": c.depth_scale,
          "train_filenames": names["train"], "val_filenames": names["test"], "test_filenames": names["test"],
          "frames": frames, "rsart": {"object_id": obj.id, "state": sid, "values": st.values,
                                      "units": obj.meta.units}}
    P, C = backprojected_points(train)
    if len(P):
        _write_ply(d / "points3D.ply", P, C)
        tf["ply_file_path"] = "points3D.ply"
    write_json(d / "transforms.json", tf)
    return d / "transforms.json"


def _colmap_model(views, K, folder: Path, points: tuple[np.ndarray, np.ndarray] | None) -> None:
    pycolmap = imported("pycolmap", "capture", "rsart export --to colmap")

    rec = pycolmap.Reconstruction()
    cam = pycolmap.Camera(model="PINHOLE", width=K.width, height=K.height,
                          params=list(corner_origin_intrinsics(K)), camera_id=1)
    rec.add_camera_with_trivial_rig(cam)
    (folder / "images").mkdir(parents=True, exist_ok=True)
    for k, v in enumerate(views, 1):
        name = f"{v.id}.png"
        _copy_image(v, "rgb", folder / "images" / name)
        im = pycolmap.Image(name=name, camera_id=1, image_id=k)
        rec.add_image_with_trivial_frame(im, pycolmap.Rigid3d(v.camera.w2c[:3, :4]))
    if points is not None:
        for p, c in zip(*points):
            rec.add_point3D(p, pycolmap.Track(), c)
    (folder / "sparse" / "0").mkdir(parents=True, exist_ok=True)
    rec.write(str(folder / "sparse" / "0"))


def write_colmap(obj, sid: str, d: Path) -> Path:
    """COLMAP model for state ``sid`` into folder ``d``: ``sparse/0`` + ``images/`` (train views), ``test/``."""
    st = obj.states[sid]
    train, test = _check_splits(st)
    K = st.cameras.intrinsics
    _colmap_model(train, K, d, backprojected_points(train))
    if test:
        _colmap_model(test, K, d / "test", None)
    return d / "sparse" / "0"


def write_blender(obj, sid: str, d: Path) -> Path:
    """Blender / NeRF-synthetic ``transforms_{train,val,test}.json`` for state ``sid`` into folder ``d``."""
    st = obj.states[sid]
    train, test = _check_splits(st)
    K = st.cameras.intrinsics
    head = {"camera_angle_x": horizontal_fov(K), **_intrinsics_px_corner(K),
            "rsart": {"object_id": obj.id, "state": sid, "values": st.values, "units": obj.meta.units}}
    for v in train + test:
        rgb = v.rgb
        m = _object_mask(v)
        alpha = np.full(rgb.shape[:2], 255, np.uint8) if m is None else (m * 255).astype(np.uint8)
        write_png_rgb(d / "images" / f"{v.id}.png", np.dstack([rgb, alpha]))
    for name, views in (("train", train), ("val", test), ("test", test)):
        frames = [{"file_path": f"./images/{v.id}", "transform_matrix": v.camera.c2w_opengl().tolist()}
                  for v in views]
        write_json(d / f"transforms_{name}.json", {**head, "frames": frames})
    return d / "transforms_train.json"


WRITERS: dict[str, Callable] = {"nerfstudio": write_nerfstudio, "colmap": write_colmap, "blender": write_blender}


def export(obj, to: str, out: str | os.PathLike, *, states: list[str] | None = None,
           overwrite: bool = False) -> list[Path]:
    """Export ``obj`` (an :class:`rsart.RSArtObject`) in format ``to`` into ``out/<state_id>/`` per state.

    ``states``: state ids (default: every captured state). ``out`` is built atomically; an existing
    non-empty ``out`` needs ``overwrite``. Returns the main file of each state's export.
    """
    if to not in WRITERS:
        raise RsartError(f"unknown export format {to!r} (formats: {', '.join(FORMATS)})")
    if to == "colmap":  # say so before anything is read or written
        require("capture", "rsart export --to colmap", modules=("pycolmap",))
    sids = _states(obj, states)
    written = []
    with atomic_dir(out, overwrite=overwrite) as tmp:
        for sid in sids:
            d = tmp / sid
            for sub in ("images", "depth", "masks"):
                (d / sub).mkdir(parents=True, exist_ok=True)
            main = WRITERS[to](obj, sid, d)
            for sub in ("depth", "masks"):  # drop folders a format did not use
                if not any((d / sub).iterdir()):
                    (d / sub).rmdir()
            written.append(Path(out) / main.relative_to(tmp))
    return written

