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
from .io import check_inside, read_depth_png, read_mask_png, read_png_rgb


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

    def torch_views(self, states: list[str] | None = None, split: str = "train") -> list[tuple[int, str, "View"]]:
        """(state position, state id, view) of every view of ``states`` (default: captured states) in ``split``.

        Raises RsartError naming what exists when a state is unknown or not captured, or when ``split``
        selects no view of a state (instead of an empty dataset that trains on nothing)."""
        if not states:
            states = self.captured_states
            if not states:
                raise RsartError(f"{self.path}: no state has captured views (states: {', '.join(self.states)}; "
                                 "render some with `rsart render`)")
        views = []
        for k, sid in enumerate(states):
            if sid not in self.states:
                raise RsartError(f"{self.path}: no state {sid!r} (states: {', '.join(self.states)})")
            st = self.states[sid]
            if not st.captured:
                raise RsartError(f"{self.path}: state {sid!r} has no images (captured states: "
                                 f"{', '.join(self.captured_states) or 'none'})")
            sel = st.split(split)
            if not sel:
                have = sorted({v.split for v in st.views})
                raise RsartError(f"{self.path}: state {sid!r} has no {split!r} views (splits: {', '.join(have)})")
            views += [(k, sid, v) for v in sel]
        return views

    def torch_dataset(self, states: list[str] | None = None, split: str = "train", size: tuple[int, int] | None = None,
                      with_depth: bool = True, with_mask: bool = True):
        """A ``torch.utils.data.Dataset`` over the views of ``states`` (default: captured states) in ``split``.

        Items: dict with ``image`` (H, W, 3) float32 in [0, 1], ``depth`` (H, W) float32 m, ``mask`` (H, W)
        int64, ``K`` (3, 3) float32, ``c2w`` (4, 4) float32 (OpenCV), ``state_index`` int64 (position in
        ``states``), ``state_id`` and ``view_id`` strings. ``size`` = (width, height) resamples images and K.
        Raises RsartError for an unknown state, a state without images or a split without views.
        """
        from .torch_data import ViewDataset  # a missing [torch] extra is said first

        return ViewDataset(self.torch_views(states, split), size=size, with_depth=with_depth, with_mask=with_mask)

    def export(self, to: str, out_dir: str | os.PathLike, states: list[str] | None = None,
               overwrite: bool = False) -> list[Path]:
        """Export for training tools: ``to`` = "nerfstudio" | "colmap" | "blender" (see :mod:`rsart.export`)."""
        from .export import export

        return export(self, to, out_dir, states=states, overwrite=overwrite)

    def export_nerfstudio(self, out_dir: str | os.PathLike, states: list[str] | None = None,
                          overwrite: bool = False) -> list[Path]:
        """``<out_dir>/<state>/transforms.json`` per state (nerfstudio); same as ``export("nerfstudio", ...)``."""
        return self.export("nerfstudio", out_dir, states, overwrite)


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

    def torch_dataset(self, objects: list[str] | str | None = None, states: list[str] | None = None,
                      split: str = "train", size: tuple[int, int] | None = None, with_depth: bool = True,
                      with_mask: bool = True):
        """One ``torch.utils.data.Dataset`` over the views of many objects (feed-forward training).

        ``objects``: object ids, or the name of a dataset split (``index.json`` splits), default every
        object. ``states``: state ids taken from each object (default: each object's captured states).
        Items are :meth:`RSArtObject.torch_dataset`'s plus ``object_id`` (str) and ``object_index`` (int64,
        position in the object list). Images of different objects may differ in size: pass ``size`` =
        (width, height) to batch them. Raises RsartError naming what exists for an unknown object or split,
        and for an object without such states or views.
        """
        from .torch_data import ViewDataset

        if objects is None:
            ids = list(self.index.objects)
        elif isinstance(objects, str):
            if objects not in self.index.splits:
                raise RsartError(f"{self.root}: no split {objects!r} (splits: {', '.join(self.index.splits)})")
            ids = list(self.index.splits[objects])
        else:
            ids = list(objects)
        unknown = [i for i in ids if i not in self.index.objects]
        if unknown:
            raise RsartError(f"{self.root}: no object(s) {unknown} (objects: {', '.join(self.index.objects)})")
        views = []
        for n, oid in enumerate(ids):
            views += [(k, sid, v, oid, n) for k, sid, v in self[oid].torch_views(states, split)]
        return ViewDataset(views, size=size, with_depth=with_depth, with_mask=with_mask)

    def __repr__(self) -> str:
        return f"Dataset({self.name!r} v{self.version}, {len(self)} objects, splits={list(self.splits)})"


def load(path: str | os.PathLike, cache: str | os.PathLike | None = None) -> Dataset | RSArtObject:
    """Open a dataset root (folder with ``index.json``) or one object folder (with ``meta.json``).

    Raw sources load too: a PartNet-Mobility object folder (``mobility.urdf``), a ``.urdf`` or a USD
    file is converted once (as ``rsart convert`` does) into the cache folder ``cache`` (default
    ``$RSART_CACHE``, else ``~/.cache/rsart``) and loaded from there; the cache is keyed by the source's
    content, so an edited source is converted again. See :mod:`rsart.sources.cache`.
    """
    path = Path(path)
    if (path / "index.json").is_file():
        return Dataset(path)
    if (path / "meta.json").is_file() and not (path / "mobility.urdf").is_file():
        return RSArtObject(path)
    if path.name == "meta.json" and path.is_file() and not (path.parent / "mobility.urdf").is_file():
        return RSArtObject(path.parent)
    from .sources.cache import cached_object, source_kind

    if source_kind(path) is not None:
        return RSArtObject(cached_object(path, cache))
    if not path.exists():
        raise RsartError(f"{path}: no such file or folder")
    raise RsartError(f"{path}: neither a dataset root (index.json), an object folder (meta.json), a "
                     "PartNet-Mobility folder (mobility.urdf), a .urdf nor a USD file")
