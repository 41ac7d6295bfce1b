"""A labelled Gaussian field posed by its parts' joints, and the photometric losses of such poses.

The reference Gaussians ``ref`` (dict of tensors: means (N, 3), quats (N, 4) wxyz, scales (N, 3)
standard deviations, colors (N, 3), opacities (N,)) are split into parts by ``groups`` (label -> indices
of its Gaussians); each part moves by its :class:`PartJoint` to state k (and by its parent's motion for a
chained joint); everything else stays put. Each part's Gaussians are taken from the part's own reference
state (``PartJoint.ref``, where its joint values are 0): the state in which the part is seen best, since a
trained field places Gaussians well only where some view of that state sees them (a drawer's inside is
hidden while it is closed). :func:`composite_ref` assembles such a ``ref`` from a multi-state field,
:func:`posed_parts` it and its ``groups``. Metres and radians, world frame, OpenCV cameras. Shared by the
articulation fit (:mod:`.articulate`) and part consolidation (:mod:`.consolidate`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from rsart.camera import Camera

from pd2gs.deform import quat_multiply
from pd2gs.render.projection import quat_to_rotmat

from .kinematics import EPS

Views = list[list[tuple[Camera, np.ndarray]]]  # views[k] = [(camera, rgb uint8 (H, W, 3))] of state k


@dataclass
class PartJoint:
    """Learnable parameters of one part's joint (tensors with grad)."""

    label: int
    type: str
    axis: torch.Tensor    # (3,) unnormalised
    pivot: torch.Tensor   # (3,) revolute only (unused for prismatic)
    values: torch.Tensor  # (K,) angle (rad) or slide (m) per state; the reference entry is held at 0
    parent: int | None = None  # label of the part it hangs from (None: the static base)
    ref: int = 0          # index of the state whose Gaussians it moves (its values are 0 there); a chained
                          # joint shares its parent's (its axis and pivot are given in that state's frame)


def composite_ref(stack: dict[str, torch.Tensor], labels: np.ndarray, joints: list["PartJoint"], r: int
                  ) -> dict[str, torch.Tensor]:
    """Reference Gaussians: each joint's Gaussians (``labels == j.label``) from state ``j.ref``, all others
    from state ``r``. ``stack``: means (K, N, 3), quats (K, N, 4), scales (K, N, 3), colors (N, 3),
    opacities (N,)."""
    state = np.full(len(labels), r)
    for j in joints:
        state[np.asarray(labels) == j.label] = j.ref
    k, i = torch.as_tensor(state, dtype=torch.long), torch.arange(len(labels))
    return {"means": stack["means"][k, i], "quats": stack["quats"][k, i], "scales": stack["scales"][k, i],
            "colors": stack["colors"], "opacities": stack["opacities"]}


def posed_parts(stack: dict[str, torch.Tensor], labels: np.ndarray, joints: list["PartJoint"], r: int
                ) -> tuple[dict[str, torch.Tensor], dict[int, torch.Tensor]]:
    """(ref, groups) for the labels (N,) and ``joints``: :func:`composite_ref` and label -> indices of the
    joint's Gaussians, the two inputs every posing function here takes."""
    labels = np.asarray(labels)
    return (composite_ref(stack, labels, joints, r),
            {j.label: torch.as_tensor(np.flatnonzero(labels == j.label), dtype=torch.long) for j in joints})


