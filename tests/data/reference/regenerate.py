"""Rebuild the pinned reference set and its expected scores (run only for an intended metric change).

    python tests/data/reference/regenerate.py                   # rescore; rewrite expected_scores.json
    python tests/data/reference/regenerate.py --data --gt --perturbed --pd2gs-from OUT_A,OUT_B

The reference set (see README.md here): two procedural objects (generator rsart.sources.procedural
version 1, seed 0, one movable part: a prismatic drawer and a revolute box lid), only what scoring needs
(meta.json + twin/parts/*.ply), and three submissions: the ground truth, a perturbed ground truth and a
PD²GS output. expected_scores.json holds every per-object number of scores.json (section ``objects``),
each with its tolerance: Chamfer numbers get the spread of their per-seed values (the standard error of
the 3-seed mean, see :func:`chamfer_tolerance`), every other number 1e-9.
"""
from __future__ import annotations

import argparse
import json
import math
import shutil
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parents[2]))  # run from anywhere: the repository's rsart

from rsart.evaluation.cli import main as rsart_eval  # noqa: E402
from rsart.evaluation.version import SCORER_VERSION  # noqa: E402
from rsart.io import write_json  # noqa: E402
from rsart.metrics.chamfer import ChamferConfig  # noqa: E402

DATA = HERE / "data"
SUBMISSIONS = HERE / "submissions"
EXPECTED = HERE / "expected_scores.json"
OBJECTS = [("drawer", 0, 1), ("box", 0, 1)]     # (category, seed, movable parts)
PERTURB = "axis=5deg,pivot=0.02,motion=3deg,travel=0.01,seed=0"
JOINT_TOL = 1e-9
PD2GS_MAX_FACES = 2000                           # decimate PD²GS meshes above this (keeps the set small)


def write_data() -> None:
    """Generate the objects and keep what scoring reads: meta.json and the part meshes."""
    from rsart.sources.procedural import generate
    from rsart.sources.procedural.suite import write_generated

    shutil.rmtree(DATA, ignore_errors=True)
    DATA.mkdir(parents=True)
    ids = []
    with tempfile.TemporaryDirectory() as tmp:
        for cat, seed, movable in OBJECTS:
            g = generate(cat, seed, movable=movable)
            write_generated(g, Path(tmp) / g.object_id)
            src, dst = Path(tmp) / g.object_id, DATA / g.object_id
            (dst / "twin" / "parts").mkdir(parents=True)
            shutil.copy2(src / "meta.json", dst / "meta.json")
            for ply in sorted((src / "twin" / "parts").glob("*.ply")):
                shutil.copy2(ply, dst / "twin" / "parts" / ply.name)
            ids.append(g.object_id)
    write_json(DATA / "index.json", {"format": "rsart/1", "name": "rsart-reference", "version": "1",
                                     "objects": ids, "splits": {"all": ids}})


def write_submission(name: str, perturb: str | None = None) -> None:
    out = SUBMISSIONS / name
    args = ["--make-gt-submission", "--data", str(DATA), "--out", str(out), "--overwrite"]
    if rsart_eval(args + (["--perturb", perturb] if perturb else [])) != 0:
        raise SystemExit(f"could not write the {name} submission")


def copy_pd2gs(outs: list[Path]) -> None:
    """Merge `pd2gs run` outputs (one per object) into one submission; decimate large meshes."""
    import trimesh

    dst = SUBMISSIONS / "pd2gs"
    shutil.rmtree(dst, ignore_errors=True)
    dst.mkdir(parents=True)
    merged = None
    for out in outs:
        sub_dir = Path(out) / "submission"
        doc = json.loads((sub_dir / "submission.json").read_text())
        for oid, res in doc["results"].items():
            for path in _mesh_paths(res):
                mesh = trimesh.load(sub_dir / path, force="mesh", process=False)
                if len(mesh.faces) > PD2GS_MAX_FACES:
                    mesh = mesh.simplify_quadric_decimation(face_count=PD2GS_MAX_FACES)
                (dst / path).parent.mkdir(parents=True, exist_ok=True)
                mesh.export(dst / path)
        if merged is None:
            merged = doc
        else:
            merged["results"].update(doc["results"])
    merged["dataset"] = {"name": "rsart-reference", "version": "1"}
    write_json(dst / "submission.json", merged)


def _mesh_paths(res: dict | None) -> list[str]:
    if not res:
        return []
    paths = [p for part in res.get("parts", {}).values() for p in part.get("meshes", {}).values()]
    return paths + list((res.get("whole") or {}).values())


def score(name: str, seeds: tuple[int, ...] | None = None, out: Path | None = None) -> dict:
    """scores.json of submission ``name`` with the default settings (or only ``seeds``)."""
    with tempfile.TemporaryDirectory() as tmp:
        out = out or Path(tmp)
        args = [str(SUBMISSIONS / name / "submission.json"), "--data", str(DATA), "--out", str(out), "--workers", "1"]
        if seeds is not None:
            args += ["--chamfer-seeds", ",".join(map(str, seeds))]
        if rsart_eval(args) != 0:
            raise SystemExit(f"scoring {name} failed")
        return json.loads((out / "scores.json").read_text())


def numbers(doc, prefix: str = "") -> dict[str, float]:
    """Every number of a JSON tree by its path (``drawer-1p-0000/parts/1/metrics/cd_m``); bools excluded."""
    out: dict[str, float] = {}
    if isinstance(doc, dict):
        for k, v in doc.items():
            out.update(numbers(v, f"{prefix}/{k}" if prefix else str(k)))
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            out.update(numbers(v, f"{prefix}[{i}]"))
    elif isinstance(doc, (int, float)) and not isinstance(doc, bool):
        out[prefix] = float(doc)
    return out


def is_chamfer(path: str) -> bool:
    return any(part.startswith(("cd_", "chamfer")) for part in path.replace("[", "/").split("/"))


def chamfer_tolerance(per_seed: list[float]) -> float:
    """The standard error of the mean of the per-seed values: std (ddof 1) / sqrt(n seeds), at least 1e-9."""
    n = len(per_seed)
    mean = sum(per_seed) / n
    sd = math.sqrt(sum((x - mean) ** 2 for x in per_seed) / (n - 1))
    return max(sd / math.sqrt(n), JOINT_TOL)


def expected_scores() -> dict:
    seeds = ChamferConfig().seeds
    subs = {}
    for name in ("gt", "perturbed", "pd2gs"):
        full = numbers(score(name)["objects"])
        single = [numbers(score(name, seeds=(s,))["objects"]) for s in seeds]
        subs[name] = {path: {"value": v, "tol": chamfer_tolerance([d[path] for d in single]) if is_chamfer(path)
                             and all(path in d for d in single) else JOINT_TOL}
                      for path, v in sorted(full.items())}
    return {"scorer_version": SCORER_VERSION, "chamfer": ChamferConfig().to_dict(), "submissions": subs}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", action="store_true", help="regenerate the dataset")
    ap.add_argument("--gt", action="store_true", help="rewrite the ground-truth submission")
    ap.add_argument("--perturbed", action="store_true", help="rewrite the perturbed submission")
    ap.add_argument("--pd2gs-from", default=None, help="comma list of `pd2gs run` output folders to copy")
    a = ap.parse_args()
    if a.data:
        write_data()
    if a.gt:
        write_submission("gt")
    if a.perturbed:
        write_submission("perturbed", PERTURB)
    if a.pd2gs_from:
        copy_pd2gs([Path(p) for p in a.pd2gs_from.split(",")])
    write_json(EXPECTED, expected_scores())
    print(f"wrote {EXPECTED}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
