"""The one joint/part model of rsart: a kinematic twin and its forward kinematics.

A :class:`Twin` is a tree of rigid parts (part 0 = static base) connected by 1-DoF
joints (:class:`rsart.format.Joint`). Frames: every part mesh is stored at the *rest
configuration* (all joint values 0) in the world (object base) frame; joint ``axis`` and
``origin`` are given in that same frame. Posing applies, for each part, the chain of
joint motions from the base, so chained joints (a lamp arm) compose correctly:

    T_part(q) = T_parent(q) @ M_joint(q_joint),
    M_revolute(θ)  = Trans(o) · Rot(axis, θ) · Trans(-o),
    M_prismatic(d) = Trans(d · axis).

Units: metres (or the object's scene units) and radians.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import trimesh

from .errors import RsartError
from .format import Joint, Part


def rotation_matrix(axis: np.ndarray, angle: float) -> np.ndarray:
    """(3, 3) rotation by ``angle`` radians about the unit ``axis`` (Rodrigues)."""
    a = np.asarray(axis, dtype=np.float64)
    a = a / np.linalg.norm(a)
    Kx = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle) * Kx + (1 - np.cos(angle)) * (Kx @ Kx)


def joint_motion(joint_type: str, axis: np.ndarray, origin: np.ndarray, value: float) -> np.ndarray:
    """(4, 4) world-frame rigid motion of a joint's child at ``value`` (rad or m), relative to its parent."""
    T = np.eye(4)
    axis = np.asarray(axis, dtype=np.float64)
    if joint_type == "revolute":
        R = rotation_matrix(axis, value)
        o = np.asarray(origin, dtype=np.float64)
        T[:3, :3] = R
        T[:3, 3] = o - R @ o
    elif joint_type == "prismatic":
        T[:3, 3] = value * axis / np.linalg.norm(axis)
    else:
        raise RsartError(f"unknown joint type {joint_type!r}")
    return T


@dataclass
class TwinPart:
    """A rigid part of a twin, at the rest configuration in the world frame.

    ``mesh``: the geometry (one trimesh; watertight for generated twins; used for metrics and ray casting).
    ``visuals``: optional textured sub-meshes for RGB rendering (same frame); empty -> render ``mesh``.
    """

    index: int
    name: str
    mesh: trimesh.Trimesh
    visuals: list[trimesh.Trimesh] = field(default_factory=list)
    extra: dict = field(default_factory=dict)

    def render_meshes(self) -> list[trimesh.Trimesh]:
        """The meshes to rasterise for RGB: ``visuals`` if any, else ``[mesh]``."""
        return self.visuals or [self.mesh]


