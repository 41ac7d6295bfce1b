"""Camera poses from images with pycolmap (SfM with known intrinsics) and metric scale from sensor depth.

Frames: SfM returns poses in an arbitrary similarity frame; :func:`metric_scale` finds the factor
that makes SfM depths agree with the sensor's (robust median of per-point ratios), so the poses are
then in metres. Cameras are OpenCV (x right, y down, z forward); ``c2w`` maps camera points to the
SfM (capture) frame. COLMAP puts pixel centres at +0.5 (its image corner is (0, 0)); rsart puts the
centre of the top-left pixel at (0, 0), so principal points are shifted by 0.5 on the way in and
2-D observations on the way out.
"""
from __future__ import annotations

import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import cv2
import numpy as np

from rsart.camera import Intrinsics
from rsart.errors import RsartError


@dataclass
class SfmResult:
    """Poses of the images SfM registered (``c2w[name]`` (4, 4), OpenCV, capture frame) and observations.

    ``observations[name]``: (M, 5) array of (u, v, X, Y, Z) -- a 2-D keypoint (rsart pixel convention)
    and its triangulated 3-D point (capture frame), used for the metric scale. ``scale``: the factor
    already applied to translations and points (1.0 until :func:`apply_scale`).
    """

    c2w: dict[str, np.ndarray]
    observations: dict[str, np.ndarray] = field(default_factory=dict)
    points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    scale: float = 1.0
    mean_reprojection_error: float = float("nan")
    pair_counts: dict = field(default_factory=dict)  # pair_filter: verified pairs kept / thinned / dropped

    def registered(self, names: list[str]) -> float:
        """Fraction of ``names`` that SfM registered."""
        return sum(n in self.c2w for n in names) / max(1, len(names))


