"""Procedural twins on disk (issue 3): object folders, URDF/USD round trips, MuJoCo, determinism, the suite, CLI."""
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import cKDTree

from rsart.cli import main as cli_main
from rsart.format import read_index, read_meta, validate_path
from rsart.mujoco_check import mujoco_pose_error
from rsart.sources.procedural import CATEGORIES, generate
from rsart.sources.procedural.suite import SuiteItem, suite_items, write_generated, write_suite
from rsart.twin_io import read_twin
from rsart.urdf import read_urdf
from rsart.verify import verify

usd = pytest.importorskip("rsart.usd")
REPO = Path(__file__).resolve().parents[3]


def nn_gap(a: np.ndarray, b: np.ndarray) -> float:
    """Symmetric max nearest-neighbour distance between two point sets (m)."""
    return max(float(cKDTree(b).query(a)[0].max()), float(cKDTree(a).query(b)[0].max()))


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    root = tmp_path_factory.mktemp("procedural")
    out = {}
    for cat in CATEGORIES:
        g = generate(cat, 1)
        write_generated(g, root / g.object_id)
        out[cat] = (g, root / g.object_id)
    return out


@pytest.mark.parametrize("cat", list(CATEGORIES))
def test_object_folder_is_complete_and_valid(written, cat):
    g, d = written[cat]
    assert validate_path(d) == []
    meta = read_meta(d / "meta.json")
    assert meta.category == cat and meta.object_id == g.object_id and meta.units == "m"
    assert meta.source["kind"] == "procedural" and meta.source["id"] == f"{cat}:1"
    assert meta.source["generator"] == "rsart.sources.procedural" and meta.source["version"]
    assert [s.id for s in meta.states][:4] == ["m0", "m1", "m2", "m3"]
    assert meta.eval_states == {"start": "m0", "end": "m3"}
    assert {s.kind for s in meta.states} == {"multi", "single"}
    for f in (meta.twin["urdf"], meta.twin["usd"], *[p.mesh for p in meta.parts]):
        assert (d / f).is_file(), f
    assert list((d / "twin" / "visual").glob("*.png")), "textures stored with the twin"
    back = read_twin(d)
    for p, q in zip(g.twin.parts, back.parts):
        assert q.mesh.is_watertight
        assert np.allclose(p.mesh.vertices, q.mesh.vertices, atol=1e-9)


@pytest.mark.parametrize("cat", list(CATEGORIES))
def test_urdf_and_usd_round_trip_the_posed_twin(written, cat):
    g, d = written[cat]
    meta = read_meta(d / "meta.json")
    from_urdf = read_urdf(d / "twin" / "object.urdf")
    from_usd = usd.read_usd(d / "twin" / "object.usda")
    for other in (from_urdf, from_usd):
        assert [j.name for j in other.joints] == [j.name for j in g.twin.joints]
        for j, k in zip(g.twin.joints, other.joints):
            assert j.type == k.type and np.allclose(j.axis, k.axis, atol=1e-9)
            assert np.allclose(j.limits, k.limits, atol=1e-9)
    # the URDF references the textured visuals; the USD carries the watertight geometry as each part's mesh
    for s in meta.states:
        visuals = g.twin.posed_visuals(s.values)
        geometry = g.twin.posed_meshes(s.values)
        got_urdf, got_usd = from_urdf.posed_meshes(s.values), from_usd.posed_meshes(s.values)
        for i, p in enumerate(g.twin.parts):
            ref = np.concatenate([m.vertices for m in visuals[i]])
            assert nn_gap(ref, got_urdf[i].vertices) < 1e-6, f"URDF {p.name} at {s.id}"
            assert nn_gap(geometry[i].vertices, got_usd[i].vertices) < 1e-6, f"USD {p.name} at {s.id}"


@pytest.mark.parametrize("cat", list(CATEGORIES))
def test_mujoco_loads_the_urdf_and_agrees(written, cat):
    g, d = written[cat]
    for s in read_meta(d / "meta.json").states:
        assert mujoco_pose_error(g.twin, d / "twin" / "object.urdf", s.values) < 1e-6


