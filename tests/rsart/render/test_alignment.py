"""The pixel convention: RGB, depth and mask of one view line up to the pixel.

Proof used here: on a plain background whose colour no part has, the RGB silhouette (pixels that
differ from the background), the depth support (depth > 0) and the mask support (mask > 0) are the
same set of pixels, and the edges between parts in the mask are depth/colour edges too. A camera
offset of even half a pixel between rasteriser and ray caster flips many silhouette pixels.
"""
from __future__ import annotations

import numpy as np
import pytest

from rsart.render.frame import RenderOptions, StateRenderer
from rsart.render.paths import fit_radius, orbit_pose

BG = (255, 0, 255)


def _frames(twin, intr, backend, antialias=False, n=3):
    values = {"door_hinge": 1.1, "drawer_slide": 0.15}
    opts = RenderOptions(intrinsics=intr, background="plain", plain_colour=BG, rgb_backend=backend,
                         antialias=antialias, reconcile=False)  # the raw rasteriser output is what is tested
    b = twin.bounds(values)
    r = fit_radius(b, intr)
    sr = StateRenderer(twin, values, opts, b, r)
    try:
        return [sr.render(orbit_pose(b.mean(0), r, 0.4 + 2.1 * i, 0.6 + 0.15 * i), np.random.default_rng(i))
                for i in range(n)], sr.backend
    finally:
        sr.close()


def _silhouette(rgb):
    return np.any(rgb[..., :3] != np.array(BG, dtype=np.uint8), axis=-1)


def _boundary(mask):
    m = mask > 0
    edge = np.zeros_like(m)
    edge[:-1] |= m[:-1] != m[1:]
    edge[1:] |= m[:-1] != m[1:]
    edge[:, :-1] |= m[:, :-1] != m[:, 1:]
    edge[:, 1:] |= m[:, :-1] != m[:, 1:]
    return edge


@pytest.mark.parametrize("backend", ["raycast", "pyrender"])
def test_rgb_depth_mask_silhouettes_are_identical(locker, small_intrinsics, backend, request):
    if backend == "pyrender":
        request.getfixturevalue("gl_backend")
    frames, used = _frames(locker, small_intrinsics, backend)
    assert used.startswith(backend)
    for f in frames:
        obj = f.mask > 0
        assert 500 < obj.sum() < obj.size  # the object is in view and does not fill it
        assert np.array_equal(f.depth > 0, obj)
        assert np.array_equal(_silhouette(f.rgb), obj), f"{np.sum(_silhouette(f.rgb) != obj)} pixels differ"


def test_antialiased_rgb_differs_only_on_the_mask_boundary(locker, small_intrinsics, gl_backend):
    frames, _ = _frames(locker, small_intrinsics, "pyrender", antialias=True)
    for f in frames:
        diff = _silhouette(f.rgb) != (f.mask > 0)
        assert not np.any(diff & ~_boundary(f.mask))


def test_part_boundaries_in_the_mask_are_colour_boundaries(locker, small_intrinsics, gl_backend):
    """Inside the object, neighbouring pixels of different parts have different colours in the rasteriser
    too (parts are painted distinct colours): no one-pixel shift between mask and RGB."""
    frames, _ = _frames(locker, small_intrinsics, "pyrender")
    palette = {1: (200, 170, 120), 2: (40, 90, 200), 3: (30, 170, 60)}
    for f in frames:
        for label, colour in palette.items():
            px = f.rgb[f.mask == label].astype(int)
            if len(px) == 0:
                continue
            # shading changes brightness, not hue: the dominant channel of every pixel is the part colour's
            assert np.mean(np.argmax(px, axis=1) == int(np.argmax(colour))) > 0.99, label


def test_locker_parts_do_not_interpenetrate(locker):
    """The alignment tests need unambiguous surfaces: no part crosses another at the rendered state."""
    import trimesh

    meshes = locker.posed_meshes({"door_hinge": 1.1, "drawer_slide": 0.15})
    body, door, drawer = meshes
    for m in (door, drawer):
        assert not trimesh.proximity.signed_distance(body, m.vertices).max() > 0  # no vertex inside the body


def test_state_renderers_alive_together_render_their_own_state(locker, small_intrinsics, gl_backend):
    """Renderers share one GL context per process but each keeps its own scene."""
    opts = RenderOptions(intrinsics=small_intrinsics, background="plain", plain_colour=BG)
    b = locker.bounds({"door_hinge": 1.5, "drawer_slide": 0.2})
    r = fit_radius(b, small_intrinsics)
    closed = StateRenderer(locker, {"door_hinge": 0.0, "drawer_slide": 0.0}, opts, b, r)
    opened = StateRenderer(locker, {"door_hinge": 1.5, "drawer_slide": 0.2}, opts, b, r)
    c2w = orbit_pose(b.mean(0), r, 0.3, 0.7)
    rng = np.random.default_rng
    a1, o1, a2 = closed.render(c2w, rng(0)), opened.render(c2w, rng(0)), closed.render(c2w, rng(0))
    assert np.array_equal(a1.rgb, a2.rgb) and not np.array_equal(a1.mask, o1.mask)
    for f in (a1, o1):
        assert np.array_equal(_silhouette(f.rgb), f.mask > 0)
