"""Protocols pick the right states and view counts."""
from __future__ import annotations

import pytest

from rsart.errors import RsartError
from rsart.format import ObjectMeta
from rsart.render.protocols import plan_protocol, unseen_id
from rsart.states import multi_values, protocol_states


def _meta(twin) -> ObjectMeta:
    states, ev = protocol_states(twin.joints)
    return ObjectMeta("obj", "test", {"kind": "procedural"}, "m", {}, twin.to_parts(), list(twin.joints), states, ev)


def test_pd2gs_is_four_multi_states_of_50_plus_test_views(locker):
    p = plan_protocol("pd2gs", _meta(locker))
    assert [s.state.id for s in p.states] == ["m0", "m1", "m2", "m3"]
    assert all(s.n_train == 50 and s.n_test == 10 for s in p.states)
    assert sum(s.n_train for s in p.states) == 200 and not p.new_states


def test_two_state_is_start_and_end_times_100(locker):
    p = plan_protocol("two-state", _meta(locker))
    assert [(s.state.id, s.n_train) for s in p.states] == [("m0", 100), ("m3", 100)]


def test_single_joint_is_min_and_max_of_each_joint_with_others_fixed(locker):
    meta = _meta(locker)
    p = plan_protocol("single-joint", meta)
    # the min states equal m0 (lower limits 0), which protocol_states merged into m0
    ids = [s.state.id for s in p.states]
    assert ids == ["m0", "s1max", "s2max"]  # m0 serves as both joints' min state
    for sp in p.states:
        assert sp.n_train == 100
    s1 = meta.state("s1max").values
    assert s1 == {"door_hinge": locker.joint("door_hinge").limits[1], "drawer_slide": 0.0}


def test_single_joint_resolves_merged_and_unlimited_joints(lamp):
    meta = _meta(lamp)  # shoulder (-1, 1): its min state equals m0; elbow unlimited: quarter turn from m0
    p = plan_protocol("single-joint", meta)
    assert [s.state.id for s in p.states] == ["m0", "s1max", "s2max"] and not p.new_states
    base = meta.state("m0").values
    for sp in p.states[1:]:
        assert all(v == base[k] for k, v in sp.state.values.items() if k != sp.state.joint)


def test_single_joint_creates_a_min_state_meta_lacks(locker):
    meta = _meta(locker)
    meta.states = [s for s in meta.states if s.id != "s2max"]
    p = plan_protocol("single-joint", meta)
    assert [s.state.id for s in p.states] == ["m0", "s1max", "s2max"]
    assert [s.id for s in p.new_states] == ["s2max"]
    made = p.new_states[0]
    assert (made.kind, made.joint, made.extreme, made.extra) == ("single", "drawer_slide", "max", {"protocol": "single-joint"})
    assert made.values == {"door_hinge": 0.0, "drawer_slide": 0.2}


def test_rs_art_renders_every_state_and_more_than_400_views(locker, lamp):
    for twin in (locker, lamp):
        meta = _meta(twin)
        p = plan_protocol("rs-art", meta)
        assert [s.state.id for s in p.states] == [s.id for s in meta.states]
        assert all(s.n_train >= 60 for s in p.states)
        assert sum(s.n_train for s in p.states) > 400


def test_unseen_adds_intermediate_multi_states(locker):
    meta = _meta(locker)
    p = plan_protocol("unseen", meta)
    assert [s.state.id for s in p.states] == ["u1of6", "u1of2", "u5of6"]
    assert [s.id for s in p.new_states] == ["u1of6", "u1of2", "u5of6"]
    for sp, t in zip(p.states, (1 / 6, 1 / 2, 5 / 6)):
        assert sp.state.kind == "multi" and sp.state.extra == {"protocol": "unseen", "fraction": t}
        assert sp.state.values == multi_values(locker.joints, t)
        assert sp.n_train == 0 and sp.n_test == 20
    assert unseen_id(0.25) == "u1of4"


def test_view_overrides_and_bad_protocols(locker):
    p = plan_protocol("pd2gs", _meta(locker), views=3, test_views=0)
    assert all((s.n_train, s.n_test) == (3, 0) for s in p.states)
    with pytest.raises(RsartError, match="unknown protocol"):
        plan_protocol("nope", _meta(locker))
    with pytest.raises(RsartError, match="positive number of views"):
        plan_protocol("pd2gs", _meta(locker), views=0, test_views=0)
