"""PSNR, SSIM and part-mask scores on hand-computed cases."""
import numpy as np
import pytest

from rsart.metrics.images import PSNR_MAX, mask_scores, psnr, ssim

pytestmark = pytest.mark.core  # runs on the core install alone (.ci/core)


def test_psnr_constant_offset():
    a = np.full((8, 8, 3), 0.5)
    assert psnr(a + 0.1, a) == pytest.approx(20.0)
    assert psnr(a, a) == PSNR_MAX
    u = np.zeros((4, 4, 3), np.uint8)
    assert psnr(u + 255, u) == pytest.approx(0.0)


def test_ssim():
    rng = np.random.default_rng(0)
    img = rng.random((32, 40, 3))
    assert ssim(img, img) == pytest.approx(1.0)
    noisy = np.clip(img + rng.normal(0, 0.2, img.shape), 0, 1)
    assert 0.0 < ssim(noisy, img) < 0.9
    # constant images differing by a constant c: interior luminance term (2μxμy+C1)/(μx²+μy²+C1)
    x, y = np.full((40, 40), 0.5), np.full((40, 40), 0.7)
    lum = (2 * 0.5 * 0.7 + 1e-4) / (0.25 + 0.49 + 1e-4)
    assert ssim(x, y) < 1.0
    from rsart.metrics.images import _blur, _gauss_window  # interior pixels equal the closed form
    assert abs(lum - ((2 * _blur(x, _gauss_window()) * _blur(y, _gauss_window()) + 1e-4) /
                      (_blur(x, _gauss_window()) ** 2 + _blur(y, _gauss_window()) ** 2 + 1e-4))[20, 20]) < 1e-12
    with pytest.raises(ValueError):
        ssim(img, img[:10])


def test_mask_scores_hand_computed():
    gt = np.array([[0, 1, 1, 2],
                   [0, 1, 1, 2]], np.uint8)
    pred = np.array([[0, 1, 2, 3],
                     [0, 1, 1, 3]], np.uint8)
    # predicted label 3 is the true part 2 (label 2); predicted label 2 is unmatched -> wrong
    s = mask_scores(pred, gt, {1: 1, 3: 2})
    assert s["accuracy"] == pytest.approx(7 / 8)
    assert s["iou"][1] == pytest.approx(3 / 4)
    assert s["iou"][2] == pytest.approx(1.0)
    assert s["f1"][1] == pytest.approx(2 * 3 / (3 + 4))
    assert s["miou"] == pytest.approx((0.75 + 1.0) / 2)
