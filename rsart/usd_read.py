"""rsart's USD reader: a UsdPhysics articulation (rsart's layout or a foreign one) -> a Twin.

What is read (see docs/usd.md):

* bodies: prims with ``PhysicsRigidBodyAPI`` plus every prim a joint's ``body0``/``body1`` targets
  (a target inside a rigid body resolves to that body, as PhysX does); a body's geometry is every
  ``Mesh``/``Cube``/``Sphere``/``Cylinder`` below it (instance proxies included, nested bodies
  excluded) under its full authored transform;
* joints: ``PhysicsRevoluteJoint``/``PhysicsPrismaticJoint`` become rsart joints (``body0`` = parent,
  ``body1`` = child), ``PhysicsFixedJoint`` merges two bodies into one part (or anchors the base to
  the world); any other joint type is an error naming its prim;
* rest configuration: a joint's value is 0 when its two frames coincide
  (``body0·local0 == body1·local1``); bodies authored at another joint value are moved back;
* frames/units: stage ``upAxis`` Y is rotated into rsart's Z-up world by +90° about X, lengths are
  scaled by ``metersPerUnit``, revolute limits go from degrees to radians.

Safety: the file and every layer it composes must lie inside the USD file's folder; textures
outside it are skipped with a warning. Every problem is reported as a ValidationError entry whose
path is the prim path.
"""
from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from .checks import is_safe_id, make_safe_id, unique_name
from .errors import Problems, RsartError
from .format import Joint
from .kinematics import Twin, TwinPart
from .usd_geometry import AXIS_VECTORS, Y_UP_TO_Z_UP, body_meshes, custom_attr, matrix_from_quat

_MAX_LAYERS = 256


@dataclass
class _UsdJoint:
    """One parsed UsdPhysics joint; frames are (4, 4) rigid transforms in the stage's world (authored pose)."""

    path: str
    kind: str  # revolute | prismatic | fixed
    name: str
    body0: str | None  # body prim path, None = the world
    body1: str | None
    frame0: np.ndarray
    frame1: np.ndarray
    axis: str
    limits: tuple[float, float] | None  # stage units: degrees (revolute) or stage lengths (prismatic)
    rsart: dict
    sign: float = 1.0  # -1 when re-oriented (body0/body1 swapped): the motion axis is then -axis


# ----------------------------------------------------------------------------- opening
def _fresh_layer(identifier: str):
    """The layer at ``identifier`` as it is on disk now (USD caches open layers per process)."""
    from pxr import Sdf

    layer = Sdf.Layer.Find(identifier)
    if layer is not None and not layer.dirty:
        layer.Reload(True)
        return layer
    return layer if layer is not None else Sdf.Layer.FindOrOpen(identifier)


def _open_stage(path: Path):
    """Open ``path`` after checking that every composed layer lies inside its folder."""
    from pxr import Sdf, Usd

    root = path.parent.resolve()
    layer = _fresh_layer(str(path))
    if layer is None:
        raise RsartError(f"{path}: not a readable USD file")
    seen, todo = {layer.identifier}, [layer]
    while todo:
        lay = todo.pop()
        for dep in lay.GetCompositionAssetDependencies():
            if not dep:  # internal reference (same layer)
                continue
            absdep = lay.ComputeAbsolutePath(dep)
            plain = Path(absdep.split("[", 1)[0]).resolve()
            if plain != root and root not in plain.parents:
                raise RsartError(f"{path}: layer {lay.identifier} refers to {dep!r}, outside {root}; "
                                 "rsart reads only files inside the USD file's folder")
            if absdep not in seen and len(seen) < _MAX_LAYERS and plain.is_file():
                seen.add(absdep)
                sub = _fresh_layer(absdep)
                if sub is not None:
                    todo.append(sub)
    return Usd.Stage.Open(layer, Usd.Stage.LoadAll)


# ----------------------------------------------------------------------------- small helpers
def _mat(gf) -> np.ndarray:
    """(4, 4) column-vector transform from a Gf.Matrix4d (USD uses row vectors)."""
    return np.array(gf, dtype=np.float64).T


