"""ChArUco board poses: a board image placed at a known metric pose (exact homography warp) is found
again to a fraction of a degree and a millimetre; board_scale recovers an SfM-like scale."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from capture_tools.board import BoardSpec, board_pose, board_scale
from rsart.camera import Intrinsics, look_at

K = Intrinsics(640, 480, 600.0, 600.0, 319.5, 239.5)
SPEC = BoardSpec()


def view_of_board(c2w: np.ndarray) -> np.ndarray:
    """RGB image of the board (board frame: z = 0 plane, x across, y down the rows) seen by camera ``c2w``."""
    px_per_m = 4000
    w, h = int(SPEC.squares_x * SPEC.square * px_per_m), int(SPEC.squares_y * SPEC.square * px_per_m)
    tex = SPEC.board().generateImage((w, h), marginSize=0)
    w2c = np.linalg.inv(c2w)
    # board pixel (a, b) -> board point ((a + 0.5) / px_per_m, (b + 0.5) / px_per_m, 0)
    S = np.array([[1 / px_per_m, 0, 0.5 / px_per_m], [0, 1 / px_per_m, 0.5 / px_per_m], [0, 0, 1]])
    H = K.K @ np.column_stack([w2c[:3, 0], w2c[:3, 1], w2c[:3, 3]]) @ S
    img = cv2.warpPerspective(tex, H, (K.width, K.height), flags=cv2.INTER_AREA, borderValue=200)
    return np.repeat(img[..., None], 3, axis=2)


def test_board_pose_matches_truth():
    centre = np.array([SPEC.squares_x * SPEC.square / 2, SPEC.squares_y * SPEC.square / 2, 0.0])
    truths, found = {}, {}
    for i in range(5):
        a = 2 * np.pi * i / 5
        eye = centre + 0.5 * np.array([np.cos(a) * 0.6, np.sin(a) * 0.6, -0.8])  # board z points away from cameras
        c2w = look_at(eye, centre, up=np.array([0.0, -1.0, 0.0]))
        truths[f"{i}"] = c2w
        p = board_pose(view_of_board(c2w), K, SPEC)
        assert p is not None and p.corners >= 12 and p.rms_px < 0.5
        R = p.c2w[:3, :3].T @ c2w[:3, :3]
        ang = np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1)))
        assert ang < 0.3 and np.linalg.norm(p.c2w[:3, 3] - c2w[:3, 3]) < 0.002
        found[f"{i}"] = p
    # an "SfM" frame: the truth scaled by 1/3 and moved; the board gives the metric scale back
    sfm = {}
    for n, m in truths.items():
        m2 = m.copy()
        m2[:3, 3] = m[:3, 3] / 3 + np.array([1.0, 2.0, 3.0])
        sfm[n] = m2
    s, _ = board_scale(sfm, found)
    assert s == pytest.approx(3.0, rel=0.01)


def test_no_board_no_pose():
    assert board_pose(np.full((K.height, K.width, 3), 128, np.uint8), K) is None
