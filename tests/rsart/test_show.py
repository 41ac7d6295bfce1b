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


def _colour_pixels(img: np.ndarray, hex_colour: str, tol: int = 12) -> np.ndarray:
    rgb = np.array([int(hex_colour[i:i + 2], 16) for i in (1, 3, 5)])
    return (np.abs(img.astype(int) - rgb).max(axis=2) <= tol)


def test_view_faces_the_side_the_parts_move_to(cabinet):
    """The cabinet's drawer slides to +x and its lid is hinged at the back (-x) edge: both say the front is +x,
    so the camera sits 30° beside +x. Turning the whole object turns the view with it."""
    from rsart.show import choose_view

    elev, azim = choose_view(cabinet)
    assert azim == pytest.approx(30.0, abs=1.0) and elev == 35.0  # a lid: looked at from a little higher
    # the same object rotated 90° about z: the view follows (front now +y)
    import math

    from rsart.kinematics import Twin, TwinPart
    from rsart.format import Joint
    R = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    T = np.eye(4)
    T[:3, :3] = R
    parts = [TwinPart(p.index, p.name, p.mesh.copy().apply_transform(T)) for p in cabinet.parts]
    joints = [Joint(j.name, j.type, j.parent, j.child, R @ j.axis, R @ j.origin, j.limits) for j in cabinet.joints]
    assert choose_view(Twin("turned", parts, joints))[1] == pytest.approx(120.0, abs=1.0)
    assert math.isfinite(choose_view(cabinet, {"lid_hinge": 0.0, "drawer_slide": 0.0})[1])


def test_axes_are_drawn_on_top_and_the_legend_names_every_part(cabinet, tmp_path):
    from rsart.show import AXIS_STYLE, PART_COLORS, show_twin

    out = show_twin(cabinet, tmp_path / "c.png", states=["m0"], dpi=80)
    img = np.asarray(Image.open(out).convert("RGB"))
    # at rest the drawer is inside the body: its prismatic axis starts at the drawer's centre, inside the
    # mesh, and must still show (drawn after the meshes, with a white outline)
    assert _colour_pixels(img, AXIS_STYLE["prismatic"]["color"]).sum() > 30
    assert _colour_pixels(img, AXIS_STYLE["revolute"]["color"]).sum() > 30
    # legend patches: flat (unshaded) part colours in the bottom strip, one per part
    legend = img[int(img.shape[0] * 0.8):]
    for c in PART_COLORS[:3]:
        assert _colour_pixels(legend, c, tol=3).sum() > 20, c


def test_title_counts_in_the_singular_and_sits_above_one_row(tmp_path):
    from rsart.show import _plural, show_twin

    assert _plural(1, "movable part") == "1 movable part" and _plural(2, "joint") == "2 joints"
    g = generate("drawer", 0, 1)
    assert len(g.twin.parts) == 2
    out = show_twin(g.twin, tmp_path / "one.png", states=["m0", "m1", "m2", "m3"], dpi=80)  # one row of 4
    img = np.asarray(Image.open(out).convert("L"))
    ink = (img < 128).any(axis=1)
    top = int(np.argmax(ink))
    band = top + int(np.argmax(~ink[top:]))          # the first line of text: the sheet title only
    w = img.shape[1]
    first_line = img[top:band] < 128
    # the panel titles ("m0" at 1/8 of the width, "m3" at 7/8) are not on the title's line
    assert not first_line[:, : int(0.3 * w)].any() and not first_line[:, int(0.7 * w):].any()
    assert (img[band:band + 60] < 128)[:, : int(0.3 * w)].any()  # ... but just below it