def _write_inputs(work: Path, images: dict[str, np.ndarray], masks: dict[str, np.ndarray] | None) -> None:
    (work / "images").mkdir(parents=True, exist_ok=True)
    if masks is not None:
        (work / "masks").mkdir(parents=True, exist_ok=True)
    for name, rgb in images.items():
        cv2.imwrite(str(work / "images" / name), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
        if masks is not None and name in masks:
            # COLMAP masks: 0 = ignore features there; "<image name>.png"
            cv2.imwrite(str(work / "masks" / f"{name}.png"), (masks[name] > 0).astype(np.uint8) * 255)


def run_sfm(images: dict[str, np.ndarray], intrinsics: Intrinsics, masks: dict[str, np.ndarray] | None = None,
            work_dir: str | Path | None = None, max_features: int = 4096, seed: int = 0,
            threads: int = -1, peak_threshold: float = 0.004, dsp: bool = True,
            pair_filter: PairFilter | None = None) -> SfmResult:
    """Incremental SfM on ``images`` (name -> (H, W, 3) uint8 RGB) with fixed pinhole ``intrinsics``.

    ``masks`` (name -> (H, W), non-zero = keep features) restrict SIFT to the object (a green booth
    has no texture worth matching). Names must end in ``.png``. ``pair_filter`` may thin each verified
    image pair's inlier matches before mapping (see :data:`PairFilter`). The largest model is returned;
    images it did not register are absent from ``c2w``. Raises :class:`RsartError` when nothing
    reconstructs.
    """
    import pycolmap

    if len(images) < 3:
        raise RsartError(f"SfM needs at least 3 images, got {len(images)}")
    own = work_dir is None
    work = Path(tempfile.mkdtemp(prefix="rsart-sfm-")) if own else Path(work_dir)
    try:
        _write_inputs(work, images, masks)
        db = work / "database.db"
        if db.exists():
            db.unlink()
        reader = pycolmap.ImageReaderOptions()
        reader.camera_model = "PINHOLE"
        reader.camera_params = f"{intrinsics.fx},{intrinsics.fy},{intrinsics.cx + 0.5},{intrinsics.cy + 0.5}"
        if masks is not None:
            reader.mask_path = str(work / "masks")
        ext = pycolmap.FeatureExtractionOptions()
        ext.sift.max_num_features = max_features
        ext.sift.peak_threshold = peak_threshold  # below COLMAP's 0.0067: more keypoints on small objects
        ext.sift.domain_size_pooling = dsp  # DSP-SIFT: more stable descriptors, better matches
        ext.num_threads = threads
        pycolmap.extract_features(db, work / "images", image_names=sorted(images),
                                  camera_mode=pycolmap.CameraMode.SINGLE, reader_options=reader,
                                  extraction_options=ext, device=pycolmap.Device.cpu)
        pycolmap.match_exhaustive(db, device=pycolmap.Device.cpu)
        counts = _filter_pairs(db, pair_filter) if pair_filter is not None else {}
        opts = pycolmap.IncrementalPipelineOptions()
        opts.ba_refine_focal_length = False
        opts.ba_refine_principal_point = False
        opts.ba_refine_extra_params = False
        opts.random_seed = seed
        opts.num_threads = 1  # single-threaded mapping: the same input gives the same poses (it is the cheap part)
        (work / "sparse").mkdir(exist_ok=True)
        models = pycolmap.incremental_mapping(db, work / "images", work / "sparse", options=opts)
        if not models:
            raise RsartError(f"SfM registered no images ({len(images)} given): too little texture or overlap")
        rec = max(models.values(), key=lambda r: r.num_reg_images())
        out = _result(rec)
        out.pair_counts = counts
        return out
    finally:
        if own:
            shutil.rmtree(work, ignore_errors=True)


PairFilter = Callable[[str, str, np.ndarray, np.ndarray, np.ndarray], "np.ndarray | None"]
"""``f(name1, name2, xy1 (N1, 2), xy2 (N2, 2), matches (M, 2) int)`` -> the rows of ``matches`` to keep
(an index or boolean array), or None to keep the pair as it is. ``xy`` are the images' keypoints in rsart
pixels; ``matches`` index them. A pair left with fewer than :data:`MIN_PAIR_MATCHES` matches is dropped."""

MIN_PAIR_MATCHES = 15


def _filter_pairs(db_path: Path, pair_filter: PairFilter) -> dict[str, int]:
    """Apply ``pair_filter`` to every verified pair in the COLMAP database (in place); counts of pairs."""
    import pycolmap

    db = pycolmap.Database.open(str(db_path))
    try:
        names = {im.image_id: im.name for im in db.read_all_images()}
        xy = {i: db.read_keypoints(i)[:, :2].astype(np.float64) - 0.5 for i in names}
        counts = {"kept": 0, "thinned": 0, "dropped": 0}
        pair_ids, geoms = db.read_two_view_geometries()
        for pid, g in zip(pair_ids, geoms):
            i1, i2 = pycolmap.pair_id_to_image_pair(pid)
            m = np.asarray(g.inlier_matches)
            if not len(m):
                continue
            keep = pair_filter(names[i1], names[i2], xy[i1], xy[i2], m)
            if keep is None:
                counts["kept"] += 1
                continue
            m2 = m[keep]
            if len(m2) < MIN_PAIR_MATCHES:
                db.delete_two_view_geometry(i1, i2)
                counts["dropped"] += 1
            else:
                g.inlier_matches = np.ascontiguousarray(m2, dtype=m.dtype)
                db.update_two_view_geometry(i1, i2, g)
                counts["thinned"] += 1
        return counts
    finally:
        db.close()


def _result(rec) -> SfmResult:
    c2w, obs = {}, {}
    for img in rec.images.values():
        if not img.has_pose:
            continue
        w2c = np.eye(4)
        w2c[:3, :4] = img.cam_from_world().matrix()
        c2w[img.name] = np.linalg.inv(w2c)
        rows = []
        for p2 in img.points2D:
            if p2.has_point3D():
                X = rec.points3D[p2.point3D_id].xyz
                rows.append((p2.xy[0] - 0.5, p2.xy[1] - 0.5, *X))
        obs[img.name] = np.asarray(rows, dtype=np.float64).reshape(-1, 5)
    pts = np.array([p.xyz for p in rec.points3D.values()]).reshape(-1, 3)
    return SfmResult(c2w, obs, pts, 1.0, float(rec.compute_mean_reprojection_error()))


def stable_depth(depth: np.ndarray, rel: float = 0.015) -> np.ndarray:
    """(H, W) depth with 0 wherever the 3x3 neighbourhood is incomplete or spans more than ``rel`` x z.

    Keypoints sit on texture and silhouette edges; at a silhouette the sensor's depth may come from the
    surface behind, which would bias the scale and the RGB-D adjustment.
    """
    d = depth.astype(np.float32)
    k = np.ones((3, 3), np.uint8)
    hi = cv2.dilate(d, k)
    lo = cv2.erode(np.where(d > 0, d, np.float32(np.inf)), k)
    ok = (d > 0) & np.isfinite(lo) & (hi - lo <= rel * d)
    return np.where(ok, d, 0).astype(np.float32)


def depth_ratios(sfm: SfmResult, depths: dict[str, np.ndarray]) -> np.ndarray:
    """(M,) measured / SfM depth over every observation with a stable depth measurement.

    ``depths``: name -> (H, W) float z-depth in metres (0 = none), aligned to the colour image.
    """
    ratios = [np.zeros(0)]
    for name, ob in sfm.observations.items():
        if name not in depths or name not in sfm.c2w or not len(ob):
            continue
        d = stable_depth(depths[name])
        u = np.round(ob[:, 0]).astype(int)
        v = np.round(ob[:, 1]).astype(int)
        ok = (u >= 0) & (v >= 0) & (u < d.shape[1]) & (v < d.shape[0])
        w2c = np.linalg.inv(sfm.c2w[name])
        z_sfm = (ob[ok, 2:5] @ w2c[:3, :3].T + w2c[:3, 3])[:, 2]
        z_meas = d[v[ok], u[ok]]
        good = (z_meas > 0) & (z_sfm > 0)
        ratios.append(z_meas[good] / z_sfm[good])
    return np.concatenate(ratios)


def metric_scale(sfm: SfmResult, depths: dict[str, np.ndarray], min_points: int = 20) -> tuple[float, int]:
    """Metres per SfM unit: the median of :func:`depth_ratios` (the median, not a mean, ignores points on
    depth edges and holes). Returns (scale, number of ratios)."""
    r = depth_ratios(sfm, depths)
    if len(r) < min_points:
        raise RsartError(f"metric scale: only {len(r)} SfM points have a depth measurement (need {min_points})")
    return float(np.median(r)), int(len(r))


def depth_disagreement(sfm: SfmResult, depths: dict[str, np.ndarray]) -> float:
    """Median |log(ratio / median ratio)| of :func:`depth_ratios`: how far SfM's structure departs from the
    sensor's up to one scale (~0.005 for a right model, several times more for a wrongly chained one); inf
    without ratios."""
    r = depth_ratios(sfm, depths)
    r = r[r > 0]
    return float(np.median(np.abs(np.log(r / np.median(r))))) if len(r) else float("inf")


def apply_scale(sfm: SfmResult, s: float) -> SfmResult:
    """A copy of ``sfm`` with translations and points multiplied by ``s`` (e.g. into metres)."""
    c2w = {}
    for n, m in sfm.c2w.items():
        m = m.copy()
        m[:3, 3] *= s
        c2w[n] = m
    obs = {n: np.concatenate([o[:, :2], o[:, 2:] * s], axis=1) for n, o in sfm.observations.items()}
    return SfmResult(c2w, obs, sfm.points * s, sfm.scale * s, sfm.mean_reprojection_error, sfm.pair_counts)