def _files(d: Path) -> dict[str, bytes]:
    return {p.relative_to(d).as_posix(): p.read_bytes() for p in sorted(d.rglob("*")) if p.is_file()}


def test_same_seed_byte_identical_files_across_processes(tmp_path):
    g = generate("woven_basket", 2)
    write_generated(g, tmp_path / "a" / g.object_id)
    # a fresh interpreter (other hash seed) through the CLI
    env_cmd = [sys.executable, "-m", "rsart", "generate", "--category", "woven_basket", "--seed", "2",
               "--out", str(tmp_path / "b")]
    r = subprocess.run(env_cmd, cwd=REPO, capture_output=True, text=True, env={"PYTHONHASHSEED": "123",
                                                                                 "PATH": "/usr/bin:/bin"})
    assert r.returncode == 0, r.stderr
    a, b = _files(tmp_path / "a" / g.object_id), _files(tmp_path / "b" / g.object_id)
    assert a.keys() == b.keys()
    for k in a:
        if k.endswith((".json", ".ply", ".obj", ".png", ".urdf", ".mtl")):
            assert a[k] == b[k], k


def test_small_suite_index_splits_and_checksums(tmp_path):
    items = [SuiteItem("drawer", 0), SuiteItem("refrigerator", 0), SuiteItem("oven", 2), SuiteItem("table", 0, 5)]
    index = write_suite(tmp_path / "synth", workers=2, items=items)
    assert index.objects == ["drawer-0000", "refrigerator-0000", "oven-0002", "table-5p-0000"]
    back = read_index(tmp_path / "synth")
    assert back.name == "rsart-synth" and back.objects == index.objects
    assert back.splits["rs-art-like"] == ["drawer-0000"]
    assert back.splits["partnet-like"] == ["refrigerator-0000", "oven-0002"]
    assert back.splits["five-part"] == ["table-5p-0000"]
    assert back.splits["three-part"] == ["oven-0002"]
    assert set(back.splits["multi-part"]) == {"oven-0002", "table-5p-0000"} | (
        {"drawer-0000"} if back.extra["movable_parts"]["drawer-0000"] >= 3 else set())
    assert verify(tmp_path / "synth").ok
    assert validate_path(tmp_path / "synth") == []
    (tmp_path / "synth" / "drawer-0000" / "meta.json").write_text("{}")
    assert not verify(tmp_path / "synth").ok


def test_suite_composition_mirrors_the_paper():
    items = suite_items()
    assert len(items) == 46
    cats = {it.category for it in items}
    assert cats == set(CATEGORIES)
    movable = [len(generate(it.category, it.seed, it.movable).twin.parts) - 1 for it in items
               if CATEGORIES[it.category].family == "partnet-like" and it.movable is None]
    assert len(movable) == 24 and movable.count(3) == 4 and movable.count(2) == 20
    assert sum(1 for it in items if it.movable == 5) == 4


def test_cli_generate_and_show(tmp_path, capsys):
    assert cli_main(["generate", "--category", "stand", "--seed", "3", "--count", "2", "--out", str(tmp_path)]) == 0
    assert (tmp_path / "stand-0003" / "meta.json").is_file() and (tmp_path / "stand-0004" / "meta.json").is_file()
    assert cli_main(["show", str(tmp_path / "stand-0003"), "--out", str(tmp_path / "o.png"), "--states", "m0,m3"]) == 0
    assert (tmp_path / "o.png").stat().st_size > 10000
    # existing output is refused without --overwrite; bad input exits 2 without a traceback
    assert cli_main(["generate", "--category", "stand", "--seed", "3", "--out", str(tmp_path)]) == 2
    assert cli_main(["generate", "--category", "stand", "--movable", "9", "--out", str(tmp_path)]) == 2
    assert cli_main(["show", str(tmp_path / "nothing"), "--out", str(tmp_path / "x.png")]) == 2
    assert cli_main(["show", str(tmp_path / "stand-0003"), "--out", str(tmp_path / "x.png"), "--states", "zz"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "error:" in err
