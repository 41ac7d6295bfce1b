"""Camera paths around an object, the way RS-Art was captured (world frame z up, OpenCV cameras).

* :func:`fit_radius`: the distance at which the object's bounding sphere fills ``fill`` of the
  smaller half field of view.
* :func:`circular_path`: one hand-held circle per interaction state: elevation drawn in
  [30°, 60°], evenly spaced azimuths, and hand-held jitter (azimuth spacing, height/elevation,
  radius, small roll and pitch/yaw of the look-at point).
* :func:`random_views`: wide-baseline views, azimuth uniform and elevation uniform in the range.
* :func:`fixed_test_views`: test views that depend only on the object (identical in every state),
  so novel-view metrics compare like with like across states.

All functions return (N, 4, 4) camera-to-world matrices (OpenCV axes).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..camera import Intrinsics, look_at
from ..kinematics import rotation_matrix


@dataclass(frozen=True)
class PathSpec:
    """Parameters of the capture paths (angles in radians, lengths relative to the radius)."""

    elevation_range: tuple[float, float] = (math.radians(30), math.radians(60))
    fill: float = 0.9
    jitter_elevation: float = math.radians(2.0)
    jitter_radius: float = 0.03
    jitter_roll: float = math.radians(2.0)
    jitter_target: float = 0.03
    jitter_azimuth: float = 0.25


def bounding_sphere(bounds: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre (3,) and radius of the sphere around (2, 3) axis-aligned ``bounds``."""
    lo, hi = np.asarray(bounds, dtype=np.float64)
    return (lo + hi) / 2, float(np.linalg.norm(hi - lo) / 2)


def fit_radius(bounds: np.ndarray, intrinsics: Intrinsics, fill: float = 0.9) -> float:
    """Camera distance at which the bounding sphere of ``bounds`` spans ``fill`` of the smaller half-FOV.

    The sphere's angular radius asin(r / d) is set to atan(fill · tan(half_fov)).
    """
    _, r = bounding_sphere(bounds)
    half = min(math.atan(intrinsics.width / 2 / intrinsics.fx), math.atan(intrinsics.height / 2 / intrinsics.fy))
    ang = math.atan(fill * math.tan(half))
    return max(r, 1e-6) / math.sin(ang)


def orbit_pose(target: np.ndarray, radius: float, azimuth: float, elevation: float, roll: float = 0.0) -> np.ndarray:
    """(4, 4) c2w on a sphere around ``target`` (azimuth from +x towards +y, elevation above the xy plane)."""
    eye = np.asarray(target, dtype=np.float64) + radius * np.array(
        [math.cos(elevation) * math.cos(azimuth), math.cos(elevation) * math.sin(azimuth), math.sin(elevation)])
    c2w = look_at(eye, target)
    if roll:
        c2w[:3, :3] = c2w[:3, :3] @ rotation_matrix(np.array([0.0, 0.0, 1.0]), roll)
    return c2w


def circular_path(target: np.ndarray, radius: float, n: int, rng: np.random.Generator,
                  spec: PathSpec = PathSpec()) -> np.ndarray:
    """(n, 4, 4) one hand-held circle: elevation drawn in ``spec.elevation_range``, with jitter."""
    lo, hi = spec.elevation_range
    elev0 = rng.uniform(lo, hi)
    az0 = rng.uniform(0, 2 * math.pi)
    step = 2 * math.pi / max(n, 1)
    out = np.empty((n, 4, 4))
    for i in range(n):
        az = az0 + step * (i + rng.uniform(-spec.jitter_azimuth, spec.jitter_azimuth))
        el = float(np.clip(elev0 + rng.normal(0, spec.jitter_elevation), lo, hi))
        r = radius * (1 + rng.normal(0, spec.jitter_radius))
        tgt = np.asarray(target) + rng.normal(0, spec.jitter_target * radius, size=3) * 0.3
        out[i] = orbit_pose(tgt, r, az, el, roll=rng.normal(0, spec.jitter_roll))
    return out


def random_views(target: np.ndarray, radius: float, n: int, rng: np.random.Generator,
                 spec: PathSpec = PathSpec()) -> np.ndarray:
    """(n, 4, 4) wide-baseline views: azimuth uniform in [0, 2π), elevation uniform in the range."""
    lo, hi = spec.elevation_range
    out = np.empty((n, 4, 4))
    for i in range(n):
        r = radius * (1 + rng.normal(0, spec.jitter_radius))
        out[i] = orbit_pose(target, r, rng.uniform(0, 2 * math.pi), rng.uniform(lo, hi),
                            roll=rng.normal(0, spec.jitter_roll))
    return out


def fixed_test_views(target: np.ndarray, radius: float, n: int, spec: PathSpec = PathSpec()) -> np.ndarray:
    """(n, 4, 4) deterministic test views: a golden-angle spiral of azimuths, elevations across the range."""
    lo, hi = spec.elevation_range
    golden = math.pi * (3 - math.sqrt(5))
    out = np.empty((n, 4, 4))
    for i in range(n):
        el = lo + (hi - lo) * ((i + 0.5) / max(n, 1))
        out[i] = orbit_pose(target, radius, math.pi / 7 + golden * i, el)
    return out
