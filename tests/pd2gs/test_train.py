"""Training end to end on a tiny synthetic 2-part scene; resume; CLI errors and rendering."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from pd2gs.cli import main
from pd2gs.synthetic import make_frames
from pd2gs.train import TrainConfig, Trainer


@pytest.fixture(scope="module")
def frames():
    return make_frames(angles_deg=(0.0, 50.0), views=6, size=(32, 24), test_every=3, n_gaussians=800)


def tiny_config(iters=60):
    return TrainConfig(states=["closed", "open"], size=(32, 24), iters=iters, init_points=400,
                       densify_from=20, densify_every=20, opacity_reset_every=0,
                       checkpoint_every=10_000, max_gaussians=800)


def test_training_lowers_the_loss(frames):
    tr = Trainer(tiny_config(), frames)
    losses = [tr.step()["loss"] for _ in range(60)]
    assert np.mean(losses[-10:]) < 0.7 * np.mean(losses[:10])
    assert tr.field.gaussians.num != 400  # density control ran
    assert set(tr.evaluate("test")) == {"closed", "open", "mean"}


def test_resume_reproduces_an_uninterrupted_run(frames, tmp_path):
    straight = Trainer(tiny_config(30), frames)
    straight.run(progress=False)
    first = Trainer(tiny_config(30), frames, tmp_path / "run")
    first.run(progress=False, stop_at=15)  # as if interrupted after the checkpoint at 15
    second = Trainer(tiny_config(30), frames, tmp_path / "run")
    second.load_state_dict(torch.load(tmp_path / "run" / "checkpoint.pt", weights_only=False))
    second.run(progress=False)
    for a, b in zip(straight.field.state_dict().values(), second.field.state_dict().values()):
        assert torch.equal(a, b)


def test_cli_rejects_bad_input(tmp_path, capsys):
    assert main(["train", str(tmp_path / "missing"), "--out", str(tmp_path / "run")]) == 2
    assert "no meta.json" in capsys.readouterr().err
    assert main(["train", str(tmp_path), "--out", str(tmp_path / "r"), "--size", "big"]) == 2
    assert main(["render", str(tmp_path / "nothing"), "--state", "m0"]) == 2


def test_cli_renders_states_and_interpolations(frames, tmp_path):
    run = tmp_path / "run"
    Trainer(tiny_config(5), frames, run).run(progress=False)
    assert main(["render", str(run), "--state", "closed", "--views", "2"]) == 0
    assert (run / "renders" / "closed.png").is_file()
    assert main(["render", str(run), "--state", "closed", "--to", "open", "--t", "0.5"]) == 0
    assert (run / "renders" / "closed_to_open_t0.50.png").is_file()
    assert main(["render", str(run), "--state", "closed", "--to", "open", "--frames", "3",
                 "--out", str(tmp_path / "anim")]) == 0
    assert Path(tmp_path / "anim" / "closed_to_open.gif").stat().st_size > 0
    assert main(["render", str(run), "--state", "nope"]) == 2


def test_unseen_state_is_scored_by_latent_interpolation(frames):
    from pd2gs.evaluate import eval_unseen

    tr = Trainer(tiny_config(5), frames)
    tr.run(progress=False)
    unseen = [f for f in make_frames(angles_deg=(25.0,), views=4, size=(32, 24), n_gaussians=800)]
    res = eval_unseen(tr.field, unseen, tr.cfg.background, steps=3)
    assert res["segment"] == [0, 1] and res["t"] in (0.0, 0.5, 1.0)
    assert res["views"] == {"fit": 2, "scored": 2} and 5 < res["psnr"] < 60


def test_curriculum_adds_states_in_order_from_their_predecessor(frames):
    cfg = tiny_config(40)
    cfg.curriculum, cfg.curriculum_frac = True, 0.5
    tr = Trainer(cfg, frames)
    assert [tr.join_iteration(k) for k in range(2)] == [0, 20]
    seen = set()
    for _ in range(20):
        seen.add(tr._next_frame().state)
        tr.iteration += 1
    assert seen == {0}  # only the first state before the second joins
    before = tr.field.latents[0].detach().clone()
    tr._next_frame()  # iteration 20: state 1 joins, starting from state 0's latent
    assert torch.equal(tr.field.latents[1].detach(), before)
    seen = {tr._next_frame().state for _ in range(12)}
    assert seen == {0, 1}


def test_scale_regulariser_keeps_per_state_scales(frames):
    def scale_drift(weight):
        cfg = tiny_config(40)
        cfg.scale_reg_weight = weight
        tr = Trainer(cfg, frames)
        for _ in range(40):
            tr.step()
        with torch.no_grad():
            d = tr.field.deform(tr.field.latent(1))
            return float((d.log_scales - tr.field.gaussians.log_scales).abs().mean())
    assert scale_drift(10.0) < 0.5 * scale_drift(0.0)


def test_hull_prior_pulls_the_deformed_centres_into_each_state_hull(frames):
    def outside_after(weight):
        cfg = tiny_config(30)
        cfg.init, cfg.hull_weight, cfg.hull_cover_weight, cfg.hull_until_frac = "box", weight, weight, 1.0
        cfg.hull_resolution = 24
        tr = Trainer(cfg, frames)
        assert (tr.hull_prior is not None) == (weight > 0)
        for _ in range(30):
            tr.step()
        probe = tr.hull_prior if tr.hull_prior is not None else _prior_of(cfg, frames, tr.field.extent)
        with torch.no_grad():
            return float(probe.outside(tr.field.deform(tr.field.latent(1)).means, 1))
    assert outside_after(20.0) < 0.5 * outside_after(0.0)


def _prior_of(cfg, frames, extent):
    from pd2gs.hull import HullPrior
    from pd2gs.train import build_hulls

    return HullPrior(build_hulls(cfg, frames), extent)


def test_hull_prior_fades_out_and_old_configs_load(frames):
    cfg = tiny_config(20)
    cfg.hull_weight, cfg.hull_until_frac = 1.0, 0.5
    tr = Trainer(cfg, frames)
    assert tr.hull_factor() == 1.0
    tr.iteration = 5
    assert abs(tr.hull_factor() - 0.5) < 1e-9
    tr.iteration = 10
    assert tr.hull_factor() == 0.0 and tr._hull_terms(tr.field.gaussians.means, 1) == 0.0
    old = {k: v for k, v in TrainConfig().__dict__.items() if not k.startswith("hull")}
    old["deform"] = {}
    loaded = TrainConfig.from_json(old)  # a run written before the prior existed resumes without it
    assert loaded.hull_weight == 0.0 and loaded.hull_cover_weight == 0.0 and TrainConfig().hull_weight > 0
