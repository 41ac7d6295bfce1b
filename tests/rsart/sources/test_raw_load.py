"""rsart.load() on raw sources (PartNet-Mobility folder, .urdf, .usda): converted once into a content-keyed
cache; round trips through the URDF/USD keep the object's identity; missing textures are said, not dropped."""
from __future__ import annotations

import shutil

import pytest

import rsart
import rsart.sources.partnet
from rsart.cli import main
from rsart.format import read_meta
from rsart.sources.urdf_twin import MissingTextureWarning


def test_load_raw_partnet_folder_converts_once(partnet_root, tmp_path, capfd):
    src = tmp_path / "148"
    shutil.copytree(partnet_root / "148", src)
    cache = tmp_path / "cache"
    obj = rsart.load(src, cache=cache)
    err = capfd.readouterr().err
    assert "converting partnet-mobility" in err and str(cache) in err and err.count("\n") <= 2
    assert obj.id == "pm-148" and obj.category == "Faucet" and obj.path.parent == cache
    assert [j.type for j in obj.joints] == ["revolute"] and len(obj.twin.parts) == 2
    assert obj.meta.source["kind"] == "partnet-mobility" and obj.meta.source["id"] == "148"
    before = (obj.path / "meta.json").stat().st_mtime_ns
    again = rsart.load(src, cache=cache)  # cached: no message, same folder, not rewritten
    assert again.path == obj.path and capfd.readouterr().err == ""
    assert (obj.path / "meta.json").stat().st_mtime_ns == before
    # an edited source converts again into a new entry
    urdf = src / "mobility.urdf"
    urdf.write_text(urdf.read_text().replace('<robot name="', '<robot name="edited_', 1))
    edited = rsart.load(src, cache=cache)
    assert edited.path != obj.path and "converting" in capfd.readouterr().err
    assert len(list(cache.iterdir())) == 2


def test_rsart_cache_env_sets_the_default(partnet_root, tmp_path, monkeypatch, capfd):
    monkeypatch.setenv("RSART_CACHE", str(tmp_path / "envcache"))
    obj = rsart.load(partnet_root / "148")  # the shared folder is only read
    assert obj.path.parent == tmp_path / "envcache"
    explicit = rsart.load(partnet_root / "148", cache=tmp_path / "explicit")
    assert explicit.path.parent == tmp_path / "explicit"


def test_raw_urdf_and_usd_keep_identity_and_provenance(partnet_root, tmp_path, capfd):
    """PartNet -> object folder -> its URDF and its USD loaded raw: same id, category and original source."""
    first = rsart.load(partnet_root / "148", cache=tmp_path / "c")
    for twin_file in ("object.urdf", "object.usda"):
        back = rsart.load(first.path / "twin" / twin_file, cache=tmp_path / "c2")
        assert back.id == "pm-148" and back.category == "Faucet" and back.meta.units == "scene"
        assert back.meta.source["kind"] == "partnet-mobility" and back.meta.source["id"] == "148"
        assert back.meta.source["converted_from"]["file"] == twin_file
        assert [j.name for j in back.joints] == [j.name for j in first.joints]


def test_load_refuses_other_files(tmp_path):
    f = tmp_path / "notes.txt"
    f.write_text("x")
    with pytest.raises(rsart.RsartError, match="neither a dataset root"):
        rsart.load(f)


def test_missing_texture_warns_once_and_is_recorded(partnet_root, tmp_path):
    src = tmp_path / "100676"
    shutil.copytree(partnet_root / "100676", src)
    images = sorted((src / "images").iterdir())
    assert images
    for im in images:
        im.unlink()
    with pytest.warns(MissingTextureWarning) as rec:
        meta = rsart.sources.partnet.convert_partnet(src, tmp_path / "out", watertight=_fast())
    assert len([w for w in rec if issubclass(w.category, MissingTextureWarning)]) == 1
    msg = str(rec[0].message)
    assert "100676" in msg and images[0].name in msg
    notes = read_meta(tmp_path / "out").extra["conversion_notes"]
    assert any("texture image(s) or material file(s)" in n and images[0].name in n for n in notes)
    assert meta.object_id == "pm-100676"


def test_textured_samples_keep_their_textures(partnet_root):
    """The five shared samples with texture images load with every image referenced by their materials."""
    from rsart.urdf import read_urdf

    for oid in ("100676", "148", "101940", "45213", "8867"):
        twin = read_urdf(partnet_root / oid / "mobility.urdf")
        assert not [p.extra.get("missing_textures") for p in twin.parts if p.extra.get("missing_textures")]
        textured = [m for p in twin.parts for m in p.visuals
                    if getattr(getattr(m.visual, "material", None), "image", None) is not None]
        assert textured, oid


def _fast():
    from rsart.sources.urdf_twin import WatertightConfig

    return WatertightConfig(resolution=32, part_resolution=16, chamfer_samples=0)


