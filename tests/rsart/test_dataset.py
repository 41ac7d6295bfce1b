"""rsart.load(): laziness, exploration, torch dataset, nerfstudio export."""
import json

import numpy as np
import pytest

import rsart
from rsart.camera import Intrinsics, look_at
from rsart.format import CamerasFile, DatasetIndex, ViewRecord, write_cameras, write_index
from rsart.io import write_depth_png, write_mask_png, write_png_rgb

pytestmark = pytest.mark.core  # runs on the core install alone (.ci/core)


def add_views(obj_dir, state="m0", n=4, w=32, h=24):
    """Write n small synthetic views (real PNG files) for a state."""
    sdir = obj_dir / "states" / state
    rng = np.random.default_rng(0)
    views = []
    for i in range(n):
        vid = f"{i:04d}"
        write_png_rgb(sdir / "rgb" / f"{vid}.png", rng.integers(0, 255, (h, w, 3), dtype=np.uint8))
        write_depth_png(sdir / "depth" / f"{vid}.png", np.full((h, w), 0.5 + 0.1 * i, np.float32))
        write_mask_png(sdir / "mask" / f"{vid}.png", np.full((h, w), i % 3, np.uint8))
        c2w = look_at(np.array([1.0, 0, 0.5]) * (1 + i), np.zeros(3))
        views.append(ViewRecord(vid, c2w, "train" if i < n - 1 else "test"))
    write_cameras(CamerasFile(Intrinsics(w, h, 30.0, 30.0, (w - 1) / 2, (h - 1) / 2), 0.001, views),
                  sdir / "cameras.json")


def test_load_object_is_lazy(cabinet_dir, monkeypatch):
    add_views(cabinet_dir)
    calls = []
    import rsart.dataset as D
    for name in ("read_png_rgb", "read_depth_png", "read_mask_png"):
        orig = getattr(D, name)
        monkeypatch.setattr(D, name, lambda *a, _o=orig, _n=name, **k: calls.append(_n) or _o(*a, **k))
    obj = rsart.load(cabinet_dir)
    views = obj.states["m0"].views
    assert len(views) == 4 and views[3].split == "test"
    assert calls == []  # loading and listing views decodes nothing
    v = views[2]
    assert v.rgb.shape == (24, 32, 3) and calls == ["read_png_rgb"]
    _ = v.rgb
    assert calls == ["read_png_rgb"]  # cached
    assert v.depth.dtype == np.float32 and abs(float(v.depth[0, 0]) - 0.7) < 1e-6
    assert v.mask.max() == 2
    np.testing.assert_allclose(v.camera.w2c @ v.camera.c2w, np.eye(4), atol=1e-12)


def test_object_exploration(cabinet_dir):
    obj = rsart.load(cabinet_dir)
    assert obj.id == "cabinet-0000" and [p.name for p in obj.parts] == ["base", "lid", "drawer"]
    assert set(obj.states) >= {"m0", "m1", "m2", "m3", "s1max", "s2max"}
    assert obj.states["m1"].views == [] and not obj.states["m1"].captured
    assert obj.twin.joint("drawer_slide").limits == (0.0, 0.25)
    assert "cabinet-0000" in repr(obj)


def test_dataset_root(tmp_path, cabinet_dir):
    root = cabinet_dir.parent
    write_index(DatasetIndex("tiny", "1", ["cabinet-0000"], {"all": ["cabinet-0000"]}), root / "index.json")
    ds = rsart.load(root)
    assert len(ds) == 1 and ds["cabinet-0000"].category == "storage" and ds.split("all")[0].id == "cabinet-0000"
    with pytest.raises(KeyError, match="no split"):
        ds.split("nope")


def test_load_rejects_other_folders(tmp_path):
    with pytest.raises(rsart.RsartError, match="neither a dataset root"):
        rsart.load(tmp_path)
    with pytest.raises(rsart.RsartError, match="no such file or folder"):
        rsart.load(tmp_path / "missing")


