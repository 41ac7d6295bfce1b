"""Helpers for the baselines_adapters tests: scoring with rsart.evaluation, playing the methods."""
from __future__ import annotations

import shutil
from pathlib import Path


def score(submission: Path, object_dir: Path) -> dict:
    """rsart-eval's result dict of the one object (validation problems fail the test)."""
    from rsart.evaluation import load_ground_truth, read_submission, score_submission

    gt = load_ground_truth(object_dir)
    sub, problems = read_submission(submission, gt)
    assert not problems, problems
    res, problems = score_submission(sub, gt, workers=1)
    assert not problems, problems
    return next(iter(res.values()))


def copy_tree(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst)
    return dst


# ----------------------------------------------------------------------------- reading exports
import json  # noqa: E402
import math  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402
import trimesh  # noqa: E402

GL_FLIP = np.diag([1.0, -1.0, -1.0, 1.0])  # OpenGL <-> OpenCV camera axes, written out independently here


def read_json(p: Path):
    return json.loads(Path(p).read_text())


def read_rgba(p: Path) -> np.ndarray:
    img = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
    assert img is not None and img.shape[2] == 4, p
    return cv2.cvtColor(img, cv2.COLOR_BGRA2RGBA)


def load_ply(p: Path) -> trimesh.Trimesh:
    return trimesh.load(str(p), force="mesh", process=False)


def project_gl(points: np.ndarray, c2w_gl: np.ndarray, fx: float, fy: float, cx_edge: float, cy_edge: float):
    """Pixel indices (col, row) of world points seen by an OpenGL camera (y up, looking down -z), with a
    principal point in the pixel-edge convention (pixel centres at i + 0.5)."""
    w2c = np.linalg.inv(c2w_gl)
    pc = points @ w2c[:3, :3].T + w2c[:3, 3]
    z = -pc[:, 2]
    u = fx * pc[:, 0] / z + cx_edge
    v = -fy * pc[:, 1] / z + cy_edge
    return np.floor(u).astype(int), np.floor(v).astype(int)


def inside_fraction(points, c2w_gl, fx, fy, cx_edge, cy_edge, alpha: np.ndarray) -> float:
    """Fraction of points projecting onto the object's alpha, dilated by one pixel (ray-cast masks sample
    pixel centres, so thin edges a point falls on may be empty at 64x48)."""
    alpha = cv2.dilate((alpha > 0).astype(np.uint8), np.ones((3, 3), np.uint8))
    u, v = project_gl(points, c2w_gl, fx, fy, cx_edge, cy_edge)
    h, w = alpha.shape
    ok = (u >= 0) & (u < w) & (v >= 0) & (v < h)
    hits = np.zeros(len(u), bool)
    hits[ok] = alpha[v[ok], u[ok]] > 0
    return float(hits.mean())


def backproject_gl(depth_m: np.ndarray, c2w_gl: np.ndarray, fx: float, fy: float, cx_edge: float,
                   cy_edge: float) -> np.ndarray:
    """(N, 3) world points of the pixels with depth > 0, for an OpenGL camera (pixel centres at i + 0.5)."""
    v, u = np.nonzero(depth_m > 0)
    z = depth_m[v, u]
    x = (u + 0.5 - cx_edge) / fx * z
    y = -(v + 0.5 - cy_edge) / fy * z
    pc = np.stack([x, y, -z], axis=1)
    return pc @ c2w_gl[:3, :3].T + c2w_gl[:3, 3]


def distance_to_mesh(points: np.ndarray, mesh: trimesh.Trimesh) -> np.ndarray:
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(np.asarray(mesh.vertices, np.float32)),
                        o3d.core.Tensor(np.asarray(mesh.faces, np.uint32)))
    return scene.compute_distance(o3d.core.Tensor(np.asarray(points, np.float32))).numpy()


def rodrigues(axis, angle) -> np.ndarray:
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def tilt(axis, deg: float) -> np.ndarray:
    """``axis`` tilted by ``deg`` degrees about a fixed perpendicular direction."""
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    p = np.cross(a, [0.0, 0.0, 1.0] if abs(a[2]) < 0.9 else [1.0, 0.0, 0.0])
    return rodrigues(p, math.radians(deg)) @ a


