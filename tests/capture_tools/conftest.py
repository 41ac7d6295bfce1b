"""Simulated booth captures shared by the capture_tools tests (rendered once per session).

The textured cabinet (tests/capture_tools/textured_twin.py) is rendered with rsart's capture simulator
in the green booth with the RealSense-like sensor model, two states (m0 closed, m3 open), 24 views per
state on a hand-held circle at 320x240. The true poses and masks stay in the object folder; the tests
write raw captures from it with the poses withheld.
"""
from __future__ import annotations

from pathlib import Path

import pytest

VIEWS = 24
SIZE = (320, 240)


@pytest.fixture(scope="session")
def sim_capture(tmp_path_factory) -> Path:
    from rsart.camera import REALSENSE_D435_COLOR_640x480
    from rsart.render.frame import RenderOptions
    from rsart.render.runner import RenderJob, render_object_dir
    from rsart.twin_io import write_object
    from tests.capture_tools.textured_twin import make_textured_cabinet

    out = tmp_path_factory.mktemp("sim") / "cabinet-0000"
    write_object(make_textured_cabinet(0), out, object_id="cabinet-0000", category="storage",
                 source={"kind": "procedural", "id": "textured-cabinet"})
    K = REALSENSE_D435_COLOR_640x480.scaled(*SIZE)
    job = RenderJob(protocol="two-state", views=VIEWS, test_views=0,
                    options=RenderOptions(intrinsics=K, sensor=True, background="booth"))
    render_object_dir(out, job, workers=1, progress=False)
    return out