def _rigid(T: np.ndarray) -> np.ndarray:
    """The rotation+translation of an affine (4, 4) (scale/shear removed by polar decomposition)."""
    U, _, Vt = np.linalg.svd(T[:3, :3])
    out = np.eye(4)
    out[:3, :3] = U @ Vt
    out[:3, 3] = T[:3, 3]
    return out


def _transform_problem(T: np.ndarray) -> str | None:
    if not np.all(np.isfinite(T)):
        return "non-finite transform (NaN or inf)"
    d = float(np.linalg.det(T[:3, :3]))
    if abs(d) < 1e-12:
        return "degenerate transform (zero scale)"
    if d < 0:
        return "mirrored transform (negative scale) is not supported for bodies or joint frames"
    return None


def _safe_name(name: object, fallback: str) -> str:
    if is_safe_id(name):
        return name
    return make_safe_id(fallback, "part")


def _extra(prim) -> dict:
    """rsart's ``rsart:extra`` JSON dict on ``prim`` ({} when absent, not a dict or malformed)."""
    text = custom_attr(prim, "rsart:extra")
    if not isinstance(text, str) or len(text) > 1_000_000:
        return {}
    try:
        d = json.loads(text, parse_constant=lambda c: None)
    except ValueError:
        return {}
    return d if isinstance(d, dict) else {}


# ----------------------------------------------------------------------------- joints
def _frame(stage, world, target: str | None, pos, rot, jp: str, side: int, pb: Problems) -> np.ndarray | None:
    """World (stage) joint frame on one side: the target prim's transform · (localPos, localRot)."""
    try:
        p = np.array(list(pos) if pos is not None else [0.0, 0.0, 0.0], dtype=np.float64).reshape(3)
        q = (np.array([1.0, 0.0, 0.0, 0.0]) if rot is None
             else np.array([rot.GetReal(), *list(rot.GetImaginary())], dtype=np.float64).reshape(4))
    except (AttributeError, TypeError, ValueError):
        pb.add(jp, f"localPos{side}/localRot{side} are not a point3f and a quatf")
        return None
    if not (np.all(np.isfinite(p)) and np.all(np.isfinite(q))):
        pb.add(jp, f"localPos{side}/localRot{side} contain NaN or inf")
        return None
    if np.linalg.norm(q) < 1e-6:
        pb.add(jp, f"localRot{side} is a zero quaternion (no orientation)")
        return None
    L = np.eye(4)
    L[:3, :3] = matrix_from_quat(*(q / np.linalg.norm(q)))
    if target is None:
        L[:3, 3] = p
        return L
    T = world(target)
    if (msg := _transform_problem(T)) is not None:
        pb.add(target, msg)
        return None
    F = _rigid(T) @ L
    F[:3, 3] = (T @ np.append(p, 1.0))[:3]  # localPos is in the body's (scaled) local space
    return F


def _limits(jt, kind: str, jp: str, pb: Problems) -> tuple[float, float] | None:
    lo_a, hi_a = jt.GetLowerLimitAttr(), jt.GetUpperLimitAttr()
    lo = lo_a.Get() if lo_a and lo_a.HasAuthoredValue() else -math.inf
    hi = hi_a.Get() if hi_a and hi_a.HasAuthoredValue() else math.inf
    try:
        lo, hi = float(lo), float(hi)
    except (TypeError, ValueError):
        pb.add(jp, f"lowerLimit/upperLimit must be numbers, got {lo!r}, {hi!r}")
        return None
    if math.isnan(lo) or math.isnan(hi):
        pb.add(jp, "lowerLimit/upperLimit is NaN")
        return None
    if math.isinf(lo) and math.isinf(hi) and lo < 0 < hi:
        if kind == "prismatic":
            pb.add(jp, "prismatic joint has no finite limits (rsart needs [lower, upper])")
        return None
    if math.isinf(lo) or math.isinf(hi):
        pb.add(jp, f"one-sided or infinite limits [{lo}, {hi}] are not supported (give both or neither)")
        return None
    if lo > hi:
        pb.add(jp, f"lowerLimit {lo} > upperLimit {hi}")
        return None
    return lo, hi


