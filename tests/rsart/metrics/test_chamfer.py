"""Chamfer protocol: identical meshes score the sampling floor, a shifted cube its analytic value."""
import numpy as np
import pytest
import trimesh

from rsart.metrics.chamfer import (ChamferConfig, chamfer_distance, chamfer_floor, chamfer_mesh,
                                   filter_small_components, stable_seed)

pytestmark = pytest.mark.core  # runs on the core install alone (.ci/core)


def cube(shift=(0.0, 0.0, 0.0)):
    m = trimesh.creation.box((1.0, 1.0, 1.0))
    m.apply_translation(shift)
    return m


def test_point_chamfer_hand_computed():
    a = np.array([[0.0, 0, 0], [1, 0, 0]])
    b = np.array([[0.0, 0, 0.1]])
    # a->b: (0.01 + 1.01)/2 = 0.51 ; b->a: 0.01 ; sum 0.52, x1000
    assert chamfer_distance(a, b) == pytest.approx(520.0)
    assert chamfer_distance(a, a) == 0.0


def test_identical_meshes_score_the_sampling_floor():
    v = chamfer_mesh(cube(), cube(), key=("obj", "part", "m0"))
    floor = chamfer_floor(6.0)
    assert floor == pytest.approx(0.382, abs=1e-3)
    assert abs(v - floor) < 0.1 * floor  # ≈ 0, only sampling noise, at the analytic floor


def test_shifted_cube_adds_the_analytic_value():
    """Cube vs the cube shifted by δ=0.01 along x: the two faces normal to x lie δ away, so each
    direction's mean squared distance grows by 2δ²/6; both directions x1000 -> 2000·δ²/3 = 0.0667
    on top of the sampling floor (Pythagoras: perpendicular offset adds to in-plane spacing)."""
    d = 0.01
    analytic = 2000 * d * d / 3
    key = ("obj", "part", "m0")
    same = chamfer_mesh(cube(), cube(), key=key)
    shifted = chamfer_mesh(cube((d, 0, 0)), cube(), key=key)
    assert shifted - same == pytest.approx(analytic, abs=0.1 * analytic)
    # with many samples the floor vanishes and the analytic value remains
    cfg = ChamferConfig(n_samples=200000, seeds=(0,))
    dense = chamfer_mesh(cube((d, 0, 0)), cube(), cfg, key=key)
    assert dense == pytest.approx(analytic + chamfer_floor(6.0, 200000), rel=0.1)


def test_seeds_depend_on_names_not_order():
    k = ("obj", "p1", "m3")
    assert chamfer_mesh(cube((0.02, 0, 0)), cube(), key=k) == chamfer_mesh(cube((0.02, 0, 0)), cube(), key=k)
    assert stable_seed(0, "a") != stable_seed(0, "b")
    assert stable_seed(0, "a") == stable_seed(0, "a")


def test_component_filter_drops_small_debris():
    big = trimesh.creation.icosphere(subdivisions=3)  # 1280 faces
    debris = trimesh.creation.box((0.01, 0.01, 0.01))
    debris.apply_translation([3, 0, 0])  # 12 faces < 10% of 1280
    medium = trimesh.creation.icosphere(subdivisions=2)  # 320 faces >= 10%: kept
    medium.apply_translation([-3, 0, 0])
    m = trimesh.util.concatenate([big, debris, medium])
    f = filter_small_components(m, 0.1)
    assert len(f.faces) == 1280 + 320
    assert f.bounds[1][0] < 2.0
    # the filter matters for the score: debris far away inflates an unfiltered Chamfer
    on = chamfer_mesh(m, trimesh.util.concatenate([big, medium]), key=("k",))
    off = chamfer_mesh(m, trimesh.util.concatenate([big, medium]), ChamferConfig(component_filter=False), key=("k",))
    assert off > on


def test_triangle_soup_is_one_component():
    soup = trimesh.creation.box((1, 1, 1))
    soup = trimesh.Trimesh(soup.triangles.reshape(-1, 3), np.arange(36).reshape(-1, 3), process=False)
    assert len(filter_small_components(soup).faces) == 12


def test_empty_mesh_raises():
    with pytest.raises(ValueError, match="no surface"):
        chamfer_mesh(trimesh.Trimesh(), cube())
