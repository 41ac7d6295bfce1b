"""``rsart render`` end to end: object folder contract, checksums, resume after a kill, settings guard."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from rsart.camera import Camera
from rsart.cli.render import main
from rsart.format import read_cameras, read_meta, validate_path
from rsart.io import read_depth_png, read_mask_png, read_png_rgb
from rsart.render.raycast import build_scene
from rsart.twin_io import read_twin, write_object
from rsart.verify import verify

REPO = Path(__file__).resolve().parents[3]
SMALL = ["--size", "160x120", "--no-progress"]


@pytest.fixture
def locker_dir(tmp_path, locker) -> Path:
    out = tmp_path / "src" / "locker-0000"
    write_object(locker, out, object_id="locker-0000", category="storage", source={"kind": "procedural", "id": "t"})
    return out


def _files(root: Path) -> dict[str, bytes]:
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def test_render_writes_a_valid_object_folder(locker_dir, tmp_path):
    out = tmp_path / "out"
    assert main([str(locker_dir), "--out", str(out), "--protocol", "two-state", "--views", "3", "--test-views", "1",
                 "--background", "plain", "--workers", "1", *SMALL]) == 0
    obj = out / "locker-0000"
    assert validate_path(out) == [] and verify(out).ok
    meta = read_meta(obj)
    assert sorted(p.name for p in (obj / "states").iterdir()) == ["m0", "m3"]
    twin = read_twin(obj, meta)
    for sid in ("m0", "m3"):
        cams = read_cameras(obj / "states" / sid / "cameras.json")
        assert [v.split for v in cams.views] == ["train"] * 3 + ["test"]
        scene = build_scene([[m] for m in twin.posed_meshes(meta.state(sid).values)])
        for i, v in enumerate(cams.views):
            depth = read_depth_png(obj / "states" / sid / "depth" / f"{v.id}.png", cams.depth_scale)
            mask = read_mask_png(obj / "states" / sid / "mask" / f"{v.id}.png")
            rgb = read_png_rgb(obj / "states" / sid / "rgb" / f"{v.id}.png")
            assert rgb.shape == (120, 160, 3) and mask.max() >= 1
            hits = scene.cast(Camera(cams.intrinsics, v.c2w))  # the stored camera reproduces the stored images
            assert np.array_equal(hits.part_mask(), mask)
            assert np.abs(depth - hits.depth)[mask > 0].max() <= 0.0005 + 1e-6  # 1 mm PNG quantisation
            assert np.all(depth[mask == 0] == 0)
    # the test views are the same in both states
    a, b = (read_cameras(obj / "states" / s / "cameras.json").views[-1].c2w for s in ("m0", "m3"))
    assert np.array_equal(a, b)


def test_unseen_states_are_added_to_the_output_meta_only(locker_dir, tmp_path):
    out = tmp_path / "out"
    assert main([str(locker_dir), "--out", str(out), "--protocol", "unseen", "--test-views", "1",
                 "--rgb-backend", "raycast", "--workers", "1", *SMALL]) == 0
    meta = read_meta(out / "locker-0000")
    added = [s for s in meta.states if s.extra.get("protocol") == "unseen"]
    assert [s.id for s in added] == ["u1of6", "u1of2", "u5of6"] and added[1].extra["fraction"] == 0.5
    assert not any(s.id.startswith("u") for s in read_meta(locker_dir).states)
    assert all(v.split == "test" for v in read_cameras(out / "locker-0000/states/u1of2/cameras.json").views)


def test_rerun_skips_finished_views_and_refuses_other_settings(locker_dir, tmp_path, capsys):
    out = tmp_path / "out"
    args = [str(locker_dir), "--out", str(out), "--views", "2", "--test-views", "0", "--rgb-backend", "raycast",
            "--workers", "1", *SMALL]
    assert main(args) == 0
    rgb = out / "locker-0000/states/m1/rgb/0001.png"
    stamp = rgb.stat().st_mtime_ns
    assert main(args) == 0 and rgb.stat().st_mtime_ns == stamp
    assert main([*args, "--seed", "7"]) == 2
    assert "states m0, m1, m2, m3 were already rendered with other settings (protocol pd2gs differs in seed)" \
        in capsys.readouterr().err
    assert main([*args, "--background", "plain"]) == 2  # same cameras, other images: also refused
    assert main([*args, "--seed", "7", "--overwrite"]) == 0 and verify(out).ok
    assert rgb.stat().st_mtime_ns != stamp


def test_protocols_share_a_folder_when_their_states_agree(locker_dir, tmp_path):
    out = tmp_path / "out"
    base = [str(locker_dir), "--out", str(out), "--test-views", "1", "--rgb-backend", "raycast", "--workers", "1",
            *SMALL]
    assert main([*base, "--protocol", "pd2gs", "--views", "2"]) == 0
    assert main([*base, "--protocol", "unseen"]) == 0  # training states + held-out states together
    states = sorted(p.name for p in (out / "locker-0000" / "states").iterdir())
    assert states == ["m0", "m1", "m2", "m3", "u1of2", "u1of6", "u5of6"]
    assert validate_path(out) == [] and verify(out).ok
    assert main([*base, "--protocol", "two-state", "--views", "2"]) == 2  # m0/m3 with other cameras


def test_bad_input_exits_2_without_traceback(tmp_path, capsys):
    assert main([str(tmp_path / "missing"), "--out", str(tmp_path / "o")]) == 2
    assert "no such file or folder" in capsys.readouterr().err
    assert main([str(tmp_path), "--out", str(tmp_path / "o"), "--size", "12"]) == 2
    assert "--size" in capsys.readouterr().err


def test_resume_after_kill_gives_the_same_files_as_an_uninterrupted_run(locker_dir, tmp_path):
    common = ["--protocol", "pd2gs", "--views", "14", "--test-views", "2", "--sensor", *SMALL]
    killed, clean = tmp_path / "killed", tmp_path / "clean"
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.Popen([sys.executable, "-m", "rsart.cli.render", str(locker_dir), "--out", str(killed),
                             "--workers", "1", *common], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 120
    while time.time() < deadline and len(list(killed.glob("locker-0000/states/*/rgb/*.png"))) < 6:
        assert proc.poll() is None, "the run finished before it could be killed"
        time.sleep(0.01)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    done = list(killed.glob("locker-0000/states/*/rgb/*.png"))
    assert 6 <= len(done) < 64, "kill landed mid-run"
    assert not (killed / "checksums.sha256").exists()
    # resume in a pool of two processes; the reference runs uninterrupted in this process
    assert main([str(locker_dir), "--out", str(killed), "--workers", "2", *common]) == 0
    assert main([str(locker_dir), "--out", str(clean), "--workers", "1", *common]) == 0
    a, b = _files(killed), _files(clean)
    assert sorted(a) == sorted(b) and not [k for k in a if k.endswith(".tmp")]
    # index.json names the dataset after its folder ("killed" / "clean"); everything else is byte-identical
    differ = [k for k in a if a[k] != b[k]]
    assert differ == ["checksums.sha256", "index.json"], differ
    strip = lambda text: [ln for ln in text.decode().splitlines() if not ln.endswith("  index.json")]
    assert strip(a["checksums.sha256"]) == strip(b["checksums.sha256"])
    assert len([k for k in a if "/rgb_clean/" in k]) == 64