def geodesic_deg_same_angle(delta: float, tilt_deg: float, extra: float = 0.0) -> float:
    """Closed form: angle between Rot(a2, delta + extra) and Rot(a, delta) with a2 at tilt_deg from a."""
    d2 = delta + extra
    c = math.cos(d2 / 2) * math.cos(delta / 2) + math.sin(d2 / 2) * math.sin(delta / 2) * math.cos(math.radians(tilt_deg))
    return math.degrees(2 * math.acos(min(1.0, abs(c))))


# ----------------------------------------------------------------------------- playing the methods
def _write_mesh(path: Path, mesh: trimesh.Trimesh) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    m = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    if path.suffix == ".obj":
        path.write_text(trimesh.exchange.obj.export_obj(m, include_normals=False))
    else:
        path.write_bytes(trimesh.exchange.ply.export_ply(m, encoding="binary"))


def _entries(trans: dict) -> list[dict]:
    ti = trans["trans_info"]
    return ti if isinstance(ti, list) else [ti]


def gt_motion(entry: dict, extra_angle_deg: float = 0.0, extra_travel: float = 0.0, tilt_deg: float = 0.0,
              flip: bool = False) -> tuple[str, np.ndarray, np.ndarray, float]:
    """(kind, axis d, origin o, amount) of a trans.json entry, amount in degrees (rotate) or units, perturbed."""
    kind = entry["type"]
    d = np.asarray(entry["axis"]["d"], float)
    o = np.asarray(entry["axis"]["o"], float)
    amount = entry[kind]["r"] - entry[kind]["l"]
    amount += extra_angle_deg if kind == "rotate" else extra_travel
    if tilt_deg:
        d = tilt(d, tilt_deg)
    if flip:
        d, amount = -d, -amount
    return kind, d, o, amount


def rigid_of(kind: str, d, o, amount) -> np.ndarray:
    M = np.eye(4)
    if kind == "rotate":
        R = rodrigues(d, math.radians(amount))
        M[:3, :3] = R
        M[:3, 3] = (np.eye(3) - R) @ o
    else:
        M[:3, 3] = amount * np.asarray(d) / np.linalg.norm(d)
    return M


def play_paris(export: Path, runs_root: Path, perturb: dict | None = None, articulatedgs: bool = False,
               flip: bool = False, skip: tuple[str, ...] = ()) -> Path:
    """Write what PARIS (or ArticulatedGS) would output for each joint run of ``export``, from its GT files
    (the method frame). ``perturb``: joint -> dict(extra_angle_deg=, extra_travel=, tilt_deg=)."""
    man = read_json(export / "rsart_export.json")
    for jn, info in man["runs"].items():
        if jn in skip:
            continue
        gt = export / info["folder"] / "gt"
        kind, d, o, amount = gt_motion(_entries(read_json(gt / "trans.json"))[0], flip=flip, **(perturb or {}).get(jn, {}))
        static, dyn0 = load_ply(gt / "start/start_static_rotate.ply"), load_ply(gt / "start/start_dynamic_rotate.ply")
        if articulatedgs:
            save = runs_root / jn / "output" / "run1"
            if kind == "rotate":
                m = {"type": "revolute", "axis": (3.0 * d).tolist(), "pivot": o.tolist(), "theta": math.radians(amount)}
            else:
                m = {"type": "prismatic", "axis": (2.0 * d).tolist(), "dist": float(amount)}
            (save).mkdir(parents=True, exist_ok=True)
            (save / "motion.json").write_text(json.dumps(m))
            _write_mesh(save / "static.ply", static)
            _write_mesh(save / "dynamic.ply", dyn0)
            continue
        save = runs_root / jn / "revolute" / "01@20260101-000000" / "save"
        if kind == "rotate":
            m = {"type": "rotate", "axis_o": o.tolist(), "axis_d": (d / np.linalg.norm(d)).tolist(),
                 "rot_angle": float(amount), "R": rodrigues(d, math.radians(amount)).tolist()}
        else:
            m = {"type": "translate", "axis_o": o.tolist(), "axis_d": (d / np.linalg.norm(d)).tolist(), "dist": float(amount)}
        save.mkdir(parents=True, exist_ok=True)
        (save / "it20000_test_motion.json").write_text(json.dumps(m))
        # an older, wrong iteration the importer must ignore
        (save / "it10000_test_motion.json").write_text(json.dumps({**m, "axis_d": [0.0, 0.0, 1.0]}))
        _write_mesh(save / "it20000_static_256_thre10.0.ply", static)
        _write_mesh(save / "it20000_dyn_t0_256_thre10.0.ply", dyn0)
        dyn1 = dyn0.copy()
        dyn1.apply_transform(rigid_of(kind, d, o, amount))
        _write_mesh(save / "it20000_dyn_t1_256_thre10.0.ply", dyn1)
    return runs_root


