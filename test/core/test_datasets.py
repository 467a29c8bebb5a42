"""Dataset generators: the paper's recipe, feasible instances, byte-identical per seed."""

from __future__ import annotations

import numpy as np

from lvws_ros.core.datasets import DATASETS, dataset_instance, write_dataset
from lvws_ros.core.executor import simulate
from lvws_ros.core.formats import load_instance, schedule_to_dict
from lvws_ros.core.schedule import check_schedule
from lvws_ros.registry import make_policy


def test_specs_match_the_paper():
    assert (DATASETS["I"].count, DATASETS["I"].train) == (1000, 800)
    assert (DATASETS["II"].count, DATASETS["II"].train) == (10000, 8000)
    assert (DATASETS["III"].count, DATASETS["III"].train) == (20, 0)


def test_instances_follow_the_recipe():
    for key in ["I", "II", "III"]:
        spec = DATASETS[key]
        for k in [0, 1, spec.count - 1]:
            inst = dataset_instance(spec, k, seed=0)
            assert spec.robots[0] <= inst.num_robots <= spec.robots[1]
            assert spec.tasks[0] <= inst.num_tasks <= spec.tasks[1]
            assert len(inst.capabilities) in (2, 3)
            assert np.all((inst.robot_payload >= 1) & (inst.robot_payload <= 30))
            assert np.all((inst.task_payload >= 1) & (inst.task_payload <= 30))
            assert inst.robot_caps.any(axis=0).all()
            # feasible: the whole team covers every task (Instance validation) and GRP finishes
            assert check_schedule(inst, simulate(inst, make_policy("grp")).schedule) == []


def test_same_seed_byte_identical_files(tmp_path):
    a, b, c = tmp_path / "a", tmp_path / "b", tmp_path / "c"
    write_dataset("II", a, seed=3, count=30)
    write_dataset("II", b, seed=3, count=30)
    write_dataset("II", c, seed=4, count=30)
    files = sorted(p.relative_to(a) for p in a.rglob("*.json"))
    assert len(files) == 31  # 30 instances + manifest
    for f in files:
        assert (a / f).read_bytes() == (b / f).read_bytes(), f
    contents = {p.read_bytes() for p in a.rglob("*.json")}
    assert contents != {p.read_bytes() for p in c.rglob("*.json")}, "another seed, other instances"


def test_same_seed_same_schedules(tmp_path):
    write_dataset("I", tmp_path, seed=0, count=5)
    for f in sorted((tmp_path / "train").glob("*.json")):
        inst = load_instance(f)
        runs = []
        for _ in range(2):
            d = schedule_to_dict(simulate(inst, make_policy("rand_subteam", seed=9)).schedule)
            d.pop("compute_seconds")  # wall time, the only field allowed to differ
            runs.append(d)
        assert runs[0] == runs[1]


def test_split_is_800_200_for_dataset_i():
    splits = [("train" if k < DATASETS["I"].train else "test") for k in range(DATASETS["I"].count)]
    assert splits.count("train") == 800 and splits.count("test") == 200
