"""Build a :class:`rsart.kinematics.Twin` from solids, materials and joints.

A generator declares parts (each a list of (solid, material) pieces), then joints between
them; :meth:`ObjectBuilder.build` turns each part into

* ``TwinPart.mesh``: the boolean union of its pieces (one watertight trimesh), and
* ``TwinPart.visuals``: one textured trimesh per material, UV-mapped by box projection
  (each face takes the two world axes most parallel to it, normalised by the visual's bounds
  so UVs stay in [0, 1]) with the material's procedural image.

Frames/units: world = object base frame, z up, metres; meshes at the rest configuration.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import trimesh
from trimesh.visual.material import SimpleMaterial
from trimesh.visual.texture import TextureVisuals

from ...errors import RsartError
from ...format import Joint
from ...kinematics import Twin, TwinPart
from . import shapes
from .textures import Material, texture_image

_UV_AXES = {0: (1, 2), 1: (0, 2), 2: (0, 1)}


@dataclass
class PartSpec:
    """A part under construction: ``pieces`` are (solid, material) pairs; ``label`` a semantic tag."""

    name: str
    label: str
    pieces: list[tuple[shapes.Solid, Material]] = field(default_factory=list)


def texture_size(extent: float, metres_per_px: float = 0.003) -> int:
    """Texture resolution (a power of two in [64, 512]) for a visual of ``extent`` metres."""
    px = extent / metres_per_px
    return int(2 ** np.clip(np.round(np.log2(max(px, 1.0))), 6, 9))


def box_uv(mesh: trimesh.Trimesh) -> tuple[trimesh.Trimesh, np.ndarray]:
    """Unmerge ``mesh`` per face and give it box-projected UVs in [0, 1] ((3F, 2), one per corner)."""
    tri = mesh.vertices[mesh.faces]                                   # (F, 3, 3)
    normals = mesh.face_normals
    dom = np.argmax(np.abs(normals), axis=1)
    lo = mesh.bounds[0]
    ext = float(np.max(mesh.extents)) or 1.0
    uv = np.zeros((len(tri), 3, 2))
    for a, (i, j) in _UV_AXES.items():
        sel = dom == a
        uv[sel, :, 0] = (tri[sel, :, i] - lo[i]) / ext
        uv[sel, :, 1] = (tri[sel, :, j] - lo[j]) / ext
    faces = np.arange(3 * len(tri)).reshape(-1, 3)
    return trimesh.Trimesh(tri.reshape(-1, 3), faces, process=False), np.clip(uv.reshape(-1, 2), 0.0, 1.0)


def textured_visual(solid_mesh: trimesh.Trimesh, material: Material, name: str) -> trimesh.Trimesh:
    """A copy of ``solid_mesh`` with box UVs and ``material``'s texture (trimesh TextureVisuals + PIL image)."""
    m, uv = box_uv(solid_mesh)
    img = texture_image(material, texture_size(float(np.max(solid_mesh.extents))))
    mat = SimpleMaterial(image=img, diffuse=(255, 255, 255, 255), ambient=(255, 255, 255, 255),
                         specular=(40, 40, 40, 255), glossiness=10.0, name=name)
    m.visual = TextureVisuals(uv=uv, material=mat)
    m.metadata["name"] = name
    m.metadata["material"] = {"name": material.name, "kind": material.kind, "color": list(material.color)}
    return m


class ObjectBuilder:
    """Collects parts and joints of one procedural object; :meth:`build` returns the Twin."""

    def __init__(self, name: str):
        self.name = name
        self.parts: list[PartSpec] = []
        self.joints: list[Joint] = []

    # ----------------------------------------------------------------- parts
    def part(self, name: str, label: str | None = None) -> int:
        """Declare a part; returns its index (the first part declared is the static base, index 0)."""
        if any(p.name == name for p in self.parts):
            raise RsartError(f"{self.name}: duplicate part name {name!r}")
        self.parts.append(PartSpec(name, label or name.rstrip("_0123456789")))
        return len(self.parts) - 1

    def add(self, part: int, solid: shapes.Solid, material: Material) -> None:
        """Add a solid piece with ``material`` to ``part``."""
        if solid.is_empty():
            raise RsartError(f"{self.name}: empty solid added to part {self.parts[part].name!r}")
        self.parts[part].pieces.append((solid, material))

    # ----------------------------------------------------------------- joints
    def revolute(self, name: str, parent: int, child: int, axis, origin, limits: tuple[float, float]) -> None:
        """Revolute joint about unit ``axis`` through ``origin`` (world, rest), ``limits`` in radians."""
        self._joint(name, "revolute", parent, child, axis, origin, limits)

    def prismatic(self, name: str, parent: int, child: int, axis, limits: tuple[float, float], origin=None) -> None:
        """Prismatic joint along ``axis``, ``limits`` in metres; ``origin`` defaults to the child's bounds centre."""
        if origin is None:
            b = np.array([s.bounding_box() for s, _ in self.parts[child].pieces])   # (k, 6)
            origin = (b[:, :3].min(0) + b[:, 3:].max(0)) / 2
        self._joint(name, "prismatic", parent, child, axis, origin, limits)

    def _joint(self, name, jtype, parent, child, axis, origin, limits) -> None:
        a = np.asarray(axis, dtype=np.float64)
        a = a / np.linalg.norm(a)
        lo, hi = float(limits[0]), float(limits[1])
        if lo > hi:
            raise RsartError(f"{self.name}: joint {name!r} has lower limit {lo} > upper {hi}")
        self.joints.append(Joint(name, jtype, parent, child, np.round(a, 12),
                                 np.round(np.asarray(origin, dtype=np.float64), 9), (round(lo, 9), round(hi, 9))))

    # ----------------------------------------------------------------- build
    def recenter(self) -> None:
        """Translate everything in x, y so the rest-configuration bounds are centred on x = y = 0
        (cameras orbit the origin); z is kept (the base rests on z = 0)."""
        b = np.array([s.bounding_box() for p in self.parts for s, _ in p.pieces])
        c = (b[:, :3].min(0) + b[:, 3:].max(0)) / 2
        shift = np.round(np.array([-c[0], -c[1], 0.0]), 6)
        if not np.any(shift):
            return
        for p in self.parts:
            p.pieces = [(s.translate(tuple(shift)), m) for s, m in p.pieces]
        for j in self.joints:
            j.origin = np.round(j.origin + shift, 9)

    def build(self, recenter: bool = True) -> Twin:
        """Union each part's pieces into a watertight mesh, make textured visuals, and return the Twin."""
        if recenter:
            self.recenter()
        tparts = []
        for i, p in enumerate(self.parts):
            if not p.pieces:
                raise RsartError(f"{self.name}: part {p.name!r} has no geometry")
            mesh = shapes.to_trimesh(shapes.union([s for s, _ in p.pieces]))
            if not mesh.is_watertight:
                raise RsartError(f"{self.name}: part {p.name!r} is not watertight")
            visuals = []
            by_mat: dict[str, tuple[Material, list]] = {}
            for s, m in p.pieces:
                by_mat.setdefault(m.name, (m, []))[1].append(s)
            for k, (m, solids) in enumerate(by_mat.values()):
                vm = shapes.to_trimesh(shapes.union(solids))
                visuals.append(textured_visual(vm, m, f"{p.name}_{m.name}"))
            tparts.append(TwinPart(i, p.name, mesh, visuals, {"label": p.label}))
        return Twin(self.name, tparts, list(self.joints))
