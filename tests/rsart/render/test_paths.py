"""Camera paths: elevation range, object centred and inside the image, fixed test views."""
from __future__ import annotations

import math

import numpy as np

from rsart.camera import REALSENSE_D435_COLOR_640x480, Camera
from rsart.render.paths import PathSpec, bounding_sphere, circular_path, fit_radius, fixed_test_views, random_views

K = REALSENSE_D435_COLOR_640x480
BOUNDS = np.array([[-0.2, -0.15, 0.0], [0.25, 0.2, 0.4]])


def _elevation(c2w, target):
    v = c2w[:3, 3] - target
    return math.degrees(math.asin(v[2] / np.linalg.norm(v)))


def test_circle_stays_in_elevation_range_and_sees_the_object():
    target, r_obj = bounding_sphere(BOUNDS)
    radius = fit_radius(BOUNDS, K, 0.8)
    rng = np.random.default_rng(3)
    poses = circular_path(target, radius, 40, rng)
    elev = [_elevation(p, target) for p in poses]
    assert min(elev) >= 30 - 2 and max(elev) <= 60 + 2  # target jitter moves the reference point slightly
    az = np.unwrap([math.atan2(*(p[:3, 3] - target)[[1, 0]]) for p in poses])
    assert abs(az[-1] - az[0]) > math.radians(330)  # one full circle
    corners = np.array(np.meshgrid(*BOUNDS.T)).reshape(3, -1).T
    for p in poses:
        uv, z = Camera(K, p).project(corners)
        assert np.all(z > 0)
        assert np.all((uv[:, 0] > 0) & (uv[:, 0] < K.width - 1) & (uv[:, 1] > 0) & (uv[:, 1] < K.height - 1))
        c, _ = Camera(K, p).project(target[None])
        assert np.hypot(c[0, 0] - K.cx, c[0, 1] - K.cy) < 0.1 * K.height  # aimed at the object, hand-held


def test_fit_radius_makes_the_sphere_fill_the_requested_fraction():
    target, r = bounding_sphere(BOUNDS)
    d = fit_radius(BOUNDS, K, 0.6)
    half = math.atan(K.height / 2 / K.fy)
    assert math.isclose(math.tan(math.asin(r / d)), 0.6 * math.tan(half), rel_tol=1e-9)


def test_jitter_adds_roll_and_random_views_spread():
    target = np.zeros(3)
    poses = circular_path(target, 1.0, 30, np.random.default_rng(0))
    rolls = [math.degrees(math.asin(np.clip(p[2, 0], -1, 1))) for p in poses]  # camera x tilts out of the xy plane
    assert 0.3 < np.std(rolls) < 6
    still = circular_path(target, 1.0, 30, np.random.default_rng(0),
                          PathSpec(jitter_roll=0, jitter_elevation=0, jitter_radius=0, jitter_target=0, jitter_azimuth=0))
    assert np.allclose([p[2, 0] for p in still], 0, atol=1e-12)
    assert np.allclose([np.linalg.norm(p[:3, 3]) for p in still], 1.0)
    rv = random_views(target, 1.0, 200, np.random.default_rng(1))
    el = [_elevation(p, target) for p in rv]
    assert 29 < min(el) < 35 and 55 < max(el) < 61


def test_fixed_test_views_do_not_depend_on_randomness():
    a = fixed_test_views(np.zeros(3), 1.2, 8)
    b = fixed_test_views(np.zeros(3), 1.2, 8)
    assert np.array_equal(a, b) and len({tuple(np.round(p[:3, 3], 6)) for p in a}) == 8