def _parse_joint(stage, prim, kind: str, body_of, world, pb: Problems) -> _UsdJoint | None:
    from pxr import UsdPhysics

    jp = str(prim.GetPath())
    j = UsdPhysics.Joint(prim)
    n0 = len(pb)
    ends: list[str | None] = []
    for side, rel in ((0, j.GetBody0Rel()), (1, j.GetBody1Rel())):
        targets = rel.GetTargets() if rel else []
        if len(targets) > 1:
            pb.add(jp, f"body{side} has {len(targets)} targets; expected one")
        if not targets:
            ends.append(None)
            continue
        t = stage.GetPrimAtPath(targets[0]) if targets[0].IsPrimPath() else None
        if not t or not t.IsValid() or t.IsPseudoRoot():
            pb.add(jp, f"body{side} targets {targets[0]}, which does not exist"
                   if not (t and t.IsPseudoRoot()) else f"body{side} targets the stage root /, not a body")
            ends.append(None)
            continue
        ends.append(str(t.GetPath()))
    if len(pb) > n0:
        return None
    if ends[0] is None and ends[1] is None:
        pb.add(jp, "joint has neither body0 nor body1")
        return None
    b0 = body_of(ends[0]) if ends[0] else None
    b1 = body_of(ends[1]) if ends[1] else None
    if b0 is None and b1 is None:
        pb.add(jp, "joint connects no body (its targets are the world or containers of rigid bodies)")
        return None
    f0 = _frame(stage, world, ends[0], j.GetLocalPos0Attr().Get(), j.GetLocalRot0Attr().Get(), jp, 0, pb)
    f1 = _frame(stage, world, ends[1], j.GetLocalPos1Attr().Get(), j.GetLocalRot1Attr().Get(), jp, 1, pb)
    axis, limits = "X", None
    if kind != "fixed":
        jt = UsdPhysics.RevoluteJoint(prim) if kind == "revolute" else UsdPhysics.PrismaticJoint(prim)
        axis = str(jt.GetAxisAttr().Get())
        if axis not in AXIS_VECTORS:
            pb.add(jp, f"axis {axis!r} is not one of X, Y, Z")
        limits = _limits(jt, kind, jp, pb)
        if b0 is None or b1 is None:
            pb.add(jp, f"{kind} joint connects a body to the world; rsart needs the static base as a body "
                       "(anchor it with a fixed joint) and the joint between two bodies")
    if len(pb) > n0:
        return None
    if b0 is not None and b0 == b1:
        pb.add(jp, f"body0 and body1 are the same body {b0}")
        return None
    rs = {k: custom_attr(prim, f"rsart:{k}") for k in ("name", "axis", "origin", "limits")}
    rs["extra"] = _extra(prim)
    return _UsdJoint(jp, kind, _safe_name(rs["name"], prim.GetName()), b0, b1, f0, f1, axis, limits, rs)


# ----------------------------------------------------------------------------- tree
def _orient(joints: list[_UsdJoint]) -> list[_UsdJoint]:
    """Joints re-oriented away from the one body anchored to the world (body0 = the side nearer to it).

    A joint authored child-first (``body1`` nearer the anchor) is swapped: bodies and frames trade
    places and the axis flips, which keeps its value and limits (frame1 = frame0·M(θ) <=>
    frame0 = frame1·M(-θ) = frame1·M_{-axis}(θ)). Without exactly one anchored body, joints stay as authored.
    """
    anchored = {j.body1 or j.body0 for j in joints if j.body0 is None or j.body1 is None}
    if len(anchored) != 1:
        return joints
    root = anchored.pop()
    adj: dict[str, list[int]] = {}
    for i, j in enumerate(joints):
        if j.body0 is not None and j.body1 is not None:
            adj.setdefault(j.body0, []).append(i)
            adj.setdefault(j.body1, []).append(i)
    out, seen, stack, used = list(joints), {root}, [root], set()
    while stack:
        b = stack.pop()
        for i in adj.get(b, []):
            if i in used:
                continue
            used.add(i)
            j = joints[i]
            other = j.body1 if j.body0 == b else j.body0
            if other in seen:  # a cycle: left as authored, _tree reports it
                continue
            seen.add(other)
            stack.append(other)
            if j.body1 == b:
                out[i] = replace(j, body0=j.body1, body1=j.body0, frame0=j.frame1, frame1=j.frame0, sign=-j.sign)
    return out


