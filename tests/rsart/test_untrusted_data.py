"""Hostile datasets and URDFs (issue 22), each built on the fly: a clean refusal naming the file (exit 2 and
one line from the CLI), nothing read outside the root, nothing left behind."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

import rsart
from rsart.camera import Intrinsics, look_at
from rsart.cli import main
from rsart.errors import Problem, RsartError, ValidationError
from rsart.format import CamerasFile, DatasetIndex, ViewRecord, write_cameras, write_index
from rsart.io import write_depth_png, write_mask_png, write_png_rgb
from rsart.render.inputs import object_dirs
from rsart.verify import verify, write_checksums

REPO = Path(__file__).resolve().parents[2]
W, H = 32, 24


def _cli(*args, timeout=120):
    """A real `rsart` process (bounded)."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return subprocess.run([sys.executable, "-m", "rsart", *map(str, args)], capture_output=True, text=True,
                          env=env, timeout=timeout)


def add_views(obj_dir: Path, state: str = "m0", n: int = 3) -> None:
    sdir = obj_dir / "states" / state
    views = []
    for i in range(n):
        vid = f"{i:04d}"
        write_png_rgb(sdir / "rgb" / f"{vid}.png", np.full((H, W, 3), 40 * i, np.uint8))
        write_depth_png(sdir / "depth" / f"{vid}.png", np.full((H, W), 0.5, np.float32))
        write_mask_png(sdir / "mask" / f"{vid}.png", np.ones((H, W), np.uint8))
        views.append(ViewRecord(vid, look_at(np.array([1.0 + i, 0, 0.5]), np.zeros(3)), "train"))
    write_cameras(CamerasFile(Intrinsics(W, H, 30.0, 30.0, (W - 1) / 2, (H - 1) / 2), 0.001, views),
                  sdir / "cameras.json")


def _one_line(text: str) -> str:
    lines = [ln for ln in text.splitlines() if ln.strip()]
    assert len(lines) == 1, text
    return lines[0]


