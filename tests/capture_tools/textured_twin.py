"""A small articulated twin with rich, non-green textures (what SfM needs), built with trimesh.

A lab would capture real, textured objects; the procedural twins' textures are smooth and low-contrast at
320x240, which starves SIFT, so the SfM tests use this twin: a 0.30 x 0.24 x 0.18 m base with a
revolute lid (hinged along the back top edge) and a prismatic drawer, every face carrying a random
colour-blob texture whose hues avoid the booth's green.
"""
from __future__ import annotations

import math

import cv2
import numpy as np
import trimesh
from PIL import Image

from rsart.format import Joint
from rsart.kinematics import Twin, TwinPart

# box faces: (normal axis, sign); each face gets a tile of the texture atlas (3 x 2 tiles)
_FACES = [(0, 1), (0, -1), (1, 1), (1, -1), (2, 1), (2, -1)]


def blob_texture(size: int, rng: np.random.Generator) -> np.ndarray:
    """(size, size, 3) uint8: random discs and bars in colours with hue outside the green band."""
    img = np.full((size, size, 3), 235, np.uint8)
    for _ in range(size // 3):
        hue = int(rng.choice([rng.integers(0, 25), rng.integers(100, 180)]))  # OpenCV hue: skip 25..100 (yellow-green-cyan)
        col = cv2.cvtColor(np.uint8([[[hue, rng.integers(120, 255), rng.integers(40, 230)]]]), cv2.COLOR_HSV2RGB)[0, 0]
        c = tuple(int(x) for x in col)
        x, y = rng.integers(0, size, 2)
        if rng.uniform() < 0.6:
            cv2.circle(img, (int(x), int(y)), int(rng.integers(3, size // 10)), c, -1)
        else:
            w, h = rng.integers(3, size // 6, 2)
            cv2.rectangle(img, (int(x), int(y)), (int(x + w), int(y + h)), c, -1)
    return img


def textured_box(extents, center, rng: np.random.Generator, tile: int = 128) -> tuple[trimesh.Trimesh, trimesh.Trimesh]:
    """(watertight geometry, textured visual) of an axis-aligned box; the visual has 4 own vertices per face."""
    ext, ctr = np.asarray(extents, float), np.asarray(center, float)
    geom = trimesh.creation.box(extents=ext)
    geom.apply_translation(ctr)
    atlas = np.concatenate([np.concatenate([blob_texture(tile, rng) for _ in range(3)], 1) for _ in range(2)], 0)
    verts, uvs, faces = [], [], []
    for k, (ax, sg) in enumerate(_FACES):
        u_ax, v_ax = [a for a in range(3) if a != ax]
        corners = []
        for du, dv in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
            p = np.zeros(3)
            p[ax], p[u_ax], p[v_ax] = sg, du, dv
            corners.append(ctr + p * ext / 2)
        tx, ty = k % 3, k // 3
        uv = [((tx + (du + 1) / 2 * 0.98 + 0.01) / 3, 1 - (ty + (dv + 1) / 2 * 0.98 + 0.01) / 2)
              for du, dv in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
        b = len(verts)
        verts += corners
        uvs += uv
        tri = [(b, b + 1, b + 2), (b, b + 2, b + 3)]
        n = np.cross(corners[1] - corners[0], corners[2] - corners[0])
        if np.dot(n, np.eye(3)[ax] * sg) < 0:
            tri = [(a, c, bb) for a, bb, c in tri]
        faces += tri
    mat = trimesh.visual.material.SimpleMaterial(image=Image.fromarray(atlas))
    vis = trimesh.Trimesh(np.array(verts), np.array(faces), process=False,
                          visual=trimesh.visual.TextureVisuals(uv=np.array(uvs), material=mat))
    return geom, vis


def make_textured_cabinet(seed: int = 0) -> Twin:
    """Base (0.30 x 0.24 x 0.18 m, z from 0), lid (revolute about y at the back top edge, 0..1.2 rad),
    drawer (prismatic along +x, 0..0.12 m)."""
    rng = np.random.default_rng(seed)
    base = textured_box([0.30, 0.24, 0.16], [0, 0, 0.08], rng)
    lid = textured_box([0.30, 0.24, 0.02], [0, 0, 0.171], rng)
    drawer = textured_box([0.03, 0.16, 0.08], [0.166, 0, 0.07], rng)
    parts = [TwinPart(0, "base", base[0], [base[1]]), TwinPart(1, "lid", lid[0], [lid[1]]),
             TwinPart(2, "drawer", drawer[0], [drawer[1]])]
    joints = [Joint("lid_hinge", "revolute", 0, 1, np.array([0.0, -1.0, 0.0]), np.array([-0.15, 0.0, 0.161]),
                    (0.0, 1.2)),
              Joint("drawer_slide", "prismatic", 0, 2, np.array([1.0, 0.0, 0.0]), np.array([0.15, 0.0, 0.07]),
                    (0.0, 0.12))]
    return Twin("textured_cabinet", parts, joints)
