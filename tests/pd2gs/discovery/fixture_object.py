"""A tiny real object folder (base + door + drawer, boxes) with ray-cast views, and a 'perfect' Gaussian
field sampled on its posed part surfaces: discovery end to end without training."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

from pd2gs.discovery.field import StateField
from rsart.camera import Camera, Intrinsics, look_at
from rsart.format import CamerasFile, DatasetIndex, Joint, ViewRecord, write_cameras, write_index
from rsart.io import write_depth_png, write_mask_png, write_png_rgb
from rsart.kinematics import Twin, TwinPart
from rsart.render.raycast import build_scene
from rsart.twin_io import write_object

COLORS = np.array([[0.75, 0.7, 0.6], [0.2, 0.35, 0.8], [0.85, 0.25, 0.2]])


def make_twin() -> Twin:
    base = trimesh.creation.box(extents=[0.40, 0.30, 0.40]); base.apply_translation([0, 0, 0.20])
    door = trimesh.creation.box(extents=[0.012, 0.28, 0.18]); door.apply_translation([0.206, 0, 0.29])
    drawer = trimesh.creation.box(extents=[0.012, 0.28, 0.16]); drawer.apply_translation([0.206, 0, 0.10])
    joints = [Joint("door_hinge", "revolute", 0, 1, np.array([0.0, 0.0, 1.0]), np.array([0.206, -0.14, 0.29]),
                    (0.0, 1.2)),
              Joint("drawer_slide", "prismatic", 0, 2, np.array([1.0, 0.0, 0.0]), np.zeros(3), (0.0, 0.15))]
    parts = [TwinPart(0, "base", base), TwinPart(1, "door", door), TwinPart(2, "drawer", drawer)]
    return Twin("cabinet", parts, joints)


def cameras(n: int, size=(96, 72)) -> list[Camera]:
    intr = Intrinsics(size[0], size[1], 80.0, 80.0, (size[0] - 1) / 2, (size[1] - 1) / 2, None)
    out = []
    for i in range(n):
        az = 2 * np.pi * i / n
        el = 0.35 + 0.35 * (i % 2)
        eye = np.array([0.25, 0.0, 0.2]) + 1.1 * np.array([np.cos(az) * np.cos(el), np.sin(az) * np.cos(el), np.sin(el)])
        out.append(Camera(intr, look_at(eye, np.array([0.1, 0.0, 0.2]))))
    return out


def build_object(root: Path, n_views: int = 12, states=("m0", "m1", "m2", "m3")) -> Path:
    """Write root/index.json + root/cabinet-0000 with rgb/depth/mask for ``states``; -> object folder."""
    twin = make_twin()
    obj_dir = root / "cabinet-0000"
    meta = write_object(twin, obj_dir, object_id="cabinet-0000", category="storage",
                        source={"kind": "procedural", "id": "test"}, write_usd=False)
    render_views(obj_dir, twin, meta, list(states), cameras(n_views))
    write_index(DatasetIndex("disc-test", "1", ["cabinet-0000"], {"test": ["cabinet-0000"]}),
                root / "index.json")
    return obj_dir


def ring_cameras(twin: Twin, n: int, size=(128, 96), focal: float = 100.0) -> list[Camera]:
    """n cameras on a ring around the twin's rest bounds (elevations alternating 20 and 40 degrees)."""
    lo, hi = twin.bounds(twin.zero_config())
    c, r = (lo + hi) / 2, float(np.linalg.norm(hi - lo))
    intr = Intrinsics(size[0], size[1], focal, focal, (size[0] - 1) / 2, (size[1] - 1) / 2, None)
    out = []
    for i in range(n):
        az, el = 2 * np.pi * i / n, 0.35 + 0.35 * (i % 2)
        out.append(Camera(intr, look_at(c + 1.3 * r * np.array([np.cos(az) * np.cos(el), np.sin(az) * np.cos(el),
                                                                  np.sin(el)]), c)))
    return out


def render_views(obj_dir: Path, twin: Twin, meta, states: list[str], cams: list[Camera]) -> None:
    """Ray-cast rgb (flat part colours, shaded), depth and part masks of ``states`` into obj_dir/states."""
    light = np.array([0.4, -0.3, 0.85]); light /= np.linalg.norm(light)
    for sid in states:
        posed = twin.posed_meshes(meta.state(sid).values)
        scene = build_scene([[m] for m in posed])
        sdir = obj_dir / "states" / sid
        views = []
        for i, cam in enumerate(cams):
            hits = scene.cast(cam)
            lab = hits.label
            shade = 0.55 + 0.45 * np.abs(hits.normal @ light)
            rgb = np.full(lab.shape + (3,), 0.1)
            fg = lab >= 0
            rgb[fg] = COLORS[lab[fg] % len(COLORS)] * shade[fg, None]
            vid = f"{i:04d}"
            write_png_rgb(sdir / "rgb" / f"{vid}.png", (rgb * 255).round().astype(np.uint8))
            write_depth_png(sdir / "depth" / f"{vid}.png", hits.object_depth())
            write_mask_png(sdir / "mask" / f"{vid}.png", hits.part_mask())
            views.append(ViewRecord(vid, cam.c2w, "train"))
        write_cameras(CamerasFile(cams[0].intrinsics, 0.001, views), sdir / "cameras.json")


def perfect_field(twin: Twin, meta, states: list[str], n: int = 2500, seed: int = 0, jitter: float = 0.0) -> tuple[StateField, np.ndarray]:
    """Flat Gaussians on the part surfaces (area-weighted), posed per state -> (field, true labels)."""
    rng = np.random.default_rng(seed)
    areas = np.array([p.mesh.area for p in twin.parts])
    counts = np.maximum(50, (n * areas / areas.sum()).astype(int))
    means0, rots0, labels = [], [], []
    for p, c in zip(twin.parts, counts):
        pts, fi = trimesh.sample.sample_surface(p.mesh, int(c), seed=int(rng.integers(1 << 30)))
        nrm = p.mesh.face_normals[fi]
        z = np.array([0.0, 0.0, 1.0])
        rot = np.stack([Rotation.align_vectors(nv[None], z[None])[0].as_matrix() for nv in nrm])
        means0.append(pts); rots0.append(rot); labels.append(np.full(len(pts), p.index))
    means0 = np.concatenate(means0); rots0 = np.concatenate(rots0); labels = np.concatenate(labels)
    spacing = np.sqrt(areas.sum() / len(means0))
    scales = np.tile([0.7 * spacing, 0.7 * spacing, 0.1 * spacing], (len(means0), 1))
    M, Q, S = [], [], []
    for sid in states:
        pose = twin.pose(meta.state(sid).values)
        T = np.stack([pose[int(l)] for l in labels])
        m = np.einsum("nij,nj->ni", T[:, :3, :3], means0) + T[:, :3, 3]
        if jitter:
            m = m + rng.normal(scale=jitter, size=m.shape)
        R = T[:, :3, :3] @ rots0
        q = Rotation.from_matrix(R).as_quat()[:, [3, 0, 1, 2]]
        M.append(m); Q.append(q); S.append(scales)
    colors = COLORS[labels % len(COLORS)]
    return StateField(list(states), np.stack(M), np.stack(Q), np.stack(S), colors, np.full(len(labels), 0.9)), labels
