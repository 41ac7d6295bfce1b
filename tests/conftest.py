"""Shared fixtures: small real twins and object folders built with rsart's own writers."""
from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest
import trimesh

from rsart.format import Joint
from rsart.kinematics import Twin, TwinPart


def box(extents, center) -> trimesh.Trimesh:
    m = trimesh.creation.box(extents=extents)
    m.apply_translation(center)
    return m


def make_cabinet() -> Twin:
    """A 0.4 m cabinet body, a lid hinged along its back top edge (opens upward for positive values), a drawer (+x)."""
    base = box([0.4, 0.4, 0.3], [0, 0, 0.15])
    lid = box([0.4, 0.4, 0.02], [0, 0, 0.312])
    drawer = box([0.3, 0.3, 0.1], [0.06, 0, 0.1])
    parts = [TwinPart(0, "base", base), TwinPart(1, "lid", lid), TwinPart(2, "drawer", drawer)]
    joints = [
        Joint("lid_hinge", "revolute", 0, 1, np.array([0.0, -1.0, 0.0]), np.array([-0.2, 0.0, 0.302]), (0.0, math.pi / 2)),
        Joint("drawer_slide", "prismatic", 0, 2, np.array([1.0, 0.0, 0.0]), np.array([0.2, 0.0, 0.1]), (0.0, 0.25)),
    ]
    return Twin("cabinet", parts, joints)


def make_lamp() -> Twin:
    """A chained two-joint arm: base, arm_1 (revolute about y at z=0.1), arm_2 (revolute about y at the arm tip)."""
    base = box([0.2, 0.2, 0.05], [0, 0, 0.025])
    arm1 = box([0.02, 0.02, 0.3], [0, 0, 0.25])
    arm2 = box([0.25, 0.02, 0.02], [0.125, 0, 0.4])
    parts = [TwinPart(0, "base", base), TwinPart(1, "arm_1", arm1), TwinPart(2, "arm_2", arm2)]
    joints = [
        Joint("shoulder", "revolute", 0, 1, np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 0.1]), (-1.0, 1.0)),
        Joint("elbow", "revolute", 1, 2, np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 0.4]), None),
    ]
    return Twin("lamp", parts, joints)


@pytest.fixture
def cabinet() -> Twin:
    return make_cabinet()


@pytest.fixture
def lamp() -> Twin:
    return make_lamp()


@pytest.fixture
def cabinet_dir(tmp_path) -> Path:
    """An object folder of the cabinet written by rsart.twin_io.write_object (no views)."""
    from rsart.twin_io import write_object

    out = tmp_path / "cabinet-0000"
    write_object(make_cabinet(), out, object_id="cabinet-0000", category="storage",
                 source={"kind": "procedural", "id": "test"})
    return out


@pytest.fixture(scope="session")
def partnet_root() -> Path:
    """The shared PartNet-Mobility samples (env RSART_PARTNET_ROOT); tests skip when unset."""
    root = os.environ.get("RSART_PARTNET_ROOT")
    if not root:
        pytest.skip("RSART_PARTNET_ROOT is not set: real PartNet-Mobility tests skipped "
                    "(.ci/run sets it to ../shared/assets/partnet-mobility)")
    p = Path(root)
    if not p.is_dir():
        pytest.skip(f"RSART_PARTNET_ROOT={root} is not a folder")
    return p


PARTNET_IDS = ["100162", "100676", "101326", "101940", "148", "3763", "45213", "8867"]
