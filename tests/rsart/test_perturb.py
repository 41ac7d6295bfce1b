"""rsart perturb: Gaussian camera-pose noise with the stated statistics, reproducible, recorded, validated."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rsart.camera import look_at
from rsart.cli import main
from rsart.errors import RsartError
from rsart.format import CamerasFile, ViewRecord, read_cameras, read_meta, write_cameras
from rsart.perturb import perturb_object

N = 800


@pytest.fixture
def captured(cabinet_dir):
    """The cabinet object folder with two states of N cameras on a circle (cameras.json only)."""
    from rsart.camera import REALSENSE_D435_COLOR_640x480

    meta = read_meta(cabinet_dir)
    for s in meta.states[:2]:
        views = []
        for i in range(N):
            a = 2 * np.pi * i / N
            eye = np.array([np.cos(a), np.sin(a), 0.6])
            views.append(ViewRecord(f"{i:04d}", look_at(eye, np.zeros(3)), "train"))
        write_cameras(CamerasFile(REALSENSE_D435_COLOR_640x480, 0.001, views), cabinet_dir / "states" / s.id / "cameras.json")
    return cabinet_dir


def deltas(src, out, sid):
    a = read_cameras(src / "states" / sid / "cameras.json").views
    b = read_cameras(out / "states" / sid / "cameras.json").views
    rv = np.array([Rotation.from_matrix(x.c2w[:3, :3].T @ y.c2w[:3, :3]).as_rotvec() for x, y in zip(a, b)])
    dt = np.array([y.c2w[:3, 3] - x.c2w[:3, 3] for x, y in zip(a, b)])
    return np.degrees(rv), dt


@pytest.mark.parametrize("rot,trans", [(1.0, 0.02), (3.0, 0.05)])
def test_noise_statistics(captured, tmp_path, rot, trans):
    out = tmp_path / "copy"
    perturb_object(captured, out, rot, trans, seed=0)
    sid = read_meta(captured).states[0].id
    rv, dt = deltas(captured, out, sid)
    # camera-frame rotation vectors: per-axis sigma = rot degrees, zero mean; centres: per-axis sigma = trans
    assert np.allclose(rv.std(axis=0), rot, rtol=0.1) and np.allclose(rv.mean(axis=0), 0, atol=4 * rot / np.sqrt(N))
    assert np.allclose(dt.std(axis=0), trans, rtol=0.1) and np.allclose(dt.mean(axis=0), 0, atol=4 * trans / np.sqrt(N))
    rec = read_meta(out).extra["camera_poses"]
    assert rec["rot_deg"] == rot and rec["trans"] == trans and rec["source"] == "gt"
    assert read_cameras(out / "states" / sid / "cameras.json").extra["pose_perturbation"]["seed"] == 0
    assert (out / "twin" / "object.urdf").is_file()  # everything else is copied
    assert read_meta(captured).extra.get("camera_poses") is None  # the source is untouched


def test_reproducible_and_seeded(captured, tmp_path):
    perturb_object(captured, tmp_path / "a", 1.0, 0.02, seed=3)
    perturb_object(captured, tmp_path / "b", 1.0, 0.02, seed=3)
    perturb_object(captured, tmp_path / "c", 1.0, 0.02, seed=4)
    sid = read_meta(captured).states[1].id
    ca, cb, cc = (read_cameras(tmp_path / x / "states" / sid / "cameras.json").views[5].c2w for x in "abc")
    assert np.array_equal(ca, cb) and not np.allclose(ca, cc)


def test_zero_noise_is_identity(captured, tmp_path):
    perturb_object(captured, tmp_path / "z", 0.0, 0.0)
    sid = read_meta(captured).states[0].id
    a = read_cameras(captured / "states" / sid / "cameras.json").views
    b = read_cameras(tmp_path / "z" / "states" / sid / "cameras.json").views
    assert all(np.array_equal(x.c2w, y.c2w) for x, y in zip(a, b))


def test_bad_input(captured, tmp_path, capsys):
    with pytest.raises(RsartError, match="rot-deg"):
        perturb_object(captured, tmp_path / "x", -1.0, 0.0)
    with pytest.raises(RsartError, match="outside"):
        perturb_object(captured, captured / "inner", 1.0, 0.0)
    with pytest.raises(RsartError, match="no meta.json"):
        perturb_object(tmp_path, tmp_path / "y", 1.0, 0.0)
    perturb_object(captured, tmp_path / "once", 1.0, 0.0)
    with pytest.raises(RsartError, match="already exists"):
        perturb_object(captured, tmp_path / "once", 1.0, 0.0)
    assert main(["perturb-poses", str(captured), "--trans", "nan", "--out", str(tmp_path / "n")]) == 2
    assert "--trans" in capsys.readouterr().err
    assert main(["perturb-poses", str(captured), "--rot-deg", "1", "--trans", "0.02", "--out", str(tmp_path / "ok")]) == 0
    assert "deprecated" not in capsys.readouterr().err
    # the old name still works, with a warning that names the new one
    assert main(["perturb", str(captured), "--rot-deg", "1", "--out", str(tmp_path / "old")]) == 0
    err = capsys.readouterr().err
    assert "'rsart perturb' is deprecated" in err and "rsart perturb-poses" in err


def test_uncaptured_object_is_refused(cabinet_dir, tmp_path):
    with pytest.raises(RsartError, match="no captured states"):
        perturb_object(cabinet_dir, tmp_path / "x", 1.0, 0.0)


def test_rsart_cli_does_not_import_capture_tools():
    import subprocess
    import sys

    # `rsart capture` is an entry-point plug-in (loaded by build_parser); importing rsart and its perturb
    # module must not pull capture_tools in (--poses colmap imports it lazily)
    code = ("import sys; import rsart.cli, rsart.cli.perturb, rsart.perturb; "
            "print('capture_tools' in sys.modules)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert r.stdout.strip() == "False"