def _tree(bodies: list[str], joints: list[_UsdJoint], pb: Problems) -> tuple[str, dict[str, _UsdJoint]]:
    """(root body, body -> the joint whose body1 it is). Problems: two parents, roots != 1, cycles."""
    parent: dict[str, _UsdJoint] = {}
    anchors: dict[str, str] = {}
    for j in joints:
        if j.body0 is None or j.body1 is None:  # fixed joint to the world
            anchors[j.body1 or j.body0] = j.path
            continue
        if j.body1 in parent:
            pb.add(j.path, f"body {j.body1} is already body1 of {parent[j.body1].path}; a part has one parent joint")
            continue
        parent[j.body1] = j
    for b, jp in anchors.items():
        if b in parent:
            pb.add(jp, f"anchors {b} to the world, but {b} is also body1 of {parent[b].path}")
    roots = [b for b in bodies if b not in parent]
    if len(roots) != 1:
        if roots:
            pb.add("/", f"{len(roots)} root bodies {roots}: expected exactly one static base with every other "
                        "body attached to it through joints")
        else:
            pb.add("/", f"no root body: the joints form a cycle through {sorted(parent)}")
        return "", parent
    root = roots[0]
    children: dict[str, list[str]] = {}
    for b, j in parent.items():
        children.setdefault(j.body0, []).append(b)
    reached, stack = {root}, [root]
    while stack:
        for c in children.get(stack.pop(), []):
            if c not in reached:
                reached.add(c)
                stack.append(c)
    lost = [b for b in bodies if b not in reached]
    if lost:
        pb.add(parent[lost[0]].path if lost[0] in parent else "/",
               f"joint cycle: bodies {lost} do not lead back to the root body {root}")
    return root, parent


