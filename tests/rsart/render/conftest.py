"""Fixtures of the capture-simulator tests (small images keep them fast)."""
from __future__ import annotations

import pytest

from rsart.camera import REALSENSE_D435_COLOR_640x480


@pytest.fixture
def small_intrinsics():
    """The D435 colour intrinsics scaled to 160x120 (pixel-centre convention kept)."""
    return REALSENSE_D435_COLOR_640x480.scaled(160, 120)


@pytest.fixture(scope="session")
def gl_backend() -> str:
    """"pyrender-egl" / "pyrender-osmesa" when headless GL works here, else skip."""
    from rsart.render.raster import resolve_backend

    b = resolve_backend("auto")
    if b == "raycast":
        pytest.skip("no headless OpenGL (EGL/OSMesa) here: pyrender tests skipped, ray-cast RGB still tested")
    return b


def make_locker():
    """A 0.4 m box body, a door hinged on its +x face opening outwards (+z axis), and a drawer sliding out of
    the -y face; parts never interpenetrate (checked in test_alignment) for joint values within the limits. Face-coloured."""
    import math

    import numpy as np
    import trimesh

    from rsart.format import Joint
    from rsart.kinematics import Twin, TwinPart

    def box(ext, c, colour):
        m = trimesh.creation.box(extents=ext)
        m.apply_translation(c)
        m.visual.face_colors = colour
        return m

    body = box([0.4, 0.4, 0.4], [0, 0, 0.2], (200, 170, 120, 255))
    door = box([0.02, 0.36, 0.36], [0.212, 0, 0.2], (40, 90, 200, 255))
    drawer = box([0.3, 0.2, 0.1], [0, -0.26, 0.25], (30, 170, 60, 255))
    parts = [TwinPart(0, "body", body), TwinPart(1, "door", door), TwinPart(2, "drawer", drawer)]
    joints = [Joint("door_hinge", "revolute", 0, 1, np.array([0.0, 0.0, -1.0]), np.array([0.222, -0.18, 0.0]),
                    (0.0, math.pi / 2)),
              Joint("drawer_slide", "prismatic", 0, 2, np.array([0.0, -1.0, 0.0]), np.array([0.0, -0.2, 0.25]),
                    (0.0, 0.2))]
    return Twin("locker", parts, joints)


@pytest.fixture
def locker():
    return make_locker()
