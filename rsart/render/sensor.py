"""A RealSense-like depth sensor and colour camera model applied to clean renders.

Depth (active stereo, D435-like, depth aligned to the colour camera):
  disparity d = f·B / z (pixels); d + N(0, σ_d) is rounded to the sub-pixel grid ``subpixel_step``
  and converted back, z' = f·B / d'. The error therefore grows with z² (σ_z ≈ z²·σ_d / (f·B))
  and depth takes the discrete values of the disparity grid. Pixels become invalid (0):
  * at depth discontinuities (relative jump to a 4-neighbour > ``edge_rel_jump``), dilated at random;
  * at grazing incidence (angle between ray and surface normal > ``grazing_deg``, ramping in
    from ``grazing_deg - 10°``);
  * on dark (low-albedo, weak IR return) or saturated/specular surfaces, as blob-shaped holes;
  * outside [min_z, max_z] and as sparse random dropouts.
Colour: per-view exposure gain and white balance, shot + read noise, 8-bit quantisation.
All randomness comes from the ``rng`` passed in (the runner seeds it per view).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np


@dataclass(frozen=True)
class DepthSensorModel:
    """Parameters of the depth model (metres, pixels)."""

    baseline: float = 0.050
    subpixel_sigma: float = 0.08
    subpixel_step: float = 1.0 / 8.0
    min_z: float = 0.2
    max_z: float = 6.0
    edge_rel_jump: float = 0.03
    edge_dilate_p: float = 0.5
    grazing_deg: float = 80.0
    dark_luma: float = 0.06
    bright_luma: float = 0.98
    hole_p: float = 0.7
    dropout_p: float = 0.002


@dataclass(frozen=True)
class ColourSensorModel:
    """Parameters of the colour model (intensities in [0, 1])."""

    exposure_sigma: float = 0.12
    white_balance_sigma: float = 0.03
    shot_noise: float = 0.0006
    read_noise: float = 0.004


def _luma(rgb: np.ndarray) -> np.ndarray:
    x = rgb.astype(np.float32) / 255.0
    return 0.299 * x[..., 0] + 0.587 * x[..., 1] + 0.114 * x[..., 2]


def _blobs(shape: tuple[int, int], p: float, rng: np.random.Generator, cell: int = 6) -> np.ndarray:
    """(H, W) bool random blob pattern covering about a fraction ``p`` of the image."""
    h, w = shape
    low = rng.uniform(0, 1, size=(max(1, h // cell), max(1, w // cell))).astype(np.float32)
    field = cv2.resize(low, (w, h), interpolation=cv2.INTER_LINEAR)
    return field < p


def depth_edges(depth: np.ndarray, rel_jump: float) -> np.ndarray:
    """(H, W) bool: valid pixels with a 4-neighbour whose depth differs by more than ``rel_jump`` · z
    (or a 4-neighbour that is invalid)."""
    d = depth.astype(np.float64)
    valid = d > 0
    edge = np.zeros_like(valid)
    for axis in (0, 1):
        a = np.take(d, range(0, d.shape[axis] - 1), axis=axis)
        b = np.take(d, range(1, d.shape[axis]), axis=axis)
        jump = (np.abs(a - b) > rel_jump * np.maximum(a, b)) | ((a > 0) != (b > 0))
        if axis == 0:
            edge[:-1] |= jump
            edge[1:] |= jump
        else:
            edge[:, :-1] |= jump
            edge[:, 1:] |= jump
    return edge & valid


def realsense_depth(depth: np.ndarray, focal_px: float, cos_incidence: np.ndarray, clean_rgb: np.ndarray,
                    rng: np.random.Generator, model: DepthSensorModel = DepthSensorModel()) -> np.ndarray:
    """(H, W) float32 sensor-like depth (0 = invalid) from a clean (H, W) z-depth map (metres).

    ``cos_incidence`` (H, W): |cos| between ray and surface normal; ``clean_rgb`` (H, W, 3) uint8
    gives the albedo proxy for dark/specular holes; ``focal_px`` is the depth camera focal length.
    """
    z = depth.astype(np.float64)
    valid = z > 0
    fb = focal_px * model.baseline
    disp = np.where(valid, fb / np.where(valid, z, 1.0), 0.0)
    disp = disp + rng.normal(0, model.subpixel_sigma, size=z.shape)
    disp = np.round(disp / model.subpixel_step) * model.subpixel_step
    ok = valid & (disp > 0)
    out = np.where(ok, fb / np.where(ok, disp, 1.0), 0.0)
    # invalid pixels
    bad = ~ok | (out < model.min_z) | (out > model.max_z)
    edges = depth_edges(depth, model.edge_rel_jump)
    grown = cv2.dilate(edges.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    bad |= edges | (grown & (rng.uniform(size=z.shape) < model.edge_dilate_p))
    ang = np.degrees(np.arccos(np.clip(cos_incidence, 0, 1)))
    ramp = np.clip((ang - (model.grazing_deg - 10.0)) / 10.0, 0, 1)
    bad |= valid & (rng.uniform(size=z.shape) < ramp)
    luma = _luma(clean_rgb)
    holes = _blobs(z.shape, model.hole_p, rng)
    bad |= valid & ((luma < model.dark_luma) | (luma > model.bright_luma)) & holes
    bad |= rng.uniform(size=z.shape) < model.dropout_p
    out[bad] = 0
    return out.astype(np.float32)


def realsense_colour(rgb: np.ndarray, rng: np.random.Generator,
                     model: ColourSensorModel = ColourSensorModel()) -> np.ndarray:
    """(H, W, 3) uint8 noisy colour: exposure gain, white balance, shot + read noise, clipping."""
    x = rgb.astype(np.float64) / 255.0
    gain = math.exp(rng.normal(0, model.exposure_sigma))
    wb = np.exp(rng.normal(0, model.white_balance_sigma, size=3))
    x = x * gain * wb
    sigma = np.sqrt(model.shot_noise * np.clip(x, 0, None) + model.read_noise ** 2)
    x = x + rng.normal(size=x.shape) * sigma
    return np.clip(np.round(x * 255), 0, 255).astype(np.uint8)