# ----------------------------------------------------------------------------- main
def _read_stage(stage, path: Path) -> Twin:
    from pxr import Usd, UsdGeom, UsdPhysics

    pb = Problems()
    mpu = float(UsdGeom.GetStageMetersPerUnit(stage))
    up = str(UsdGeom.GetStageUpAxis(stage))
    if not math.isfinite(mpu) or mpu <= 0:
        pb.add("/", f"metersPerUnit {mpu} must be a positive finite number")
    if up not in ("Y", "Z"):
        pb.add("/", f"upAxis {up!r} must be Y or Z")
    pb.raise_if_any(str(path))
    C = np.eye(4)
    C[:3, :3] = mpu * (Y_UP_TO_Z_UP if up == "Y" else np.eye(3))

    xcache = UsdGeom.XformCache(Usd.TimeCode.EarliestTime())  # default value, else the first time sample
    cache: dict[str, np.ndarray] = {}

    def world(p: str) -> np.ndarray:
        if p not in cache:
            cache[p] = _mat(xcache.GetLocalToWorldTransform(stage.GetPrimAtPath(p)))
        return cache[p]

    prims = list(stage.Traverse(Usd.TraverseInstanceProxies()))
    order = {str(p.GetPath()): i for i, p in enumerate(prims)}
    rigid = {str(p.GetPath()) for p in prims if p.HasAPI(UsdPhysics.RigidBodyAPI)}

    def body_of(target: str) -> str | None:
        """The body a joint target stands for: its enclosing rigid body, else the target itself (a static
        body), or None (the world) when the target is a container of rigid bodies (e.g. ``/World``)."""
        prim = stage.GetPrimAtPath(target)
        while prim and not prim.IsPseudoRoot():
            if str(prim.GetPath()) in rigid:
                return str(prim.GetPath())
            prim = prim.GetParent()
        if any(r.startswith(target.rstrip("/") + "/") for r in rigid):
            return None
        return target

    joints: list[_UsdJoint] = []
    for p in prims:
        if not p.IsA(UsdPhysics.Joint):
            continue
        if UsdPhysics.Joint(p).GetJointEnabledAttr().Get() is False:
            continue
        kind = ("revolute" if p.IsA(UsdPhysics.RevoluteJoint) else "prismatic" if p.IsA(UsdPhysics.PrismaticJoint)
                else "fixed" if p.IsA(UsdPhysics.FixedJoint) else None)
        if kind is None:
            pb.add(str(p.GetPath()), f"unsupported joint type {p.GetTypeName() or 'PhysicsJoint'} "
                                     "(rsart twins have revolute, prismatic and fixed joints only)")
            continue
        j = _parse_joint(stage, p, kind, body_of, world, pb)
        if j is not None:
            joints.append(j)
    bodies = set(rigid) | {b for j in joints for b in (j.body0, j.body1) if b}
    bodies_sorted = sorted(bodies, key=lambda b: order.get(b, len(order)))
    if not bodies_sorted:
        pb.add("/", "no rigid bodies (PhysicsRigidBodyAPI) and no joints: not a USD articulation")
    pb.raise_if_any(str(path))
    joints = _orient(joints)
    root, parent = _tree(bodies_sorted, joints, pb)
    pb.raise_if_any(str(path))

    # rest correction per body (stage world): D_child = (D_parent · F0) · F1^-1
    D: dict[str, np.ndarray] = {root: np.eye(4)}
    pending = [b for b in bodies_sorted if b != root]
    while pending:
        nxt = []
        for b in pending:
            j = parent[b]
            if j.body0 in D:
                D[b] = D[j.body0] @ j.frame0 @ np.linalg.inv(j.frame1)
            else:
                nxt.append(b)
        pending = nxt

    # parts: bodies merged through fixed joints; the base part first, then body order
    group = {}
    for b in bodies_sorted:
        g = b
        while g in parent and parent[g].kind == "fixed":
            g = parent[g].body0
        group[b] = g
    tops = [root] + [b for b in bodies_sorted if group[b] == b and b != root]
    index = {g: i for i, g in enumerate(tops)}

    parts: list[TwinPart] = []
    taken: set[str] = set()
    for g in tops:
        members = [b for b in bodies_sorted if group[b] == g]
        mesh, visuals = body_meshes(stage, members, bodies, C, D, world, path.parent.resolve(), pb)
        gprim = stage.GetPrimAtPath(g)
        name = unique_name(_safe_name(custom_attr(gprim, "rsart:name"), gprim.GetName()), taken)
        if mesh is not None:
            parts.append(TwinPart(len(parts), name, mesh, visuals, _extra(gprim)))
    pb.raise_if_any(str(path))

    out_joints, jtaken = [], set()
    for j in joints:
        if j.kind == "fixed":
            continue
        F0 = C @ D[j.body0] @ j.frame0
        axis = F0[:3, :3] @ (j.sign * AXIS_VECTORS[j.axis])
        axis = axis / np.linalg.norm(axis)
        origin = F0[:3, 3].copy()
        limits = j.limits
        if limits is not None:
            limits = ((math.radians(limits[0]), math.radians(limits[1])) if j.kind == "revolute"
                      else (limits[0] * mpu, limits[1] * mpu))
        axis, origin, limits = _rsart_exact(j.rsart, axis, origin, limits)
        out_joints.append(Joint(unique_name(j.name, jtaken), j.kind, index[group[j.body0]], index[group[j.body1]],
                                axis, origin, limits, dict(j.rsart.get("extra") or {})))
    layer_data = stage.GetRootLayer().customLayerData
    dp = stage.GetDefaultPrim()
    name = layer_data.get("rsart:twinName") if isinstance(layer_data.get("rsart:twinName"), str) else None
    name = name or (dp.GetName() if dp else path.stem)
    try:
        return Twin(name, parts, out_joints)
    except RsartError as e:
        raise RsartError(f"{path}: {e}") from None