def joint_motion(j: PartJoint, k: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Joint j's rigid motion to state k: x' = R x + t, and its rotation as a quaternion (4,)."""
    u = j.axis / (j.axis.norm() + EPS)
    v = j.values[k]
    if j.type == "revolute":
        rq = torch.cat([torch.cos(0.5 * v).reshape(1), torch.sin(0.5 * v) * u])
        R = quat_to_rotmat(rq[None])[0]
        return R, j.pivot - R @ j.pivot, rq
    return torch.eye(3), v * u, torch.tensor([1.0, 0.0, 0.0, 0.0])


def world_motions(joints: list[PartJoint], k: int) -> dict[int, tuple[torch.Tensor, torch.Tensor, torch.Tensor]]:
    """label -> world motion (R, t, quat) of each part to state k: its own joint motion, then its parents'.
    A chained joint's axis and pivot are in the reference state's world frame, where every motion is the
    identity, so x' = T_parent(k) T_joint(k) x."""
    by_label = {j.label: j for j in joints}
    out: dict[int, tuple[torch.Tensor, torch.Tensor, torch.Tensor]] = {}

    def world(j: PartJoint, depth: int = 0):
        if j.label not in out:
            R, t, rq = joint_motion(j, k)
            if j.parent in by_label and depth < len(joints):  # depth: a cycle cannot recurse forever
                Rp, tp, qp = world(by_label[j.parent], depth + 1)
                R, t, rq = Rp @ R, Rp @ t + tp, quat_multiply(qp[None], rq[None])[0]
            out[j.label] = (R, t, rq)
        return out[j.label]
    for j in joints:
        world(j)
    return out


def pose(ref: dict[str, torch.Tensor], groups: dict[int, torch.Tensor], joints: list[PartJoint], k: int
         ) -> tuple[torch.Tensor, torch.Tensor]:
    """Means (N, 3) and quats (N, 4) of the reference Gaussians articulated to state k (``groups``: label ->
    indices of its Gaussians; everything else stays put)."""
    means, quats = ref["means"], ref["quats"]
    for label, (R, t, rq) in world_motions(joints, k).items():
        idx = groups[label]
        means = means.index_put((idx,), means[idx] @ R.T + t)
        quats = quats.index_put((idx,), quat_multiply(rq.expand(len(idx), 4), quats[idx]))
    return means, quats


def render_posed(ref, groups, joints, k, cam: Camera, bg, backend: str) -> torch.Tensor:
    """(H, W, 3) render of the field posed to state k in ``cam`` (differentiable in the joints)."""
    from pd2gs.render import rasterize

    f32 = lambda a: torch.as_tensor(np.ascontiguousarray(a), dtype=torch.float32)  # noqa: E731
    means, quats = pose(ref, groups, joints, k)
    return rasterize(means, quats, ref["scales"], ref["colors"], ref["opacities"], f32(cam.K), f32(cam.w2c),
                     cam.width, cam.height, background=bg, backend=backend).rgb


def project(cam: Camera, X: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Integer pixel (u, v) and camera depth z of world points X (n, 3) (OpenCV, pixel centres at integers)."""
    Xc = X @ cam.w2c[:3, :3].T + cam.w2c[:3, 3]
    z = Xc[:, 2]
    uv = (Xc @ np.asarray(cam.K).T)[:, :2] / np.maximum(z, 1e-9)[:, None]
    return np.round(uv[:, 0]).astype(int), np.round(uv[:, 1]).astype(int), z


def footprint_losses(configs: list[tuple[dict[str, torch.Tensor], dict[int, torch.Tensor], list[PartJoint]]],
                     idx: torch.Tensor, views: Views, held: list[tuple[int, int]], bg, backend: str) -> list[float]:
    """Mean |colour error| of each configuration (ref, groups, joints) over the pixels the Gaussians ``idx``
    cover (rendered alone, alpha > 0.3) under any of the configurations, on the held-out views. A
    whole-image loss would hide a small part such as a handle."""
    from pd2gs.render import rasterize

    err, cnt = np.zeros(len(configs)), 0
    with torch.no_grad():
        for k, i in held:
            cam, rgb = views[k][i]
            K, w2c = torch.as_tensor(cam.K, dtype=torch.float32), torch.as_tensor(cam.w2c, dtype=torch.float32)
            gt = torch.as_tensor(rgb, dtype=torch.float32) / 255.0
            outs, mask = [], torch.zeros(cam.height, cam.width, dtype=torch.bool)
            for ref, groups, js in configs:
                means, quats = pose(ref, groups, js, k)
                outs.append(rasterize(means, quats, ref["scales"], ref["colors"], ref["opacities"], K, w2c, cam.width,
                                      cam.height, background=bg, backend=backend).rgb)
                alone = rasterize(means[idx], quats[idx], ref["scales"][idx], ref["colors"][idx],
                                  ref["opacities"][idx], K, w2c, cam.width, cam.height, background=bg, backend=backend)
                mask |= alone.alpha.reshape(cam.height, cam.width) > 0.3
            cnt += int(mask.sum())
            for c, out in enumerate(outs):
                err[c] += float((out - gt).abs().mean(-1)[mask].sum())
    return list(err / max(cnt, 1))


def held_out_loss(ref, groups, joints, views: Views, held: list[tuple[int, int]], bg, backend: str) -> float:
    """Mean L1 colour error of the posed field over the ``held`` (state index, view index) pairs."""
    with torch.no_grad():
        return float(np.mean([(render_posed(ref, groups, joints, k, views[k][i][0], bg, backend)
                               - torch.as_tensor(views[k][i][1], dtype=torch.float32) / 255.0).abs().mean()
                              for k, i in held]))
