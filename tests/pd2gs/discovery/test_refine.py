"""Visibility sets, FPS prompts, mask providers, and the geometry of boundary-aware splitting."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pd2gs.discovery.field import StateField
from pd2gs.discovery.masks import (GrabCutProvider, OracleProvider, farthest_point_sampling, make_provider,
                                   sample_prompts, visibility_sets)
from pd2gs.discovery.refine import boundary_split, in_mask_ratio, project_ellipse, split_children
from rsart.camera import Camera, Intrinsics


def test_visibility_sets_winner_margin():
    lw = np.zeros((2, 3, 3))
    lw[0, 0] = [0.9, 0.05, 0.0]     # part 0 clearly wins
    lw[0, 1] = [0.5, 0.4, 0.0]      # ambiguous: ratio 1.25 < 2
    lw[1, 2] = [0.0, 0.0, 0.7]      # part 2 only
    pos, neg = visibility_sets(lw, 0, tau_vis=2.0)
    assert pos.tolist() == [[True, False, False], [False, False, False]]
    assert neg.tolist() == [[False, False, True], [True, True, True]]
    pos2, _ = visibility_sets(lw, 2, tau_vis=2.0)
    assert pos2[1, 2] and pos2.sum() == 1


def test_fps_spreads_and_prompts_come_from_the_sets():
    pts = np.array([[0, 0], [0, 1], [10, 10], [10, 9], [0, 10], [5, 5]], dtype=float)
    idx = farthest_point_sampling(pts, 3, seed=0)
    chosen = pts[idx]
    d = [np.linalg.norm(a - b) for i, a in enumerate(chosen) for b in chosen[i + 1:]]
    assert min(d) > 5.0                      # never two of the near-duplicate neighbours
    pos = np.zeros((20, 30), bool); pos[5:10, 5:10] = True
    neg = ~pos
    p, n = sample_prompts(pos, neg, 10, 20)
    assert p.shape == (10, 2) and n.shape == (20, 2)
    assert pos[p[:, 1], p[:, 0]].all() and neg[n[:, 1], n[:, 0]].all()


def test_grabcut_and_oracle_providers():
    rng = np.random.default_rng(0)
    img = (rng.normal(60, 8, size=(60, 80, 3))).clip(0, 255).astype(np.uint8)
    img[15:45, 20:60] = rng.normal(200, 8, size=(30, 40, 3)).clip(0, 255).astype(np.uint8)
    truth = np.zeros((60, 80), bool); truth[15:45, 20:60] = True
    support = np.zeros_like(truth); support[20:40, 25:55] = True          # visible set: an inner part only
    p, n = sample_prompts(support, ~truth, 10, 20)
    m = GrabCutProvider()(img, p, n, support=support)
    iou = (m & truth).sum() / (m | truth).sum()
    assert iou > 0.9
    true_mask = truth.astype(np.uint8) * 3
    assert np.array_equal(OracleProvider()(img, p, n, support=support, true_mask=true_mask), truth)
    with pytest.raises(RuntimeError, match="oracle"):
        OracleProvider()(img, p, n, support=support)


def test_sam_provider_errors_clearly_without_package_or_checkpoint():
    with pytest.raises(RuntimeError, match="segment_anything|sam_checkpoint"):
        make_provider("sam", sam_checkpoint=None)


def test_in_mask_ratio():
    mask = np.zeros((10, 100), bool)
    mask[:, :30] = True                                   # columns 0..29 inside
    lam = in_mask_ratio(mask, np.array([10.0, 5.0]), np.array([50.0, 5.0]), samples=400)
    assert abs(lam - (29.5 - 10) / 40) < 0.01
    assert in_mask_ratio(mask, np.array([1.0, 5.0]), np.array([20.0, 5.0])) == 1.0


def test_split_children_formula():
    R = Rotation.from_euler("z", 30, degrees=True).as_matrix()
    mu, sc = np.array([1.0, 2.0, 3.0]), np.array([0.1, 0.02, 0.01])
    (mp, sp), (mb, sb) = split_children(mu, R, sc, 0.25, axis_sigma=2.0, towards=1.0)
    e, s = R[:, 0], 2 * 2.0 * 0.1
    assert np.allclose(mp, mu + 0.375 * s * e) and np.allclose(mb, mu - 0.125 * s * e)
    assert np.allclose(sp, [0.025, 0.02, 0.01]) and np.allclose(sb, [0.075, 0.02, 0.01])
    # the two children tile the parent's extent: [-s/2, s/2] = [s/2 - lam s, s/2] + [-s/2, s/2 - lam s]
    assert np.isclose((mp - mu) @ e + 2 * 2.0 * sp[0] / 2, s / 2)
    assert np.isclose((mb - mu) @ e - 2 * 2.0 * sb[0] / 2, -s / 2)


def _cam():
    intr = Intrinsics(200, 100, 100.0, 100.0, 99.5, 49.5, None)
    c2w = np.eye(4); c2w[:3, 3] = [0, 0, -2.0]            # looking along +z at the origin
    return Camera(intr, c2w)


def test_project_ellipse_major_axis():
    cam = _cam()
    c, A, B = project_ellipse(np.zeros(3), np.eye(3), np.array([0.2, 0.01, 0.01]), cam, 2.0)
    assert np.allclose(c, [99.5, 49.5])
    assert np.allclose(sorted([A[0], B[0]]), [99.5 - 20, 99.5 + 20], atol=1e-6)   # 2 sigma * f / z = 20 px


def test_straddling_gaussian_splits_at_the_mask_edge():
    """A Gaussian of part 1 along x, centred on the origin, 40 px long; part 1's mask ends 5 px right of its
    centre (u = 104.5): lambda = 25/40, the part child sits in the mask, the background child in part 0."""
    cam = _cam()
    q = np.array([[1.0, 0.0, 0.0, 0.0]])
    fld = StateField(["a", "b"], np.zeros((2, 1, 3)), np.tile(q, (2, 1, 1)),
                     np.tile([0.2, 0.01, 0.01], (2, 1, 1)), np.array([[1.0, 0, 0]]), np.array([0.8]))
    m1 = np.zeros((100, 200), bool); m1[:, :105] = True   # part 1: u < 104.5
    m0 = ~m1                                              # part 0 (static) beyond it
    sr = boundary_split(fld, np.array([1]), 0, [cam], [{0: m0, 1: m1}], axis_sigma=2.0, min_scale=1e-4)
    assert sr.n_candidates == 1 and sr.n_splits == 1
    f = sr.field
    assert f.n == 2 and sorted(sr.labels.tolist()) == [0, 1]
    part, bg = (0, 1) if sr.labels[0] == 1 else (1, 0)
    lam = 25 / 40
    # extent s = 2 * 2 * 0.2 = 0.8 m; the part (in-mask) side is -x
    assert abs(f.means[0, part, 0] - (-(1 - lam) / 2 * 0.8)) < 0.01
    assert abs(f.means[0, bg, 0] - (lam / 2 * 0.8)) < 0.01
    assert abs(f.scales[0, part, 0] - lam * 0.2) < 0.005 and abs(f.scales[0, bg, 0] - (1 - lam) * 0.2) < 0.005
    assert np.allclose(f.colors, [[1, 0, 0]] * 2) and np.allclose(f.opacities, 0.8)
    # each child now projects inside one mask (its axis ends touch the edge within a pixel)
    for i, msk in ((part, m1), (bg, m0)):
        c, A, B = project_ellipse(f.means[0, i], np.eye(3), f.scales[0, i], cam, 2.0)
        for end in (A, B):
            end = end - np.sign(end - c) * np.array([1.0, 0.0])
            assert msk[int(round(end[1])), min(199, int(round(end[0])))]


def test_splits_follow_the_part_in_every_state():
    """The split computed in state 0 is applied in state 1 in the Gaussian's own (rotated, moved) frame."""
    cam = _cam()
    R1 = Rotation.from_euler("z", 90, degrees=True)
    q0 = np.array([1.0, 0, 0, 0]); q1 = R1.as_quat()[[3, 0, 1, 2]]
    means = np.array([[[0.0, 0, 0]], [[0.5, 0.5, 0]]])
    fld = StateField(["a", "b"], means, np.array([[q0], [q1]]), np.tile([0.2, 0.01, 0.01], (2, 1, 1)),
                     np.array([[1.0, 0, 0]]), np.array([0.8]))
    m1 = np.zeros((100, 200), bool); m1[:, :105] = True
    sr = boundary_split(fld, np.array([1]), 0, [cam], [{0: ~m1, 1: m1}], axis_sigma=2.0, min_scale=1e-4)
    f = sr.field
    for i in range(2):
        local0 = f.means[0, i] - means[0, 0]
        local1 = R1.inv().apply(f.means[1, i] - means[1, 0])
        assert np.allclose(local0, local1, atol=1e-12)
    assert np.allclose(f.scales[0], f.scales[1])
