"""The capture surroundings: RS-Art's green chroma-key booth, or a plain / transparent / random background.

RS-Art objects were captured in a booth with a seamless green curtain and a green-wrapped
0.5 m x 0.5 m pedestal under uniform ambient light. :func:`booth_meshes` builds that booth
around a posed object (world frame, z up, units of the object): a floor disc and an open
cylindrical curtain centred under the object, and a pedestal whose top touches the object's
lowest point. Booth geometry is labelled as background in masks (0) but, like a real
sensor, the depth camera sees it (depth images then contain the booth; masks separate it).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# cv2 and trimesh are imported inside the functions: `rsart render --help` reads BACKGROUNDS from here.

#: Background kinds understood by the renderer.
BACKGROUNDS = ("booth", "plain", "transparent", "random")

CURTAIN_GREEN = (18, 160, 64)
PEDESTAL_GREEN = (26, 150, 58)


@dataclass(frozen=True)
class BoothSpec:
    """Booth dimensions (metres / object units) and colours (sRGB uint8)."""

    pedestal_size: float = 0.5
    pedestal_height: float = 0.7
    curtain_min_radius: float = 2.5
    curtain_colour: tuple[int, int, int] = CURTAIN_GREEN
    pedestal_colour: tuple[int, int, int] = PEDESTAL_GREEN


def booth_meshes(object_bounds: np.ndarray, camera_radius: float, spec: BoothSpec = BoothSpec()) -> list[trimesh.Trimesh]:
    """Curtain, floor and pedestal meshes (world frame, in that order) for an object with (2, 3) ``object_bounds``.

    The pedestal is at least ``pedestal_size`` wide and 10% wider than the object's footprint; its top lies
    0.2% of the object's diagonal below the object's lowest point (about 1 mm: invisible, but it keeps the
    object's bottom and the pedestal from being coincident surfaces);
    the curtain radius is at least 1.6x the camera radius so every camera stays inside it.
    """
    import trimesh

    lo, hi = np.asarray(object_bounds, dtype=np.float64)
    cx, cy = (lo[:2] + hi[:2]) / 2
    foot = float(np.max(hi[:2] - lo[:2]))
    side = max(spec.pedestal_size, 1.1 * foot)
    size = float(np.linalg.norm(hi - lo))
    top = float(lo[2]) - 0.002 * size  # a hair below the object: no coincident surfaces (depth-test ties)
    floor = top - spec.pedestal_height
    radius = max(spec.curtain_min_radius, 1.6 * camera_radius)
    wall_h = (hi[2] - floor) + 2.0 * camera_radius + 1.0

    pedestal = trimesh.creation.box(extents=(side, side, spec.pedestal_height))
    pedestal.apply_translation((cx, cy, floor + spec.pedestal_height / 2))
    pedestal.visual.face_colors = (*spec.pedestal_colour, 255)

    curtain = trimesh.creation.cylinder(radius=radius, height=wall_h, sections=96)
    curtain.apply_translation((cx, cy, floor + wall_h / 2))
    # walls only: the booth is open above (lights), and the floor is a separate square -- the cylinder's
    # bottom cap is a fan of 96 slivers meeting at the centre, which made ray casting ~3x slower
    curtain.update_faces(np.abs(curtain.face_normals[:, 2]) < 0.5)
    curtain.remove_unreferenced_vertices()
    curtain.invert()  # normals face inwards, towards the cameras
    curtain.visual.face_colors = (*spec.curtain_colour, 255)
    r = 1.05 * radius
    floor_sq = trimesh.Trimesh([[cx - r, cy - r, floor], [cx + r, cy - r, floor], [cx + r, cy + r, floor],
                                [cx - r, cy + r, floor]], [[0, 1, 2], [0, 2, 3]], process=False)
    floor_sq.visual.face_colors = (*spec.curtain_colour, 255)
    return [curtain, floor_sq, pedestal]


def random_background(height: int, width: int, rng: np.random.Generator) -> np.ndarray:
    """(H, W, 3) uint8 random background: a smooth random colour field with random stripes and grain."""
    import cv2

    gh, gw = rng.integers(2, 9, size=2)
    grid = rng.uniform(0, 255, size=(gh, gw, 3)).astype(np.float32)
    img = cv2.resize(grid, (width, height), interpolation=cv2.INTER_CUBIC)
    n = int(rng.integers(0, 6))
    for _ in range(n):  # a few random bars, like furniture or posters behind an object
        colour = rng.uniform(0, 255, size=3)
        x0, x1 = np.sort(rng.integers(0, width, size=2))
        y0, y1 = np.sort(rng.integers(0, height, size=2))
        img[y0:y1 + 1, x0:x1 + 1] = 0.5 * img[y0:y1 + 1, x0:x1 + 1] + 0.5 * colour
    img += rng.normal(0, 6, size=img.shape).astype(np.float32)
    return np.clip(img, 0, 255).astype(np.uint8)