# ----------------------------------------------------------------------------- images vs their camera
WRONG = {"rgb": lambda p: write_png_rgb(p, np.zeros((H + 6, W, 3), np.uint8)),
         "depth": lambda p: write_depth_png(p, np.full((H, W + 8), 0.5, np.float32)),
         "mask": lambda p: write_mask_png(p, np.ones((H // 2, W // 2), np.uint8))}


@pytest.mark.parametrize("kind", sorted(WRONG))
def test_wrong_size_image_is_refused_by_load_and_verify(kind, cabinet_dir):
    add_views(cabinet_dir)
    bad = cabinet_dir / "states" / "m0" / kind / "0002.png"
    WRONG[kind](bad)
    v = rsart.load(cabinet_dir).states["m0"].views
    assert getattr(v[1], kind).shape[:2] == (H, W)  # the others still load
    with pytest.raises(RsartError) as e:
        getattr(v[2], kind)
    msg = _one_line(str(e.value))
    assert msg.startswith(str(bad)) and f"is {W}x{H}" in msg, msg
    write_checksums(cabinet_dir)  # checksums match: only the size check can catch it
    rep = verify(cabinet_dir)
    assert [x.split(":")[0] for x in rep.wrong_size] == [f"states/m0/{kind}/0002.png"] and not rep.corrupt
    r = _cli("verify", cabinet_dir)
    assert r.returncode == 1 and f"wrong size: states/m0/{kind}/0002.png" in r.stdout, r.stdout + r.stderr


# ----------------------------------------------------------------------------- symlinks out of the root
@pytest.fixture
def secret(tmp_path) -> Path:
    """A real PNG outside every root, made unreadable (a non-root reader that opened it would fail)."""
    p = tmp_path / "outside" / "secret.png"
    write_png_rgb(p, np.zeros((H, W, 3), np.uint8))
    os.chmod(p, 0)
    yield p
    os.chmod(p, 0o600)


def test_symlinked_image_out_of_the_root_is_refused_unread(cabinet_dir, secret, tmp_path):
    add_views(cabinet_dir)
    write_checksums(cabinet_dir)
    rgb = cabinet_dir / "states" / "m0" / "rgb" / "0001.png"
    rgb.unlink()
    os.symlink(secret, rgb)
    with pytest.raises(RsartError, match="leads out of") as e:
        _ = rsart.load(cabinet_dir).states["m0"].views[1].rgb
    assert _one_line(str(e.value)).startswith(str(rgb))
    # a mask pointing at a FIFO: opening it would block, so a finished run proves it was never opened
    fifo = tmp_path / "outside" / "fifo"
    os.mkfifo(fifo)
    mask = cabinet_dir / "states" / "m0" / "mask" / "0000.png"
    mask.unlink()
    os.symlink(fifo, mask)
    code = ("import rsart, sys\ntry:\n    rsart.load(sys.argv[1]).states['m0'].views[0].mask\n"
            "except rsart.RsartError as e:\n    print(e)")
    r = subprocess.run([sys.executable, "-c", code, str(cabinet_dir)], capture_output=True, text=True,
                       env={**os.environ, "PYTHONPATH": str(REPO)}, timeout=60)  # bounded even if it opened it
    assert _one_line(r.stdout).startswith(f"{mask}: leads out of"), r.stdout + r.stderr
    r = _cli("verify", cabinet_dir, timeout=60)
    assert r.returncode == 2, r.stdout + r.stderr
    errs = r.stderr.splitlines()
    assert len(errs) == 2 and all(e.startswith("error: ") and "leads out of" in e for e in errs), r.stderr
    assert str(rgb) in r.stderr and str(mask) in r.stderr and "ok" not in r.stdout.split("(")[0]
    with pytest.raises(RsartError, match="leads out of"):  # nor are they hashed into a checksum file
        write_checksums(cabinet_dir)


def test_symlink_inside_the_root_is_allowed(cabinet_dir):
    add_views(cabinet_dir)
    rgb = cabinet_dir / "states" / "m0" / "rgb" / "0001.png"
    rgb.unlink()
    os.symlink("0000.png", rgb)  # relative, stays inside
    views = rsart.load(cabinet_dir).states["m0"].views
    np.testing.assert_array_equal(views[1].rgb, views[0].rgb)
    write_checksums(cabinet_dir)
    assert verify(cabinet_dir).ok


def test_state_folder_symlinked_out_is_never_listed(cabinet_dir, tmp_path):
    add_views(cabinet_dir)
    write_checksums(cabinet_dir)
    state = cabinet_dir / "states" / "m0"
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    os.replace(state, elsewhere / "m0")  # a complete, valid state folder, now outside the object
    os.symlink(elsewhere / "m0", state, target_is_directory=True)
    os.chmod(elsewhere / "m0", 0o111)  # not listable by a non-root reader
    try:
        st = rsart.load(cabinet_dir).states["m0"]
        with pytest.raises(RsartError, match="leads out of"):
            _ = st.views
        r = _cli("validate", cabinet_dir)
        assert r.returncode == 2, r.stdout + r.stderr
        line = _one_line(r.stderr)
        assert line.startswith(f"error: {state}: leads out of"), line
        r = _cli("verify", cabinet_dir)
        assert r.returncode == 2 and _one_line(r.stderr).startswith(f"error: {state}: leads out of"), r.stderr
        assert "missing: states/m0" not in r.stdout  # refused, not reported file by file
        with pytest.raises(RsartError, match="leads out of"):
            write_checksums(cabinet_dir)
    finally:
        os.chmod(elsewhere / "m0", 0o755)


def test_object_folder_symlinked_out_of_a_dataset(tmp_path, cabinet_dir):
    root = tmp_path / "ds"
    root.mkdir()
    os.symlink(cabinet_dir, root / "cabinet-0000", target_is_directory=True)
    write_index(DatasetIndex("tiny", "1", ["cabinet-0000"], {"all": ["cabinet-0000"]}), root / "index.json")
    ds = rsart.load(root)
    with pytest.raises(RsartError, match="leads out of"):
        ds["cabinet-0000"]
    r = _cli("validate", root)
    assert r.returncode == 2 and "leads out of" in _one_line(r.stderr), r.stderr
    with pytest.raises(RsartError, match="leads out of"):  # the renderer's inputs
        object_dirs(root, tmp_path / "render-out")
    assert not (tmp_path / "render-out").exists()


# ----------------------------------------------------------------------------- URDF meshes
LINK = '<link name="{n}"><visual><geometry><mesh filename="{m}"/></geometry></visual></link>'
JOINT = ('<joint name="j_{n}" type="revolute"><parent link="base"/><child link="{n}"/><axis xyz="0 0 1"/>'
         '<limit lower="0" upper="1"/></joint>')


def _urdf(folder: Path, links: dict[str, str | None]) -> Path:
    """A URDF with base + one revolute child per entry (mesh file, or None for no visual at all)."""
    folder.mkdir(parents=True, exist_ok=True)
    trimesh.creation.box(extents=(0.4, 0.4, 0.4)).export(folder / "base.obj")
    trimesh.creation.box(extents=(0.1, 0.1, 0.1)).export(folder / "box.obj")
    (folder / "text.obj").write_text("this is a text file, not a mesh\n")
    body = LINK.format(n="base", m="base.obj")
    for n, m in links.items():
        body += LINK.format(n=n, m=m) if m else f'<link name="{n}"/>'
        body += JOINT.format(n=n)
    p = folder / "robot.urdf"
    p.write_text(f'<robot name="r">{body}</robot>')
    return p


@pytest.mark.parametrize("links", [{"door": "text.obj"}, {"door": "text.obj", "lid": "box.obj"}],
                         ids=["one-movable", "two-movable"])
def test_text_mesh_link_is_an_error_naming_link_and_file(links, tmp_path, capsys):
    src = _urdf(tmp_path / "src", links)
    out = tmp_path / "out" / "obj"
    code = main(["convert", "urdf", str(src), "--out", str(out), "--resolution", "32", "-q"])
    err = _one_line(capsys.readouterr().err)
    assert code == 2
    assert err.startswith(f"error: {src}: link[door].visual[0]: ") and "text.obj" in err and "no triangles" in err
    assert "meta.json" not in err
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


def test_link_without_any_visual_is_a_helper_but_not_the_only_movable(tmp_path, capsys):
    src = _urdf(tmp_path / "src", {"hinge": None})
    out = tmp_path / "out" / "obj"
    code = main(["convert", "urdf", str(src), "--out", str(out), "--resolution", "32", "-q"])
    err = _one_line(capsys.readouterr().err)
    assert code == 2 and err.startswith(f"error: {src}: no movable part") and ".partial" not in err, err
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


def test_deep_nesting_urdf_prints_one_error_only(tmp_path):
    d = 300
    p = tmp_path / "deep.urdf"
    p.write_text('<robot name="r"><link name="base"/>' + "<a>" * d + "</a>" * d + "</robot>")
    r = _cli("convert", "urdf", p, "--out", tmp_path / "out", timeout=120)
    assert r.returncode == 2
    line = _one_line(r.stderr)
    assert line.startswith(f"error: {p}: ") and "depth" in line and "Traceback" not in r.stderr
    assert "Using different parsing approach" not in r.stderr and not (tmp_path / "out").exists()


# ----------------------------------------------------------------------------- control characters
def test_control_characters_are_escaped_in_error_text(tmp_path, capsys):
    assert str(RsartError("part 'a\nb\x00c\x1b[31m'")) == "part 'a\\nb\\x00c\\x1b[31m'"
    one = ValidationError([Problem("parts[1].name", "bad\nerror: forged")], source="x\r.json")
    assert str(one) == "x\\r.json: parts[1].name: bad\\nerror: forged"  # one problem: one line
    two = ValidationError([Problem("a", "p\n1"), Problem("b\x00", "p2")], source="f.json")
    assert str(two).splitlines() == ["f.json: 2 problems found", "  - a: p\\n1", "  - b\\x00: p2"]
    # a real process: a URDF link name with a newline (XML character reference) and an empty mesh
    src = _urdf(tmp_path / "src", {"door": "text.obj"})
    src.write_text(src.read_text().replace('"door"', '"door&#10;error: forged&#9;"'))
    r = _cli("convert", "urdf", src, "--out", tmp_path / "out")
    assert r.returncode == 2
    line = _one_line(r.stderr)
    assert "link[door\\nerror: forged\\t].visual[0]" in line and "text.obj" in line, line


def test_meta_with_control_characters_validates_on_one_line(cabinet_dir):
    meta = json.loads((cabinet_dir / "meta.json").read_text())
    meta["joints"][0]["axis"] = [0, 0, 0]
    meta["category"] = "x\ny"
    (cabinet_dir / "meta.json").write_text(json.dumps(meta))
    r = _cli("validate", cabinet_dir)
    assert r.returncode == 2
    line = _one_line(r.stderr)
    assert line.startswith(f"error: {cabinet_dir / 'meta.json'}: joints[0].axis: zero-length"), line


def test_rsart_eval_says_one_problem_on_one_line(capsys):
    from rsart.evaluation.cli import print_problems

    print_problems("sub.json", [Problem("results.a\nb.parts", "unknown object")])
    assert capsys.readouterr().err == "error: sub.json: invalid submission: results.a\\nb.parts: unknown object\n"
    print_problems("sub.json", [Problem("a", "x"), Problem("b", "y")])
    assert capsys.readouterr().err.splitlines() == [
        "error: sub.json: invalid submission: 2 problems found", "  - a: x", "  - b: y"]