def _rsart_exact(rs: dict, axis: np.ndarray, origin: np.ndarray, limits):
    """Prefer rsart's double-precision copies (``rsart:axis/origin/limits``) when they agree with UsdPhysics's."""
    try:
        a = np.array(list(rs["axis"]), dtype=np.float64) if rs.get("axis") is not None else None
        o = np.array(list(rs["origin"]), dtype=np.float64) if rs.get("origin") is not None else None
        lim = tuple(float(x) for x in rs["limits"]) if rs.get("limits") is not None else None
    except (TypeError, ValueError):
        return axis, origin, limits
    if a is not None and a.shape == (3,) and np.all(np.isfinite(a)) and np.linalg.norm(a) > 0:
        a = a / np.linalg.norm(a)
        if np.dot(a, axis) > math.cos(1e-4):
            axis = a
    if o is not None and o.shape == (3,) and np.all(np.isfinite(o)):
        d = o - origin
        off = np.linalg.norm(d - np.dot(d, axis) * axis)
        if off < 1e-5 * (1.0 + np.linalg.norm(origin)):
            origin = o
    if limits is not None and lim is not None and len(lim) == 2 and all(map(math.isfinite, lim)):
        if all(abs(x - y) <= 1e-4 * max(1.0, abs(y)) for x, y in zip(lim, limits)):
            limits = lim
    return axis, origin, limits


def read_usd_units(path: str | Path) -> str:
    """The twin's unit label: "scene" when rsart wrote it from a unitless twin
    (``customLayerData["rsart:units"]``), else "m" (read_usd always converts lengths to metres)."""
    from pxr import Tf

    try:
        layer = _fresh_layer(str(path))
    except Tf.ErrorException as e:
        raise RsartError(f"{path}: not a readable USD file: {_tf_message(e)}") from None
    if layer is None:
        raise RsartError(f"{path}: not a readable USD file")
    return "scene" if layer.customLayerData.get("rsart:units") == "scene" else "m"


def _tf_message(e: Exception) -> str:
    """The human part of a Tf error (drops the C++ function/file prefix), at most 300 characters."""
    text = " ".join(str(e).split())
    m = re.search(r" : '(.*?)'(?= Error in |$)", text)  # the first error's message
    return (m.group(1) if m else text)[:300]


def read_usd(path: str | Path) -> Twin:
    """See :func:`rsart.usd.read_usd`."""
    from pxr import Tf

    path = Path(path)
    if not path.is_file():
        raise RsartError(f"{path}: file not found" if not path.exists() else f"{path}: not a file")
    try:
        stage = _open_stage(path)
    except Tf.ErrorException as e:
        raise RsartError(f"{path}: not a readable USD file: {_tf_message(e)}") from None
    try:
        return _read_stage(stage, path)
    except RsartError:
        raise
    except Tf.ErrorException as e:
        raise RsartError(f"{path}: USD error while reading the articulation: {_tf_message(e)}") from None
    except Exception as e:  # hostile input must never surface as a traceback
        raise RsartError(f"{path}: cannot read the USD articulation ({type(e).__name__}: {e})") from None



def read_usd_object_info(path: str | Path) -> dict:
    """object_id / category / units / source rsart stored in ``customLayerData["rsart:object"]`` ({} if none)."""
    from pxr import Tf

    from .urdf import parse_object_info

    try:
        layer = _fresh_layer(str(path))
    except Tf.ErrorException:
        return {}
    return parse_object_info(layer.customLayerData.get("rsart:object")) if layer is not None else {}
