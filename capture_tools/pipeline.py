"""One interaction state from a raw recording to posed, masked views in the object frame.

:func:`process_state` streams the recording twice (never holding more than the selected frames):

1. score every frame (chroma-key mask, sharpness, exposure) and select ``n_views`` spread in time;
2. re-read the selected frames; SfM (pycolmap, known intrinsics, features inside the dilated masks;
   rerun with the next seed while the model disagrees with the sensor depth); metric scale from depth;
   RGB-D bundle adjustment; leave-one-out depth ICP per view on the object and the pedestal band
   around it (:func:`reconstruct_state` = steps 1-2; :mod:`capture_tools.joint` repeats step 2 over
   all states at once);
3. pedestal plane (RANSAC on the background depth under the object) -> up direction, and pedestal
   pixels dropped from the masks;
4. twin registration (FPFH + RANSAC, ICP) of the twin posed at the state's joint values to the
   fused object depth; cameras moved into the object (twin base) frame;
5. part masks: the registered twin ray-cast per view (part index + 1) inside the chroma-key mask;
   keyed pixels the twin misses take the nearest part label (:func:`place_state` = steps 3-5, each a
   function of its own: :func:`pedestal_step`, :func:`registration_step`, :func:`object_frame_step`,
   :func:`part_masks_from_twin`).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy import ndimage

from rsart.camera import Camera, Intrinsics
from rsart.errors import RsartError
from rsart.kinematics import Twin

from . import chroma
from .board import BoardSpec, board_pose, board_scale
from .depth_align import refine_with_depth, view_points
from .readers import RawFrame, Recording
from .register import Registration, pedestal_plane, register_twin, residual_of, up_alignment
from .rgbd_ba import refine_rgbd
from .select import score_frame, select_frames
from .sfm import apply_scale, depth_disagreement, metric_scale, run_sfm

log = logging.getLogger(__name__)


@dataclass
class CaptureSettings:
    """Knobs of the per-state pipeline (defaults suit 320x240 - 640x480 booth captures)."""

    n_views: int = 30
    chroma: chroma.ChromaSettings = field(default_factory=chroma.ChromaSettings)
    feature_dilate_px: int = 9
    rgbd_ba: bool = True
    depth_icp: bool = True
    icp_voxel: float = 0.004
    icp_stride: int = 2  # every 2nd pixel; 1 (with icp_voxel 0.003) lowers the ICP noise floor, at ~2x the time
    seed: int = 0
    board: BoardSpec | None = None
    max_ba_reproj_px: float = 1.5
    sfm: str = "joint"  # "per-state" | "joint" (capture_tools.joint)
    sfm_attempts: int = 3  # SfM reruns (seed + 1, ...) while the model disagrees with the depth sensor
    max_depth_disagreement: float = 0.02  # median |log(depth ratio / median)| of a model accepted at once
    icp_band: float = 0.08  # depth ICP also uses the pedestal in a band this fraction of the image width wide


@dataclass
class StateResult:
    """Selected frames of one state with object-frame poses, part masks and the figures of each step."""

    frames: list[RawFrame]
    c2w: dict[str, np.ndarray]
    masks: dict[str, np.ndarray]
    registration: Registration
    report: dict


@dataclass
class StateRecon:
    """One state after steps 1-2: selected ``frames``, ``names`` (frame name -> SfM image name), ``keyed``
    (frame name -> (H, W) bool chroma-key mask) and metric capture-frame poses ``c2w`` (image name -> (4, 4))."""

    frames: list[RawFrame]
    names: dict[str, str]
    keyed: dict[str, np.ndarray]
    c2w: dict[str, np.ndarray]
    report: dict


def select_state(rec: Recording, settings: CaptureSettings) -> tuple[list[RawFrame], dict[str, np.ndarray], int]:
    """Step 1: (selected frames, frame name -> keyed mask, number of frames scored) from a streamed recording."""
    scores, packed = [], {}
    for f in rec:
        m = chroma.key_object(f.rgb, settings.chroma)
        scores.append(score_frame(f.index, f.timestamp, f.rgb, m))
        packed[f.index] = (np.packbits(m), m.shape)  # 1 bit per pixel: masks of every frame stay small
    chosen = set(select_frames(scores, settings.n_views))
    frames = [f for f in rec if f.index in chosen]
    if any(f.depth is None for f in frames):
        raise RsartError(f"{rec.source}: the recording has no depth stream (needed for scale and registration)")
    masks = {f.name: np.unpackbits(packed[f.index][0], count=int(np.prod(packed[f.index][1])))
             .reshape(packed[f.index][1]).astype(bool) for f in frames}
    return frames, masks, len(scores)


def estimate_poses(images: dict[str, np.ndarray], intr: Intrinsics, depths: dict[str, np.ndarray],
                   keyed: dict[str, np.ndarray], settings: CaptureSettings, pair_filter=None,
                   groups: dict[str, str] | None = None,
                   static: dict[str, np.ndarray] | None = None) -> tuple[dict[str, np.ndarray], dict]:
    """Step 2 on image name -> RGB / depth (m) / keyed mask: SfM, metric scale (depth or board), RGB-D BA,
    leave-one-out depth ICP. ``pair_filter``, ``groups`` and ``static`` are the joint mode's
    (capture_tools.joint): cross-state matches and cross-state depth restricted to the static base.
    Returns (image name -> metric c2w in the SfM frame, figures)."""
    kern = np.ones((settings.feature_dilate_px, settings.feature_dilate_px), np.uint8)
    feat_masks = {n: cv2.dilate(m.astype(np.uint8), kern) for n, m in keyed.items()}
    sfm, attempts, best = None, [], (False, 0, 0.0)
    for attempt in range(max(1, settings.sfm_attempts)):
        # SIFT extraction and matching are multi-threaded, so a rerun can chain the circle differently; a
        # wrongly chained model (seen: 1 run in ~5 on one state, 177° off) disagrees with the sensor's depth
        try:
            cand = run_sfm(images, intr, feat_masks, seed=settings.seed + attempt, pair_filter=pair_filter)
        except RsartError:
            if attempt + 1 == max(1, settings.sfm_attempts) and sfm is None:
                raise
            continue
        dis = depth_disagreement(cand, depths)
        attempts.append({"registered": len(cand.c2w), "depth_disagreement": dis})
        # rank: agrees with the depth, then registers more frames, then agrees better
        rank = (dis <= settings.max_depth_disagreement, len(cand.c2w), -dis)
        if sfm is None or rank > best:
            sfm, best = cand, rank
        if best[:2] == (True, len(images)):
            break
    scale, n_ratios = metric_scale(sfm, depths)
    extra: dict = {"depth_scale_factor": scale, "sfm_attempts": attempts}
    if settings.board is not None:
        seen = {n: p for n, rgb in images.items() if (p := board_pose(rgb, intr, settings.board)) is not None}
        if len(seen) >= 3:
            scale, _ = board_scale(sfm.c2w, seen)  # the board's metric scale replaces the depth sensor's
            extra.update(board_views=len(seen), board_scale_factor=scale)
        else:
            extra.update(board_views=len(seen), board_note="board seen in < 3 views: depth scale kept")
    sfm = apply_scale(sfm, scale)
    report: dict = {**extra, "sfm_registered": len(sfm.c2w), "sfm_reprojection_px": sfm.mean_reprojection_error,
                    "metric_scale_ratios": n_ratios, **({"sfm_pairs": sfm.pair_counts} if sfm.pair_counts else {})}
    if settings.rgbd_ba:
        refined, ba = refine_rgbd(sfm, intr, depths)
        kept = ba.median_reproj_px <= settings.max_ba_reproj_px  # a diverged adjustment must not replace SfM
        report["rgbd_ba"] = {"median_reproj_px": ba.median_reproj_px, "median_depth_residual_m": ba.median_depth_residual,
                             "used": bool(kept)}
        if kept:
            sfm = refined
    c2w = dict(sfm.c2w)
    if settings.depth_icp:
        band_px = int(round(settings.icp_band * intr.width))
        icp_masks = {n: icp_band(m, depths[n], band_px) for n, m in keyed.items()}
        c2w, icp_rmse = refine_with_depth(c2w, intr, depths, icp_masks, voxel=settings.icp_voxel,
                                          stride=settings.icp_stride, groups=groups, static=static)
        report["depth_icp_rmse_m"] = icp_rmse
    return c2w, report


def icp_band(keyed: np.ndarray, depth: np.ndarray, band_px: int) -> np.ndarray:
    """(H, W) bool: the object mask grown by ``band_px`` pixels, keeping only depth no further than the object's
    farthest point + 10 %: the pedestal top around the object (static and flat, seen from every side), not
    the booth walls behind it."""
    if band_px <= 0:
        return keyed
    grown = cv2.dilate(keyed.astype(np.uint8), np.ones((2 * band_px + 1, 2 * band_px + 1), np.uint8)).astype(bool)
    obj = depth[keyed & (depth > 0)]
    if not len(obj):
        return keyed
    return keyed | (grown & (depth > 0) & (depth < 1.1 * float(np.percentile(obj, 99))))


def reconstruct_state(rec: Recording, settings: CaptureSettings = CaptureSettings()) -> StateRecon:
    """Steps 1-2 of the module docstring on one recording (its own SfM frame, metres)."""
    frames, masks, n_total = select_state(rec, settings)
    names = {f.name: f"{f.name}.png" for f in frames}
    c2w, report = estimate_poses({names[f.name]: f.rgb for f in frames}, rec.intrinsics,
                                 {names[f.name]: f.depth for f in frames},
                                 {names[f.name]: masks[f.name] for f in frames}, settings)
    report = {"frames_total": n_total, "frames_selected": len(frames), **report}
    frames = [f for f in frames if names[f.name] in c2w]
    if len(frames) < 3:
        raise RsartError(f"{rec.source}: SfM registered only {len(frames)} frames")
    return StateRecon(frames, names, masks, c2w, report)


@dataclass
class Pedestal:
    """Step 3 of one state: the pedestal ``plane`` (4,) n·x + d = 0 in the capture frame (n up) with its
    RANSAC ``inliers``, ``up_T`` (4, 4) turning n onto +z, the keyed ``masks`` without pedestal pixels
    (frame name -> (H, W) bool) and the ``object_points`` (N, 3) those masks keep, capture frame, metres."""

    plane: np.ndarray
    inliers: int
    up_T: np.ndarray
    masks: dict[str, np.ndarray]
    object_points: np.ndarray


def pedestal_step(recon: StateRecon, intr: Intrinsics) -> Pedestal:
    """Step 3: pedestal plane (RANSAC on the background depth under the object), pedestal pixels dropped."""
    frames, names, c2w, masks = recon.frames, recon.names, recon.c2w, dict(recon.keyed)
    obj_pts = np.concatenate([view_points(intr, f.depth, masks[f.name], c2w[names[f.name]], 2) for f in frames])
    bg_pts = np.concatenate([view_points(intr, f.depth, ~masks[f.name], c2w[names[f.name]], 3) for f in frames])
    plane, n_in = pedestal_plane(bg_pts, obj_pts)
    up_T = up_alignment(plane)
    for f in frames:
        w2c = np.linalg.inv(c2w[names[f.name]])
        n_cam = w2c[:3, :3] @ plane[:3]
        p0 = -plane[3] * plane[:3]
        plane_cam = np.concatenate([n_cam, [-(n_cam @ (w2c[:3, :3] @ p0 + w2c[:3, 3]))]])
        masks[f.name] = chroma.remove_plane(masks[f.name], f.depth, intr, plane_cam)
    obj_pts = np.concatenate([view_points(intr, f.depth, masks[f.name], c2w[names[f.name]], 2) for f in frames])
    return Pedestal(plane, n_in, up_T, masks, obj_pts)


def registration_step(pedestal: Pedestal, twin: Twin, values: dict[str, float],
                      settings: CaptureSettings = CaptureSettings(), shared: Registration | None = None
                      ) -> Registration:
    """Step 4: the twin posed at ``values`` registered to the state's object depth; with ``shared`` (one
    registration for all states of a joint capture) only its residuals on this state are measured."""
    mesh = twin.whole_mesh(values)
    if shared is not None:
        return residual_of(mesh, pedestal.object_points, shared.T, coarse_fitness=shared.coarse_fitness)
    return register_twin(mesh, pedestal.object_points, up_T=pedestal.up_T, seed=settings.seed)


def object_frame_step(recon: StateRecon, registration: Registration) -> dict[str, np.ndarray]:
    """Step 4 (end): frame name -> (4, 4) camera-to-world in the object (twin base) frame."""
    Tinv = np.linalg.inv(registration.T)
    return {f.name: Tinv @ recon.c2w[recon.names[f.name]] for f in recon.frames}


def finish_state(recon: StateRecon, intr: Intrinsics, twin: Twin, values: dict[str, float], pedestal: Pedestal,
                 registration: Registration) -> StateResult:
    """Steps 4 (end) and 5 from the results of 3 and 4: object-frame poses and part masks from the twin."""
    report = dict(recon.report)
    report["pedestal_plane_inliers"] = pedestal.inliers
    report["registration"] = {k: v for k, v in registration.to_dict().items() if k != "T_world_to_capture"}
    posed = object_frame_step(recon, registration)
    masks = part_masks_from_twin(twin, values, intr, posed, pedestal.masks)
    return StateResult(recon.frames, posed, masks, registration, report)


def place_state(recon: StateRecon, intr: Intrinsics, twin: Twin, values: dict[str, float],
                settings: CaptureSettings = CaptureSettings()) -> StateResult:
    """Steps 3-5, each once: pedestal masks -> twin registration -> object frame -> part masks from the twin."""
    pedestal = pedestal_step(recon, intr)
    return finish_state(recon, intr, twin, values, pedestal, registration_step(pedestal, twin, values, settings))


def process_state(rec: Recording, twin: Twin, values: dict[str, float],
                  settings: CaptureSettings = CaptureSettings()) -> StateResult:
    """Run steps 1-5 of the module docstring on one recording; raises :class:`RsartError` on failure."""
    return place_state(reconstruct_state(rec, settings), rec.intrinsics, twin, values, settings)


def part_masks_from_twin(twin: Twin, values: dict[str, float], intr: Intrinsics, c2w: dict[str, np.ndarray],
                         keyed: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """(H, W) uint8 part index + 1 per view: the ray-cast twin inside the keyed mask (nearest label where
    the twin misses a keyed pixel; 0 outside the keyed mask)."""
    from rsart.render.raycast import build_scene

    scene = build_scene([[m] for m in twin.posed_meshes(values)], [])
    out = {}
    for name, M in c2w.items():
        lab = scene.cast(Camera(intr, M)).part_mask().astype(np.uint8)
        key = keyed[name]
        hit = lab > 0
        if hit.any():
            idx = ndimage.distance_transform_edt(~hit, return_distances=False, return_indices=True)
            filled = lab[idx[0], idx[1]]
        else:
            filled = np.ones_like(lab)
        out[name] = np.where(key, filled, 0).astype(np.uint8)
    return out
