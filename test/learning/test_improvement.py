"""Self-improvement training (``lvws train --improve``): labels along the policy's own
schedules, the choice among candidates, one round end to end on a tiny set with a tiny
model (and resumed), and training on the device asked for."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from lvws_ros.cli.main import main
from lvws_ros.core.datasets import DATASETS, dataset_instance
from lvws_ros.core.executor import State, simulate
from lvws_ros.errors import ConfigError
from lvws_ros.learning.checkpoint import load_checkpoint, read_checkpoint, save_checkpoint
from lvws_ros.learning.demonstrations import label_state
from lvws_ros.learning.gatn import GATN, GATNConfig
from lvws_ros.learning.improvement import Candidate, choose, label
from lvws_ros.learning.policies import NO_VOLUNTARY_WAIT, LVWSPolicy
from lvws_ros.learning.sampling import sample_schedules
from lvws_ros.learning.training import TrainConfig, train, training_device
from lvws_ros.policies.exact import ExactPolicy


@pytest.fixture(scope="module")
def small_model() -> GATN:
    torch.manual_seed(5)
    return GATN(GATNConfig(hidden=16, mlp_hidden=16))


@pytest.mark.parametrize(("key", "index"), [("I", 3), ("IV", 5)])
def test_labels_from_the_decisions_taken_are_the_expert_labels_on_the_experts_run(key, index):
    """On the expert's own run, labelling by the decision taken in each state gives the
    E and X the departure rule gives (no travel and travel)."""
    inst = dataset_instance(DATASETS[key], index, seed=0)
    run = simulate(inst, ExactPolicy(workers=2), record_states=True)
    for step in run.steps:
        assert step.state is not None
        by_rule = label_state(step.state, run.schedule)
        by_decision = label_state(step.state, run.schedule, started=step.decision)
        np.testing.assert_array_equal(by_rule[0], by_decision[0])
        np.testing.assert_array_equal(by_rule[1], by_decision[1])


def test_labels_along_a_sample_reproduce_its_decisions(small_model):
    """The greedy matching on a sampled schedule's own labels (E where feasible) takes the
    sample's decisions: labels the policy can reach."""
    from lvws_ros.core.matching import greedy_match

    inst = dataset_instance(DATASETS["II"], 2, seed=0)
    policy = LVWSPolicy(model=small_model, idle_bias=NO_VOLUNTARY_WAIT)
    s = sample_schedules(policy, State.initial(inst), 4, 0.5, np.random.default_rng(0), record_states=True)[-1]
    assert s.states is not None
    cand = Candidate("sample", s.makespan, s.reward, s.states, [p.decision for p in s.steps], s.final)
    demos = label(inst, cand)
    taken = [(st, p.decision) for st, p in zip(s.states, s.steps, strict=True) if st.free_robots() and st.ready_tasks()]
    assert len(demos) == len(taken) > 0
    for d, (st, decision) in zip(demos, taken, strict=True):
        free, ready = st.free_robots(), st.ready_tasks()
        r = np.where(d.mask, d.expert, -1.0)
        m = greedy_match(r, inst.robot_caps[free], inst.robot_payload[free], inst.task_caps[ready],
                         inst.task_payload[ready])
        got = sorted((ready[j], tuple(free[i] for i in team)) for j, team in m.teams.items())
        assert got == sorted((j, tuple(sorted(t))) for j, t in decision.assignments)


def test_the_shortest_candidate_wins_and_ties_go_to_the_policys_own():
    s = State.initial(dataset_instance(DATASETS["I"], 0, seed=0))

    def cand(kind, makespan, liked=0.0):
        return Candidate(kind, makespan, liked, [s], [], s)

    assert choose([cand("lvws", 10.0), cand("sample", 9.0), cand("expert", 9.5)]).kind == "sample"
    assert choose([cand("expert", 9.0), cand("beam", 9.0), cand("sample", 9.0, 1.0)]).kind == "sample"
    assert choose([cand("sample", 9.0, 1.0), cand("sample", 9.0, 2.0)]).liked == 2.0
    assert choose([cand("sample", 9.0), cand("lvws", 9.0)]).kind == "lvws"
    assert choose([cand("lvws", 10.0), cand("expert", 8.0), cand("beam", 8.0)]).kind == "beam"


def test_one_self_improvement_round_runs_end_to_end_and_resumes(tmp_path, small_model, capsys):
    init = tmp_path / "tiny.pt"
    save_checkpoint(init, small_model, {"kind": "lvws", "idle_bias": NO_VOLUNTARY_WAIT})
    out = tmp_path / "improved.pt"
    args = ["train", "--improve", "1", "--init", str(init), "--out", str(out), "--datasets", "IV", "--count", "12",
            "--families", "", "--validation", "3", "--samples", "4", "--epochs", "1", "--processes", "1",
            "--improve-expert", "1", "--cache-dir", str(tmp_path / "cache"), "--quiet", "--seed", "3"]
    assert main(args) == 0
    err = capsys.readouterr()
    assert "seed 3" in err.err
    _, meta = load_checkpoint(out)
    history = meta["improve_history"]
    assert [h["round"] for h in history] == [0, 1]
    assert history[1]["states"] > 0 and sum(history[1]["chosen"].values()) == 10  # one per training instance
    assert meta["validation_suboptimality"] == min(h["validation_suboptimality"] for h in history)
    state = read_checkpoint(out.with_suffix(".improve.pt"))
    assert state["epoch"] == 1
    assert list((tmp_path / "cache").glob("optima-*.json"))  # proven validation optima are kept
    # resumed after its last round, a run of as many rounds has nothing left to do
    again = tmp_path / "again.pt"
    resumed = [*args[:args.index("--out")], "--out", str(again), *args[args.index("--out") + 2:],
               "--resume", str(out.with_suffix(".improve.pt"))]
    assert main(resumed) == 0
    assert "resumed" in capsys.readouterr().out
    assert load_checkpoint(again)[1]["improve_history"] == history