def test_convert_quiet_and_verbose(partnet_root, tmp_path, capsys):
    assert main(["convert", "partnet-mobility", str(partnet_root / "148"), "--out", str(tmp_path / "q"),
                 "--resolution", "32", "-q"]) == 0
    cap = capsys.readouterr()
    assert cap.err == "" and cap.out.count("\n") == 1 and "pm-148 [Faucet]" in cap.out
    assert main(["convert", "partnet-mobility", str(partnet_root / "148"), "--out", str(tmp_path / "v"),
                 "--resolution", "32", "-v"]) == 0
    cap = capsys.readouterr()
    lines = cap.err.strip().splitlines()
    assert len(lines) == 2 and lines[0].startswith("part base: ") and "faces" in lines[0] and "{" not in cap.err
    with pytest.raises(SystemExit) as e:
        main(["convert", "partnet-mobility", str(partnet_root / "148"), "--out", str(tmp_path / "x"), "-q", "-v"])
    assert e.value.code == 2 and "not allowed with" in capsys.readouterr().err


def test_empty_out_folder_is_accepted_non_empty_is_not(partnet_root, tmp_path, capsys):
    out = tmp_path / "o"
    out.mkdir()
    assert main(["convert", "partnet-mobility", str(partnet_root / "148"), "--out", str(out), "--resolution", "32",
                 "-q"]) == 0
    assert (out / "meta.json").is_file()
    usd_out = tmp_path / "u"
    usd_out.mkdir()
    assert main(["convert", "usd", str(out / "twin" / "object.usda"), "--out", str(usd_out), "-q"]) == 0
    assert read_meta(usd_out).object_id == "pm-148"
    capsys.readouterr()
    assert main(["convert", "usd", str(out / "twin" / "object.usda"), "--out", str(usd_out), "-q"]) == 2
    assert "not empty (pass overwrite" in capsys.readouterr().err


def test_converted_visuals_keep_textures(partnet_root, tmp_path):
    """The written twin/visual OBJs of a textured sample carry their texture images (what the renderer draws)."""
    from rsart.twin_io import read_twin

    assert main(["convert", "partnet-mobility", str(partnet_root / "148"), "--out", str(tmp_path / "o"),
                 "--resolution", "32", "-q"]) == 0
    twin = read_twin(tmp_path / "o")
    images = [m.visual.material.image for p in twin.parts for m in p.visuals
              if getattr(getattr(m.visual, "material", None), "image", None) is not None]
    assert len(images) == len(twin.parts) and all(min(im.size) >= 64 for im in images)
    files = [f for f in (tmp_path / "o" / "twin" / "visual").iterdir() if f.suffix in (".png", ".jpg", ".jpeg")]
    assert len(files) == len(twin.parts)


def test_cache_key_follows_what_the_source_uses(partnet_root, tmp_path):
    """URDF: the key covers the file, its meshes and their MTL/texture images, not unrelated files beside it.
    USD: every layer/asset it depends on."""
    from rsart.sources.cache import content_key

    src = tmp_path / "o"
    shutil.copytree(rsart.load(partnet_root / "148", cache=tmp_path / "c").path, src)
    urdf, usd = src / "twin" / "object.urdf", src / "twin" / "object.usda"
    k_urdf, k_usd = content_key(urdf, "urdf"), content_key(usd, "usd")
    (src / "twin" / "notes.txt").write_text("unrelated")
    (src / "twin" / "parts" / "extra.ply").write_bytes(b"not used by the URDF")
    assert content_key(urdf, "urdf") == k_urdf
    [img] = [p for p in (src / "twin" / "visual").iterdir() if p.name.startswith("base") and p.suffix != ".obj"
             and p.suffix != ".mtl"]
    img.write_bytes(img.read_bytes() + b"\0")  # an edited texture converts again
    assert content_key(urdf, "urdf") != k_urdf
    # the USD holds its meshes inline: an edited visual OBJ does not change its key, an edited USD texture does
    mesh = src / "twin" / "visual" / "switch_0.obj"
    mesh.write_text(mesh.read_text() + "\n# edited\n")
    assert content_key(usd, "usd") == k_usd
    [tex] = list((src / "twin" / "textures").glob("base*.png"))
    tex.write_bytes(tex.read_bytes() + b"\0")
    assert content_key(usd, "usd") != k_usd


def test_raw_load_without_open3d_names_the_extra(partnet_root, tmp_path):
    """Converting needs the [render] extra (open3d): without it, MissingExtra names the pip command."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    repo = Path(__file__).resolve().parents[3]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(repo / "tests" / "rsart" / "hide_extras"), str(repo)]),
               RSART_HIDE="open3d")
    code = ("import rsart, sys\ntry:\n    rsart.load(sys.argv[1], cache=sys.argv[2])\n"
            "except rsart.RsartError as e:\n    print(type(e).__name__, e)\n")
    p = subprocess.run([sys.executable, "-c", code, str(partnet_root / "148"), str(tmp_path / "c")],
                       capture_output=True, text=True, env=env, timeout=120)
    assert p.stdout.startswith("MissingExtra") and p.stdout.strip().endswith("pip install 'rsart[render]'"), p
    assert not (tmp_path / "c").exists()