def play_dtart(export: Path, run: Path, perturb: dict | None = None) -> Path:
    """DTArt's results folder from the export's GT: parts k = 1..K in trans.json order."""
    gt = export / "gt"
    entries = _entries(read_json(gt / "trans.json"))
    res = run / "results" / "step_0004000"
    suffix = (lambda i: "") if len(entries) == 1 else (lambda i: f"_{i}")
    for key, pre in (("start", "init"), ("end", "last")):
        _write_mesh(res / f"{pre}_part_0.obj", load_ply(gt / f"{key}/{key}_static_rotate.ply"))
        _write_mesh(res / f"{pre}_all.obj", load_ply(gt / f"{key}/{key}_rotate.ply"))
        for i in range(len(entries)):
            _write_mesh(res / f"{pre}_part_{i + 1}.obj", load_ply(gt / f"{key}/{key}_dynamic{suffix(i)}_rotate.ply"))
    motions = []
    for i, e in enumerate(entries):
        kind, d, o, amount = gt_motion(e, **(perturb or {}).get(i, {}))
        M = rigid_of(kind, d, o, amount)
        motions.append({"axis_position": o.tolist(), "axis_direction": d.tolist(), "theta": float(amount),
                        "rotation": M[:3, :3].tolist(), "translation": M[:3, 3].tolist()})
    name = "init_motion.json" if len(entries) == 1 else f"init_p{''.join(map(str, range(len(entries))))}_motion.json"
    (res / name).write_text(json.dumps(motions))
    return run


def play_artgs(export: Path, run: Path, perturb: dict | None = None, retopologize: bool = False) -> Path:
    """ArtGS's render output from the export's GT; ``retopologize`` re-meshes the end-state meshes
    (independent reconstructions: no vertex correspondence)."""
    gt = export / "gt"
    entries = _entries(read_json(gt / "trans.json"))
    res = run / "train" / "ours_20000"
    suffix = (lambda i: "") if len(entries) == 1 else (lambda i: f"_{i}")
    info = [{"id": 0, "parent": -1, "name": "root", "joint": "heavy", "jointData": {}, "visuals": ["meshes/start_0.ply"]}]
    for key in ("start", "end"):
        _write_mesh(res / f"meshes/{key}_-1.ply", load_ply(gt / f"{key}/{key}_rotate.ply"))
        _write_mesh(res / f"meshes/{key}_0.ply", load_ply(gt / f"{key}/{key}_static_rotate.ply"))
    for i, e in enumerate(entries):
        p = (perturb or {}).get(i, {})
        kind, d, o, amount = gt_motion(e, tilt_deg=p.get("tilt_deg", 0.0))
        start = load_ply(gt / f"start/start_dynamic{suffix(i)}_rotate.ply")
        _write_mesh(res / f"meshes/start_{i + 1}.ply", start)
        if p.get("extra_angle_deg") or p.get("extra_travel"):
            kind_t, d_t, o_t, amount_t = gt_motion(e, extra_angle_deg=p.get("extra_angle_deg", 0.0),
                                                   extra_travel=p.get("extra_travel", 0.0))
            end = start.copy()
            end.apply_transform(rigid_of(kind_t, d_t, o_t, amount_t))
        else:
            end = load_ply(gt / f"end/end_dynamic{suffix(i)}_rotate.ply")
        if retopologize:
            v, f = trimesh.remesh.subdivide_to_size(end.vertices, end.faces, max_edge=0.03)
            end = trimesh.Trimesh(v, f, process=False)
        _write_mesh(res / f"meshes/end_{i + 1}.ply", end)
        info.append({"id": i + 1, "parent": 0, "name": f"joint_{i + 1}", "joint": "hinge" if kind == "rotate" else "slider",
                     "jointData": {"axis": {"origin": o.tolist() if kind == "rotate" else [0.0, 0.0, 0.0],
                                            "direction": d.tolist()}, "limit": {}},
                     "visuals": [f"meshes/start_{i + 1}.ply"]})
    (res / "joint_info.json").write_text(json.dumps(info))
    return run
