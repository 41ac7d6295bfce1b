"""``rsart.load()``: explore an RS-Art dataset or object interactively; feed it to training code.

    >>> ds = rsart.load("data/rsart-synth")            # a dataset root (index.json)
    >>> obj = ds["drawer-0003"]                          # or rsart.load("data/rsart-synth/drawer-0003")
    >>> v = obj.states["m0"].views[3]
    >>> v.rgb.shape, v.depth.dtype, v.mask.max(), v.camera.K

Everything is lazy and cached: loading reads only ``meta.json``; a state's ``cameras.json`` is
read on first access to its views, and an image is decoded on first access to ``.rgb`` /
``.depth`` / ``.mask``. Shapes/units: rgb (H, W, 3) uint8; depth (H, W) float32 metres
(0 = no measurement); mask (H, W) uint8 part index + 1 (0 = background); camera c2w OpenCV.

Untrusted folders: every file read (index.json, meta.json, cameras.json, images) must stay inside the
root the user opened (the dataset root, or the object folder given to ``load``) after following
symlinks; one that leads out is refused by :func:`rsart.io.check_inside` before it is opened. Symlinks
that stay inside the root are allowed. Every decoded image must be its camera's width x height; the
error names the file.
"""
from __future__ import annotations

import os
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from .camera import Camera
from .errors import RsartError
from .format import CamerasFile, DatasetIndex, ObjectMeta, State, read_cameras, read_index, read_meta
from .io import check_inside, read_depth_png, read_mask_png, read_png_rgb, write_json


@dataclass
class View:
    """One captured view: images decoded lazily from ``<state>/{rgb,depth,mask}/<id>.png``."""

    id: str
    split: str
    camera: Camera
    state_dir: Path
    depth_scale: float = 0.001
    extra: dict[str, Any] = field(default_factory=dict)
    root: Path | None = None  # files must stay inside it (default: the object folder, two levels up)

    def path(self, kind: str) -> Path:
        """Path of this view's ``kind`` image ("rgb" | "depth" | "mask")."""
        return self.state_dir / kind / f"{self.id}.png"

    def _decode(self, kind: str, reader) -> np.ndarray:
        """Decode ``kind`` after the inside-the-root check; refuse an image not of its camera's size."""
        path = check_inside(self.root or self.state_dir.parent.parent, self.path(kind))
        img = reader(path)
        h, w = img.shape[:2]
        cw, ch = self.camera.width, self.camera.height
        if (w, h) != (cw, ch):
            raise RsartError(f"{path}: {kind} image is {w}x{h} pixels but its camera (cameras.json, view "
                             f"{self.id!r}) is {cw}x{ch}")
        return img

    @cached_property
    def rgb(self) -> np.ndarray:
        """(H, W, 3) uint8 RGB."""
        return self._decode("rgb", read_png_rgb)

    @cached_property
    def depth(self) -> np.ndarray:
        """(H, W) float32 z-depth in metres, 0 = no measurement."""
        return self._decode("depth", lambda p: read_depth_png(p, self.depth_scale))

    @cached_property
    def mask(self) -> np.ndarray:
        """(H, W) uint8 part index + 1, 0 = background."""
        return self._decode("mask", read_mask_png)

    @property
    def has_depth(self) -> bool:
        return self.path("depth").is_file()

    @property
    def has_mask(self) -> bool:
        return self.path("mask").is_file()

    def __repr__(self) -> str:
        return f"View({self.id!r}, split={self.split!r}, {self.camera.width}x{self.camera.height})"


class StateCapture:
    """An interaction state: its joint ``values`` and (if rendered/captured) its ``views``."""

    def __init__(self, state: State, state_dir: Path, root: Path | None = None):
        self.state = state
        self.dir = state_dir
        self.root = root or state_dir.parent.parent  # nothing outside it is read

    id = property(lambda self: self.state.id)
    kind = property(lambda self: self.state.kind)
    values = property(lambda self: dict(self.state.values))

    @property
    def captured(self) -> bool:
        return (self.dir / "cameras.json").is_file()

    @cached_property
    def cameras(self) -> CamerasFile:
        if not self.captured:
            raise RsartError(f"{self.dir}: state {self.id!r} has no captured views (no cameras.json)")
        return read_cameras(check_inside(self.root, self.dir / "cameras.json"))

    @cached_property
    def views(self) -> list[View]:
        """All views (empty if the state was not captured)."""
        if not self.captured:
            return []
        c = self.cameras
        return [View(v.id, v.split, Camera(c.intrinsics, v.c2w), self.dir, c.depth_scale, v.extra, self.root)
                for v in c.views]

    def split(self, name: str) -> list[View]:
        """Views of split ``name`` ("train" | "test")."""
        return [v for v in self.views if v.split == name]

    def view(self, view_id: str) -> View:
        for v in self.views:
            if v.id == view_id:
                return v
        raise KeyError(f"state {self.id!r}: no view {view_id!r}")

    def __repr__(self) -> str:
        n = len(self.views) if self.captured else 0
        return f"StateCapture({self.id!r}, kind={self.kind!r}, views={n})"


