"""The RealSense-like sensor model: z² noise, disparity grid, invalid edges/grazing/dark pixels; colour noise."""
from __future__ import annotations

import numpy as np

from rsart.render.sensor import DepthSensorModel, depth_edges, realsense_colour, realsense_depth

F = 615.0
GREY = np.full((120, 160, 3), 128, np.uint8)
FLAT = np.ones((120, 160), np.float32)


def _noisy(z, model=DepthSensorModel(), cos=None, rgb=GREY, seed=0):
    return realsense_depth(np.full((120, 160), z, np.float32), F, FLAT if cos is None else cos, rgb,
                           np.random.default_rng(seed), model)


def test_noise_grows_with_the_square_of_depth():
    m = DepthSensorModel(subpixel_step=1e-6, dropout_p=0)  # isolate the Gaussian disparity noise
    s = {}
    for z in (0.5, 1.0, 2.0):
        d = _noisy(z, m)
        v = d[d > 0]
        s[z] = v.std()
        assert abs(v.mean() - z) < 0.01 * z
        expected = z * z * m.subpixel_sigma / (F * m.baseline)
        assert 0.8 * expected < s[z] < 1.2 * expected
    assert 12 < s[2.0] / s[0.5] < 20  # (2 / 0.5)^2 = 16


def test_depth_lies_on_the_disparity_grid():
    m = DepthSensorModel()
    d = _noisy(1.3, m)
    disp = F * m.baseline / d[d > 0]
    steps = disp / m.subpixel_step
    assert np.allclose(steps, np.round(steps), atol=1e-3)
    assert len(np.unique(d[d > 0])) < 40  # quantised: few distinct values


def test_invalid_pixels_at_edges_grazing_angles_and_dark_surfaces():
    z = np.full((120, 160), 1.0, np.float32)
    z[:, 80:] = 2.0  # a depth discontinuity at column 80
    d = realsense_depth(z, F, FLAT, GREY, np.random.default_rng(0), DepthSensorModel(dropout_p=0))
    assert np.all(d[:, 79:81] == 0) and (d[:, 10:70] > 0).mean() > 0.99
    cos = np.full((120, 160), np.cos(np.radians(85)), np.float32)
    assert (_noisy(1.0, cos=cos) > 0).mean() < 0.01
    dark = np.zeros_like(GREY)
    dd = _noisy(1.0, rgb=dark)
    assert 0.4 < (dd == 0).mean() < 0.95  # blob-shaped holes on dark surfaces
    assert np.array_equal(depth_edges(z, 0.03)[:, 79:81], np.ones((120, 2), bool))


def test_depth_and_colour_noise_are_seeded():
    assert np.array_equal(_noisy(1.0, seed=4), _noisy(1.0, seed=4))
    assert not np.array_equal(_noisy(1.0, seed=4), _noisy(1.0, seed=5))
    a = realsense_colour(GREY, np.random.default_rng(1))
    assert np.array_equal(a, realsense_colour(GREY, np.random.default_rng(1)))
    assert 2 < np.abs(a.astype(int) - 128).mean() < 40 and a.std() > 1
