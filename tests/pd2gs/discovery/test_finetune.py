"""The post-split fine-tune moves only the children's opacity and rotation, towards the images."""
import numpy as np
import torch

from pd2gs.discovery.field import StateField
from pd2gs.discovery.finetune import finetune_children
from pd2gs.render import rasterize
from rsart.camera import Camera, Intrinsics, look_at


def test_finetune_recovers_a_child_opacity_and_leaves_the_rest():
    rng = np.random.default_rng(0)
    n = 12
    means = np.concatenate([rng.uniform(-0.2, 0.2, (n, 2)), np.zeros((n, 1))], 1)
    quats = np.tile([1.0, 0, 0, 0], (n, 1))
    scales = np.tile([0.05, 0.05, 0.01], (n, 1))
    colors = rng.uniform(0.1, 0.9, (n, 3))
    opac = np.full(n, 0.8)
    cam = Camera(Intrinsics(32, 32, 40.0, 40.0, 15.5, 15.5, None),
                 look_at(np.array([0.0, 0.0, 1.0]), np.zeros(3), up=np.array([0.0, 1.0, 0.0])))
    f = lambda a: torch.as_tensor(a, dtype=torch.float32)  # noqa: E731
    with torch.no_grad():
        img = rasterize(f(means), f(quats), f(scales), f(colors), f(opac), f(cam.K), f(cam.w2c), 32, 32).rgb
    target = (img.numpy() * 255).round().astype(np.uint8)
    fld = StateField(["a"], means[None].copy(), quats[None].copy(), scales[None].copy(), colors, opac.copy())
    children = np.array([3, 7])
    fld.opacities[children] = 0.2
    stats = finetune_children(fld, children, [[(cam, target)]], iters=30, lr=0.1)
    assert stats["loss_last"] < stats["loss_first"]
    assert np.all(np.abs(fld.opacities[children] - 0.8) < np.abs(0.2 - 0.8))   # moved towards the truth
    others = np.setdiff1d(np.arange(n), children)
    assert np.array_equal(fld.opacities[others], opac[others])
    assert np.array_equal(fld.quats[0][others], quats[others])
    assert np.allclose(np.linalg.norm(fld.quats[0][children], axis=1), 1.0)