def test_training_runs_on_the_cpu_and_refuses_a_device_that_is_not_there():
    assert training_device("cpu").type == "cpu"
    assert training_device("auto").type == ("cuda" if torch.cuda.is_available() else "cpu")
    with pytest.raises(ConfigError, match="not a torch device"):
        training_device("warp-drive")
    if not torch.cuda.is_available():
        with pytest.raises(ConfigError, match="no CUDA device"):
            training_device("cuda")


def _tiny_training(device: str) -> tuple[GATN, list]:
    inst = dataset_instance(DATASETS["I"], 1, seed=0)
    from lvws_ros.learning.demonstrations import expert_demos

    demos = expert_demos(inst, workers=1)
    cfg = TrainConfig(epochs=2, batch_size=8, seed=0, model=GATNConfig(hidden=16, mlp_hidden=16), device=device)
    return train(demos, cfg, progress=False, log=lambda s: None)


def test_training_on_the_cpu_gives_a_cpu_model():
    model, history = _tiny_training("cpu")
    assert len(history) == 2 and all(p.device.type == "cpu" for p in model.parameters())


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device here (torch sees none): the GPU training "
                                                          "path runs only on a machine with one")
def test_training_on_cuda_gives_a_cpu_model_for_the_policies():
    model, history = _tiny_training("cuda")
    assert len(history) == 2 and all(p.device.type == "cpu" for p in model.parameters())


def test_the_shipped_recipe_is_the_command_in_the_shipped_models_log():
    from lvws_ros.cli.main import build_parser
    from lvws_ros.cli.offline import RECIPES
    from lvws_ros.learning.checkpoint import MODEL_DIR

    log = (MODEL_DIR / "lvws.training.txt").read_text()
    commands = [line.split("lvws train", 1)[1].split() for line in log.splitlines() if "# command" in line
                and "lvws train" in line]
    stages = RECIPES["shipped"]
    assert len(commands) == len(stages)
    for stage, command in zip(stages, commands, strict=True):
        build_parser().parse_args(["train", *stage, "--out", "x.pt"])  # every stage's flags parse
        given = [a for a in command if a not in ("CACHE", "PREVIOUS")]
        assert " ".join(a for a in stage if "{previous}" not in a) in " ".join(given)


def test_a_recipe_runs_its_stages_in_order(tmp_path, monkeypatch, small_model):
    from lvws_ros.cli import offline

    init = tmp_path / "tiny.pt"
    save_checkpoint(init, small_model, {"kind": "lvws", "idle_bias": NO_VOLUNTARY_WAIT})
    tiny = (("--improve", "1", "--init", str(init), "--datasets", "IV", "--count", "8", "--families", "",
             "--validation", "2", "--samples", "2", "--epochs", "1", "--seed", "1"),
            ("--improve", "1", "--init", "{previous}", "--datasets", "IV", "--count", "8", "--families", "",
             "--validation", "2", "--samples", "2", "--epochs", "1", "--seed", "2"))
    monkeypatch.setitem(offline.RECIPES, "tiny", tiny)
    out = tmp_path / "final.pt"
    assert main(["train", "--recipe", "tiny", "--out", str(out), "--processes", "1", "--quiet"]) == 0
    first = load_checkpoint(tmp_path / "final.stage1.pt")[1]
    final = load_checkpoint(out)[1]
    assert first["init"] == str(init) and final["init"] == str(tmp_path / "final.stage1.pt")


def test_with_improved_only_a_round_without_a_better_candidate_labels_and_trains_nothing(tmp_path, small_model):
    from lvws_ros.learning.improvement import ImproveConfig, improve

    init = tmp_path / "tiny.pt"
    save_checkpoint(init, small_model, {"kind": "lvws", "idle_bias": NO_VOLUNTARY_WAIT})
    insts = [dataset_instance(DATASETS["IV"], k, seed=4) for k in range(5)]
    cfg = ImproveConfig(rounds=1, samples=3, temperature=0.0, improved_only=True, processes=1)  # samples = LVWS's
    model, meta = improve(init, insts[:3], insts[3:], cfg, tmp_path / "out.pt", progress=False, log=lambda s: None)
    assert meta["improve_history"][1]["states"] == 0 and not meta["improve_history"][1]["kept"]
    for a, b in zip(model.state_dict().values(), small_model.state_dict().values(), strict=True):
        assert torch.equal(a, b)