def test_torch_dataset(cabinet_dir):
    torch = pytest.importorskip("torch")
    add_views(cabinet_dir, "m0")
    add_views(cabinet_dir, "m3")
    ds = rsart.load(cabinet_dir).torch_dataset(states=["m0", "m3"], split="train", size=(16, 12))
    assert len(ds) == 6
    item = ds[4]
    assert item["image"].shape == (12, 16, 3) and item["image"].dtype == torch.float32
    assert float(item["image"].max()) <= 1.0 and item["state_index"].item() == 1 and item["state_id"] == "m3"
    assert item["depth"].shape == (12, 16) and item["mask"].dtype == torch.int64
    K = item["K"].numpy()
    np.testing.assert_allclose(K[0, 0], 15.0) and np.testing.assert_allclose(K[0, 2], (15.5 + 0.5) * 0.5 - 0.5)
    loader = torch.utils.data.DataLoader(ds, batch_size=3)
    assert next(iter(loader))["image"].shape == (3, 12, 16, 3)


def test_export_nerfstudio(cabinet_dir, tmp_path):
    add_views(cabinet_dir, "m0")
    obj = rsart.load(cabinet_dir)
    [path] = obj.export_nerfstudio(tmp_path / "ns")
    tf = json.loads(path.read_text())
    assert tf["cx"] == pytest.approx(15.5 + 0.5) and len(tf["frames"]) == 4
    assert tf["train_filenames"] == ["images/0000.png", "images/0001.png", "images/0002.png"]
    assert tf["test_filenames"] == tf["val_filenames"] == ["images/0003.png"]
    fr = tf["frames"][1]
    assert (path.parent / fr["file_path"]).read_bytes() == (cabinet_dir / "states/m0/rgb/0001.png").read_bytes()
    gl = np.array(fr["transform_matrix"])
    cv = obj.states["m0"].views[1].camera.c2w
    # OpenGL camera looks down -z: its -z axis equals OpenCV's +z axis; y flips
    np.testing.assert_allclose(-gl[:3, 2], cv[:3, 2], atol=1e-12)
    np.testing.assert_allclose(-gl[:3, 1], cv[:3, 1], atol=1e-12)
    np.testing.assert_allclose(gl[:3, 3], cv[:3, 3])


def test_torch_dataset_says_what_exists(cabinet_dir):
    pytest.importorskip("torch")  # without it, torch_dataset says the [torch] extra is missing (test_extras)
    add_views(cabinet_dir, "m0")
    obj = rsart.load(cabinet_dir)
    with pytest.raises(rsart.RsartError, match=r"state 'm1' has no images \(captured states: m0\)"):
        obj.torch_dataset(states=["m0", "m1"])
    with pytest.raises(rsart.RsartError, match=r"no state 'zz' \(states: m0, m1"):
        obj.torch_dataset(states=["zz"])
    with pytest.raises(rsart.RsartError, match=r"no 'val' views \(splits: test, train\)"):
        obj.torch_dataset(split="val")
    assert [v.id for _, _, v in obj.torch_views(split="test")] == ["0003"]


def test_dataset_level_torch_loader(tmp_path):
    torch = pytest.importorskip("torch")
    from rsart.twin_io import write_object
    from tests.conftest import make_cabinet, make_lamp

    for oid, twin in (("cabinet-0000", make_cabinet()), ("lamp-0000", make_lamp())):
        write_object(twin, tmp_path / oid, object_id=oid, category=oid.split("-")[0], source={"kind": "procedural", "id": "t"})
        add_views(tmp_path / oid, "m0", n=3)
        add_views(tmp_path / oid, "m3", n=5)
    write_index(DatasetIndex("tiny", "1", ["cabinet-0000", "lamp-0000"], {"lamps": ["lamp-0000"]}), tmp_path / "index.json")
    ds = rsart.load(tmp_path)
    tds = ds.torch_dataset(states=["m0", "m3"], size=(16, 12))
    assert len(tds) == 2 * (2 + 4)
    items = [tds[i] for i in range(len(tds))]
    assert [it["object_id"] for it in items] == ["cabinet-0000"] * 6 + ["lamp-0000"] * 6
    assert items[7]["object_index"].item() == 1 and items[7]["state_id"] == "m0"
    batch = next(iter(torch.utils.data.DataLoader(tds, batch_size=12)))
    assert batch["image"].shape == (12, 12, 16, 3) and batch["object_index"].tolist() == [0] * 6 + [1] * 6
    assert len(ds.torch_dataset("lamps", split="test")) == 2
    with pytest.raises(rsart.RsartError, match=r"no split 'nope' \(splits: lamps\)"):
        ds.torch_dataset("nope")
    with pytest.raises(rsart.RsartError, match="no object"):
        ds.torch_dataset(["cabinet-0000", "ghost"])
    with pytest.raises(rsart.RsartError, match="cabinet-0000: state 'm1' has no images"):
        ds.torch_dataset(states=["m1"])
