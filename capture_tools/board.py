"""ChArUco board option (opencv-contrib ``cv2.aruco``): metric camera poses when a board is in view.

A ChArUco board (chessboard with ArUco markers in the white squares) lying on the pedestal gives each
view where it sees the board a metric pose in the *board frame* (x along the board's squares, y
along its rows, z out of the board, origin at the board's corner; metres). :func:`board_pose` finds
it with ``CharucoDetector`` + ``solvePnP``; :func:`board_scale` compares SfM camera centres with those
poses (Sim(3) fit) to give the metric scale from the board instead of the depth sensor.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from rsart.camera import Intrinsics
from rsart.errors import RsartError

from .pose_eval import umeyama


@dataclass(frozen=True)
class BoardSpec:
    """Squares across x and y, square and marker side (metres), ArUco dictionary name (``cv2.aruco.DICT_*``)."""

    squares_x: int = 5
    squares_y: int = 7
    square: float = 0.04
    marker: float = 0.03
    dictionary: str = "DICT_5X5_100"

    def board(self) -> "cv2.aruco.CharucoBoard":
        if not hasattr(cv2.aruco, self.dictionary):
            raise RsartError(f"unknown ArUco dictionary {self.dictionary!r}")
        d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        return cv2.aruco.CharucoBoard((self.squares_x, self.squares_y), self.square, self.marker, d)


@dataclass
class BoardPose:
    """``c2w`` (4, 4) camera-to-board (OpenCV axes, metres), corners used, RMS reprojection error (px)."""

    c2w: np.ndarray
    corners: int
    rms_px: float


def board_pose(rgb: np.ndarray, intrinsics: Intrinsics, spec: BoardSpec = BoardSpec(),
               min_corners: int = 6) -> BoardPose | None:
    """The board pose seen in (H, W, 3) uint8 ``rgb``, or None when fewer than ``min_corners`` corners are found."""
    board = spec.board()
    grey = cv2.cvtColor(rgb[..., :3], cv2.COLOR_RGB2GRAY)
    corners, ids, _, _ = cv2.aruco.CharucoDetector(board).detectBoard(grey)
    if ids is None or len(ids) < min_corners:
        return None
    obj, img = board.matchImagePoints(corners, ids)
    K = intrinsics.K
    dist = np.asarray(intrinsics.distortion or [], dtype=np.float64)
    ok, rvec, tvec = cv2.solvePnP(obj, img, K, dist if dist.size else None, flags=cv2.SOLVEPNP_ITERATIVE)
    if not ok:
        return None
    proj, _ = cv2.projectPoints(obj, rvec, tvec, K, dist if dist.size else None)
    rms = float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - img.reshape(-1, 2)) ** 2, axis=1))))
    w2c = np.eye(4)
    w2c[:3, :3] = cv2.Rodrigues(rvec)[0]
    w2c[:3, 3] = tvec.ravel()
    return BoardPose(np.linalg.inv(w2c), int(len(ids)), rms)


def board_scale(sfm_c2w: dict[str, np.ndarray], board: dict[str, BoardPose]) -> tuple[float, np.ndarray]:
    """(metres per SfM unit, (4, 4) SfM -> board similarity) from the views both know (>= 3 needed)."""
    names = [n for n in sfm_c2w if n in board]
    if len(names) < 3:
        raise RsartError(f"board: seen in only {len(names)} registered views (need 3)")
    s, R, t = umeyama(np.array([sfm_c2w[n][:3, 3] for n in names]), np.array([board[n].c2w[:3, 3] for n in names]))
    M = np.eye(4)
    M[:3, :3], M[:3, 3] = s * R, t
    return s, M
