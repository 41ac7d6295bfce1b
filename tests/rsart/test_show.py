"""Twin contact sheets (rsart.show)."""
import numpy as np
import pytest
from PIL import Image

from rsart.errors import RsartError
from rsart.show import show_twin
from rsart.sources.procedural import generate
from rsart.sources.procedural.suite import write_generated


def test_show_twin_draws_every_state_in_part_colours(tmp_path):
    g = generate("refrigerator", 0)
    out = show_twin(g.twin, tmp_path / "sheet.png")
    img = np.asarray(Image.open(out).convert("RGB"))
    assert img.shape[0] > 300 and img.shape[1] > 600
    # not blank: dark/coloured pixels from meshes, and the red joint-axis arrows
    assert (img.sum(axis=2) < 600).mean() > 0.02
    red = (img[..., 0] > 180) & (img[..., 1] < 80) & (img[..., 2] < 80)
    assert red.sum() > 20


def test_show_object_folder_and_state_selection(tmp_path):
    g = generate("drawer", 2)
    write_generated(g, tmp_path / g.object_id)
    a = show_twin(tmp_path / g.object_id, tmp_path / "all.png")
    b = show_twin(tmp_path / g.object_id, tmp_path / "two.png", states=["m0", "m3"])
    wa, wb = Image.open(a).size[0], Image.open(b).size[0]
    assert wb < wa                                   # 2 panels vs 4 per row
    with pytest.raises(RsartError, match="unknown states"):
        show_twin(tmp_path / g.object_id, tmp_path / "x.png", states=["m9"])
    with pytest.raises(RsartError, match="not an object folder"):
        show_twin(tmp_path / "missing", tmp_path / "x.png")
