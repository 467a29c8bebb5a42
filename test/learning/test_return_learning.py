"""The way home in the learned policy and in GRP (objective "return"), the training family
that teaches it, and training sources counted per family."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from lvws_ros.core.datasets import DATASETS, dataset_instance
from lvws_ros.core.executor import State, simulate
from lvws_ros.core.families import FAMILIES, TRAINING_FAMILIES, TRAIT_FAMILIES, family_instance
from lvws_ros.core.formats import instance_from_dict, instance_key, instance_to_dict
from lvws_ros.core.schedule import check_schedule
from lvws_ros.errors import ConfigError, ModelError
from lvws_ros.learning.demonstrations import expert_demos, load_demos, save_demos
from lvws_ros.learning.features import BUSY_PAIR_FEATURES, MODEL_FORMATS, PAIR_FEATURES, InstanceFeatures
from lvws_ros.policies.exact import solve_exact
from lvws_ros.registry import make_policy


def _cell(objective: str = "return") -> dict:
    """Two mobile robots at a, one docked at b (10 m away), one fixed arm at a; two tasks at a."""
    return {"format": "lvws-instance/1", "name": "dock", "objective": objective, "traits": ["weld"],
            "sites": {"a": [0, 0], "b": [10, 0]},
            "robots": [{"id": "far", "traits": {"weld": 1}, "site": "a", "home": "b", "speed": 1.0},
                       {"id": "near", "traits": {"weld": 1}, "site": "a", "speed": 2.0},
                       {"id": "arm", "traits": {"weld": 1}, "site": "a"}],
            "tasks": [{"id": "t", "requires": {"weld": 1}, "duration": 1, "after": [], "site": "a"},
                      {"id": "u", "requires": {"weld": 2}, "duration": 3, "after": [], "site": "b"}]}


def _squash(x: np.ndarray) -> np.ndarray:
    with np.errstate(invalid="ignore"):
        return np.where(np.isfinite(x), x / (1 + x), 1.0)


def test_the_way_home_feature_is_the_squashed_time_home_from_where_the_task_ends():
    inst = instance_from_dict(_cell())
    feats = InstanceFeatures(inst).encode(State.initial(inst))
    assert MODEL_FORMATS[PAIR_FEATURES] == "lvws-gatn/5"
    unit = 2.0  # mean duration
    home = np.array([[10.0, 0.0], [0.0, 5.0], [0.0, np.inf]])  # far/near/arm from a, b (speed 1, 2, fixed)
    assert np.allclose(inst.travel.ways_home(), home)
    assert list(feats.rows) == [0, 1, 2] and len(feats.cols) == 3
    assert np.allclose(feats.pairs[:, :-1, PAIR_FEATURES - 1], _squash(home / unit))
    assert np.all(feats.pairs[:, -1] == 0)  # the idle column
    older = InstanceFeatures(inst, read=BUSY_PAIR_FEATURES).encode(State.initial(inst)).pairs
    assert np.array_equal(older[..., :BUSY_PAIR_FEATURES], feats.pairs[..., :BUSY_PAIR_FEATURES])
    assert np.all(older[..., BUSY_PAIR_FEATURES:] == 0)  # a lvws-gatn/4 model never sees it
    plain = instance_from_dict(_cell("makespan"))  # the makespan objective: nobody needs to go home
    assert np.all(InstanceFeatures(plain).encode(State.initial(plain)).pairs[..., PAIR_FEATURES - 1] == 0)


def test_demonstrations_written_before_the_way_home_read_with_a_zero_column_without_travel(tmp_path):
    """Without travel the way home is 0 (padded); with travel the file cannot say whether
    its instances returned home, so it is refused (labelled again)."""
    plain = expert_demos(dataset_instance(DATASETS["II"], 3, seed=0), time_limit=5, workers=1)
    travel = expert_demos(dataset_instance(DATASETS["IV"], 0, seed=0), time_limit=5, workers=1)
    for name, demos in (("plain", plain), ("travel", travel)):
        save_demos([replace(d, features=replace(d.features, pairs=d.features.pairs[..., :BUSY_PAIR_FEATURES]))
                    for d in demos], tmp_path / f"{name}.npz")
    back, _ = load_demos(tmp_path / "plain.npz")
    assert all(np.array_equal(a.features.pairs, b.features.pairs) for a, b in zip(back, plain, strict=True))
    with pytest.raises(ModelError, match=r"travel\.npz: travel states without the way-home pair feature"):
        load_demos(tmp_path / "travel.npz")


def test_grp_sends_the_robot_whose_home_is_there_in_the_last_wave():
    """Both mobile robots reach t at once and weigh the same; "near" lives at a (where t
    is), "far" at b. With the makespan objective GRP takes the lower index (the paper's
    tie-break); with "return" the robot home soonest, and the fleet is home sooner."""
    inst = instance_from_dict({**_cell(), "tasks": _cell()["tasks"][:1]})
    grp = simulate(inst, make_policy("grp")).schedule
    assert check_schedule(inst, grp) == []
    assert [a.robots for a in grp.assignments] == [("near",)] and grp.makespan == pytest.approx(10.0)
    plain = instance_from_dict({**_cell("makespan"), "tasks": _cell()["tasks"][:1]})
    assert [a.robots for a in simulate(plain, make_policy("grp")).schedule.assignments] == [("far",)]
    ordered = instance_from_dict({**_cell(), "tasks": _cell()["tasks"][:1],
                                  "robots": [dict(_cell()["robots"][0], home="a"), *_cell()["robots"][1:]]})
    assert simulate(ordered, make_policy("grp")).schedule.makespan == pytest.approx(1.0)


def test_the_return_family_is_a_training_family_with_travel_homes_and_the_return_objective():
    fam = FAMILIES["traits-return"]
    assert fam.traits and fam.travel and not fam.held_out
    assert "traits-return" in TRAINING_FAMILIES and "traits" in TRAINING_FAMILIES and "traits-return" in TRAIT_FAMILIES
    assert "traits-roles" not in TRAINING_FAMILIES  # held out
    docked = 0
    for k in range(6):
        inst = family_instance("traits-return", k, 0)
        tr = inst.travel
        assert inst.objective == "return" and tr is not None and 4 <= len(tr.sites) <= 7
        assert all(s > 0 for s in tr.robot_speed)
        docked += sum(tr.home(i) == 0 and tr.robot_site[i] != 0 for i in range(inst.num_robots))
        assert instance_key(instance_from_dict(instance_to_dict(inst))) == instance_key(inst)
        assert instance_key(family_instance("traits-return", k, 0)) == instance_key(inst)
        best = solve_exact(inst, workers=2, time_limit=10)
        assert best.status == "optimal"
        for name in ("grp", "lvws"):
            s = simulate(inst, make_policy(name)).schedule
            assert check_schedule(inst, s) == [] and s.makespan >= best.makespan - 1e-6
    assert docked > 0


def test_training_families_take_a_count_each():
    from lvws_ros.cli.offline import _families

    assert _families("mixed:800,traits, traits-return:3", 40) == (("mixed", 800), ("traits", 40),
                                                                   ("traits-return", 3))
    assert _families("", 40) == ()
    for bad in ("mixed:x", "mixed:0", "mixed:-2"):
        with pytest.raises(ConfigError, match=f"--families: '{bad}'"):
            _families(bad, 40)


def test_a_bad_family_count_exits_2_naming_it(capsys):
    from lvws_ros.cli.main import main

    assert main(["train", "--out", "x.pt", "--families", "mixed:many"]) == 2
    assert "'mixed:many'" in capsys.readouterr().err