@dataclass
class Twin:
    """An articulated object: parts (index 0 = base) and joints (each movable part is one joint's child)."""

    name: str
    parts: list[TwinPart]
    joints: list[Joint]

    def __post_init__(self) -> None:
        self.check()

    def __repr__(self) -> str:
        js = ", ".join(f"{j.name}:{j.type[0]} {j.parent}->{j.child}" for j in self.joints)
        return f"Twin({self.name!r}, parts={[p.name for p in self.parts]}, joints=[{js}])"

    # --------------------------------------------------------------- structure
    def check(self) -> None:
        """Raise RsartError unless the parts/joints form a tree rooted at part 0."""
        n = len(self.parts)
        if n == 0:
            raise RsartError(f"{self.name}: a twin needs at least one part")
        for i, p in enumerate(self.parts):
            if p.index != i:
                raise RsartError(f"{self.name}: part {p.name!r} has index {p.index}, expected {i}")
        children = {}
        for j in self.joints:
            if not (0 <= j.parent < n and 0 < j.child < n):
                raise RsartError(f"{self.name}: joint {j.name!r} links parts {j.parent}->{j.child} outside 0..{n - 1}")
            if j.child in children:
                raise RsartError(f"{self.name}: part {j.child} is the child of two joints")
            children[j.child] = j
        missing = [p for p in range(1, n) if p not in children]
        if missing:
            raise RsartError(f"{self.name}: parts {missing} have no joint")
        self._joint_of = children
        self._order = self._topological_order()

    def _topological_order(self) -> list[int]:
        order, state = [0], {0: 2}

        def visit(p: int, depth: int = 0) -> None:
            if state.get(p) == 2:
                return
            if state.get(p) == 1 or depth > len(self.parts):
                raise RsartError(f"{self.name}: joint cycle through part {p}")
            state[p] = 1
            visit(self._joint_of[p].parent, depth + 1)
            state[p] = 2
            order.append(p)

        for p in range(1, len(self.parts)):
            visit(p)
        return order

    @property
    def joint_names(self) -> list[str]:
        return [j.name for j in self.joints]

    def joint(self, name: str) -> Joint:
        for j in self.joints:
            if j.name == name:
                return j
        raise KeyError(f"{self.name}: no joint {name!r} (joints: {self.joint_names})")

    def joint_of_part(self, part: int) -> Joint:
        """The joint whose child is ``part`` (part > 0)."""
        return self._joint_of[part]

    def chain(self, part: int) -> list[Joint]:
        """Joints from the base down to ``part`` (base first)."""
        out = []
        while part != 0:
            j = self._joint_of[part]
            out.append(j)
            part = j.parent
        return out[::-1]

    # --------------------------------------------------------------- posing
    def zero_config(self) -> dict[str, float]:
        return {j.name: 0.0 for j in self.joints}

    def pose(self, values: dict[str, float] | None = None) -> dict[int, np.ndarray]:
        """Forward kinematics: part index -> (4, 4) world transform of that part at ``values``.

        ``values`` maps joint names to rad/m; missing joints are at 0; unknown names raise KeyError.
        """
        values = dict(values or {})
        unknown = set(values) - set(self.joint_names)
        if unknown:
            raise KeyError(f"{self.name}: unknown joints {sorted(unknown)} (joints: {self.joint_names})")
        T = {0: np.eye(4)}
        for p in self._order[1:]:
            j = self._joint_of[p]
            T[p] = T[j.parent] @ joint_motion(j.type, j.axis, j.origin, float(values.get(j.name, 0.0)))
        return T

    def posed_visuals(self, values: dict[str, float] | None = None) -> list[list[trimesh.Trimesh]]:
        """Per part, its render meshes (textured visuals, or the geometry) moved to ``values``."""
        T = self.pose(values)
        out = []
        for p in self.parts:
            ms = [m.copy() for m in p.render_meshes()]
            for m in ms:
                m.apply_transform(T[p.index])
            out.append(ms)
        return out

    def posed_meshes(self, values: dict[str, float] | None = None) -> list[trimesh.Trimesh]:
        """Part meshes (copies, textures kept) moved to the configuration ``values``, indexed by part."""
        T = self.pose(values)
        out = []
        for p in self.parts:
            m = p.mesh.copy()
            m.apply_transform(T[p.index])
            out.append(m)
        return out

    def posed_axes(self, values: dict[str, float] | None = None) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Joint name -> (origin (3,), unit axis (3,)) in the world frame at ``values`` (moved with the parent)."""
        T = self.pose(values)
        out = {}
        for j in self.joints:
            Tp = T[j.parent]
            out[j.name] = (Tp[:3, :3] @ j.origin + Tp[:3, 3], Tp[:3, :3] @ j.axis)
        return out

    def whole_mesh(self, values: dict[str, float] | None = None) -> trimesh.Trimesh:
        """All parts concatenated at ``values`` (geometry only)."""
        ms = [trimesh.Trimesh(m.vertices, m.faces, process=False) for m in self.posed_meshes(values)]
        return trimesh.util.concatenate(ms)

    def bounds(self, values: dict[str, float] | None = None) -> np.ndarray:
        """(2, 3) axis-aligned bounds of the posed object."""
        ms = self.posed_meshes(values)
        return np.array([np.min([m.bounds[0] for m in ms], axis=0), np.max([m.bounds[1] for m in ms], axis=0)])

    def clamp(self, values: dict[str, float]) -> dict[str, float]:
        """``values`` clipped into each joint's limits."""
        out = {}
        for k, v in values.items():
            lim = self.joint(k).limits
            out[k] = float(np.clip(v, lim[0], lim[1])) if lim is not None else float(v)
        return out

    def to_parts(self, mesh_dir: str = "twin/parts") -> list[Part]:
        """Format records of the parts (mesh paths relative to the object folder)."""
        return [Part(p.index, p.name, f"{mesh_dir}/{p.name}.ply", dict(p.extra)) for p in self.parts]