class RSArtObject:
    """One object folder: ``meta``, ``parts``, ``joints``, ``states`` (by id), ``twin`` (lazy).

    ``root``: the folder nothing may be read outside of (default: the object folder itself)."""

    def __init__(self, path: str | os.PathLike, meta: ObjectMeta | None = None, root: str | os.PathLike | None = None):
        self.path = Path(path)
        self.root = Path(root) if root is not None else self.path
        self.meta = meta or read_meta(check_inside(self.root, self.path / "meta.json"))
        self.states: Mapping[str, StateCapture] = {
            s.id: StateCapture(s, self.path / "states" / s.id, self.root) for s in self.meta.states}

    id = property(lambda self: self.meta.object_id)
    category = property(lambda self: self.meta.category)
    parts = property(lambda self: self.meta.parts)
    joints = property(lambda self: self.meta.joints)

    @cached_property
    def twin(self):
        """The kinematic twin (:class:`rsart.kinematics.Twin`), read on first access."""
        from .twin_io import read_twin

        return read_twin(self.path, self.meta)

    @property
    def captured_states(self) -> list[str]:
        return [sid for sid, s in self.states.items() if s.captured]

    def __repr__(self) -> str:
        return (f"RSArtObject({self.id!r}, category={self.category!r}, parts={len(self.parts)}, "
                f"joints={len(self.joints)}, states={list(self.states)})")

    def torch_dataset(self, states: list[str] | None = None, split: str = "train", size: tuple[int, int] | None = None,
                      with_depth: bool = True, with_mask: bool = True):
        """A ``torch.utils.data.Dataset`` over the views of ``states`` (default: captured states) in ``split``.

        Items: dict with ``image`` (H, W, 3) float32 in [0, 1], ``depth`` (H, W) float32 m, ``mask`` (H, W)
        int64, ``K`` (3, 3) float32, ``c2w`` (4, 4) float32 (OpenCV), ``state_index`` int64 (position in
        ``states``), ``state_id`` and ``view_id`` strings. ``size`` = (width, height) resamples images and K.
        """
        from .torch_data import ViewDataset

        states = states or self.captured_states
        views = []
        for k, sid in enumerate(states):
            if sid not in self.states:
                raise KeyError(f"{self.id}: no state {sid!r} (states: {list(self.states)})")
            views += [(k, sid, v) for v in self.states[sid].split(split)]
        return ViewDataset(views, size=size, with_depth=with_depth, with_mask=with_mask)

    def export_nerfstudio(self, out_dir: str | os.PathLike, states: list[str] | None = None) -> list[Path]:
        """Write ``<out_dir>/<state>/transforms.json`` per captured state (nerfstudio's format).

        Poses are converted to OpenGL camera-to-world; ``cx, cy`` are shifted by +0.5 because nerfstudio puts
        pixel centres at (i + 0.5). Image paths point (relatively) at this object's files; nothing is copied.
        """
        out_dir = Path(out_dir)
        written = []
        for sid in states or self.captured_states:
            st = self.states[sid]
            c = st.cameras
            sdir = out_dir / sid
            sdir.mkdir(parents=True, exist_ok=True)
            K = c.intrinsics
            frames = []
            for v in st.views:
                rel = lambda kind: os.path.relpath(v.path(kind), sdir)  # noqa: E731
                fr = {"file_path": rel("rgb"), "transform_matrix": v.camera.c2w_opengl().tolist(), "split": v.split}
                if v.has_depth:
                    fr["depth_file_path"] = rel("depth")
                if v.has_mask:
                    fr["mask_path"] = rel("mask")
                frames.append(fr)
            tf = {"camera_model": "OPENCV", "fl_x": K.fx, "fl_y": K.fy, "cx": K.cx + 0.5, "cy": K.cy + 0.5,
                  "w": K.width, "h": K.height, "k1": 0.0, "k2": 0.0, "p1": 0.0, "p2": 0.0,
                  "depth_unit_scale_factor": c.depth_scale, "frames": frames,
                  "rsart": {"object_id": self.id, "state": sid, "values": st.values}}
            write_json(sdir / "transforms.json", tf)
            written.append(sdir / "transforms.json")
        return written


class Dataset(Mapping[str, RSArtObject]):
    """A dataset root (``index.json``): a mapping object id -> :class:`RSArtObject` (each loaded on first access)."""

    def __init__(self, root: str | os.PathLike):
        self.root = Path(root)
        self.index: DatasetIndex = read_index(check_inside(self.root, self.root / "index.json"))
        self._cache: dict[str, RSArtObject] = {}

    name = property(lambda self: self.index.name)
    version = property(lambda self: self.index.version)
    splits = property(lambda self: self.index.splits)

    def __getitem__(self, object_id: str) -> RSArtObject:
        if object_id not in self.index.objects:
            raise KeyError(f"{self.root}: no object {object_id!r}")
        if object_id not in self._cache:
            self._cache[object_id] = RSArtObject(check_inside(self.root, self.root / object_id), root=self.root)
        return self._cache[object_id]

    def __iter__(self) -> Iterator[str]:
        return iter(self.index.objects)

    def __len__(self) -> int:
        return len(self.index.objects)

    def split(self, name: str) -> list[RSArtObject]:
        """Objects of split ``name``."""
        if name not in self.index.splits:
            raise KeyError(f"{self.root}: no split {name!r} (splits: {list(self.index.splits)})")
        return [self[i] for i in self.index.splits[name]]

    def __repr__(self) -> str:
        return f"Dataset({self.name!r} v{self.version}, {len(self)} objects, splits={list(self.splits)})"


def load(path: str | os.PathLike) -> Dataset | RSArtObject:
    """Open a dataset root (folder with ``index.json``) or one object folder (with ``meta.json``)."""
    path = Path(path)
    if (path / "index.json").is_file():
        return Dataset(path)
    if (path / "meta.json").is_file():
        return RSArtObject(path)
    if path.name == "meta.json" and path.is_file():
        return RSArtObject(path.parent)
    raise RsartError(f"{path}: neither a dataset root (index.json) nor an object folder (meta.json)")
