"""The assembly-cell simulator without ROS: physics rules, the case study, config errors."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import CASE_STUDY
from lvws_ros.core.schedule import check_schedule
from lvws_ros.errors import AssignmentRejected, ConfigError
from lvws_ros.registry import make_policy
from lvws_ros.sim.config import load_cell_config
from lvws_ros.sim.runner import run_offline
from lvws_ros.sim.world import DONE, CellSim, build_instance


def run_until_done(sim: CellSim, task: str, limit: float = 600.0) -> float:
    while sim.status[task] != DONE:
        assert sim.time < limit, f"{task} not done by {limit} s"
        sim.step()
    return sim.end[task]


def finish(sim: CellSim, *tasks: str) -> None:
    """Execute tasks one after the other with a valid subteam (to set the world up)."""
    teams = {"t01": ["panda_1"], "t02": ["panda_1"], "t03": ["panda_3"], "t04": ["jackal_2"],
             "t06": ["husky_1"], "t07": ["panda_2"], "t08": ["panda_2"], "t09": ["panda_2"]}
    for t in tasks:
        sim.assign(t, teams[t])
        run_until_done(sim, t)


def test_case_study_matches_the_paper():
    cfg = load_cell_config(CASE_STUDY)
    inst = build_instance(cfg)
    kinds = [r.kind for r in cfg.robots]
    assert kinds.count("panda") == 3 and kinds.count("jackal") == 2 and kinds.count("husky") == 1
    assert len(cfg.cells) == 3 and len(cfg.objects) == 4 and inst.num_tasks == 14
    assert cfg.objects["obj1"].weight == 7
    payload = {r.id: r.payload for r in cfg.robots}
    assert all(2 <= payload[j] <= 3 for j in ("jackal_1", "jackal_2")) and payload["husky_1"] == 6
    assert len({payload[p] for p in ("panda_1", "panda_2", "panda_3")}) == 3  # different payloads


def test_a_jackal_and_the_husky_carry_obj1_together():
    sim = CellSim(load_cell_config(CASE_STUDY))
    finish(sim, "t01", "t04", "t07", "t08")  # obj1 ready to leave cell_2 (t10)
    assert sim.status["t10"] == 1
    start = sim.time
    sim.assign("t10", ["jackal_1", "husky_1"])
    end = run_until_done(sim, "t10")
    assert sim.object_cell["obj1"] == "cell_3"
    x, y = sim.position("obj1")
    assert math.dist((x, y), sim.cfg.cells["cell_3"].position) < 1e-6
    assert all(math.dist(sim.position(r), (x, y)) < 1.0 for r in ("jackal_1", "husky_1"))  # they came along
    assert end - start > 2 * sim.cfg.handling_time


@pytest.mark.parametrize("team", [["jackal_2"], ["husky_1"], ["jackal_1", "jackal_2"]])
def test_obj1_is_too_heavy_for_anything_but_a_jackal_husky_subteam(team):
    sim = CellSim(load_cell_config(CASE_STUDY))
    finish(sim, "t01", "t04", "t07", "t08")
    with pytest.raises(AssignmentRejected, match="obj1 weighs 7"):
        sim.assign("t10", team)
    assert sim.status["t10"] == 1  # nothing started


def test_an_arm_works_only_on_objects_at_its_cell():
    sim = CellSim(load_cell_config(CASE_STUDY))
    with pytest.raises(AssignmentRejected, match="panda_1 is at cell_1"):
        sim.assign("t07", ["panda_1"])  # t07 is at cell_2
    # t08 needs obj2 at cell_2; it is still at cell_1 even once its prerequisites are
    # forced done without the transport having happened
    sim.status["t04"] = sim.status["t07"] = DONE
    sim._refresh_ready()
    with pytest.raises(AssignmentRejected, match="obj2 is not at cell_2"):
        sim.assign("t08", ["panda_2"])


def test_arms_do_not_transport():
    sim = CellSim(load_cell_config(CASE_STUDY))
    finish(sim, "t01")
    with pytest.raises(AssignmentRejected, match="only mobile robots"):
        sim.assign("t04", ["panda_1", "jackal_2"])


def test_travel_takes_time_at_bounded_speed():
    sim = CellSim(load_cell_config(CASE_STUDY))
    finish(sim, "t02")  # obj3 at cell_1, ready for t05 (to cell_3)
    jackal = sim.robot_spec["jackal_1"]
    start_pos, start = sim.position("jackal_1"), sim.time
    pickup = sim._slot("cell_1", 0, 1)
    sim.assign("t05", ["jackal_1"])
    last, max_step = sim.position("jackal_1"), 0.0
    while sim.status["t05"] != DONE:
        sim.step()
        now = sim.position("jackal_1")
        max_step = max(max_step, math.dist(now, last))
        last = now
    drive = math.dist(start_pos, pickup) + math.dist(pickup, sim._slot("cell_3", 0, 1))
    assert max_step <= jackal.speed * sim.cfg.dt + 1e-9  # no teleporting
    assert sim.end["t05"] - start >= drive / jackal.speed + 2 * sim.cfg.handling_time - 2 * sim.cfg.dt


def test_busy_robots_and_unready_tasks_are_refused():
    sim = CellSim(load_cell_config(CASE_STUDY))
    sim.assign("t01", ["panda_1"])
    with pytest.raises(AssignmentRejected, match="busy"):
        sim.assign("t02", ["panda_1"])
    with pytest.raises(AssignmentRejected, match="queued"):
        sim.assign("t04", ["jackal_1"])
    with pytest.raises(AssignmentRejected, match="unknown robot"):
        sim.assign("t03", ["robbie"])


@pytest.mark.parametrize("policy", ["grp", "lvws", "dbgm", "rand_subteam", "exact"])
def test_the_case_study_runs_to_a_valid_schedule(policy):
    sim = CellSim(load_cell_config(CASE_STUDY))
    sched, decisions = run_offline(sim, make_policy(policy))
    assert sim.done and len(sched.assignments) == 14
    assert check_schedule(sim.executed_instance(), sched) == []
    assert sched.makespan == pytest.approx(max(sim.end.values()))
    # the paper's two behaviours: a robot told to wait, the Jackal + Husky subteam on obj1
    assert any(d.waiting for d in decisions)
    assert set(sched.by_task()["t10"].robots) in ({"jackal_1", "husky_1"}, {"jackal_2", "husky_1"})


def test_same_policy_same_run():
    a, _ = run_offline(CellSim(load_cell_config(CASE_STUDY)), make_policy("lvws"))
    b, _ = run_offline(CellSim(load_cell_config(CASE_STUDY)), make_policy("lvws"))
    assert a.assignments == b.assignments


def test_frames_and_gif(tmp_path):
    from lvws_ros.sim.render import render_gif, render_png

    sim = CellSim(load_cell_config(CASE_STUDY))
    run_offline(sim, make_policy("grp"), frame_every=10.0)
    assert len(sim.trace) >= sim.makespan / 10.0
    png = render_png(sim.cfg, sim.trace[3], 14, tmp_path / "f.png")
    gif = render_gif(sim.cfg, sim.trace, 14, tmp_path / "run.gif")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert gif.read_bytes()[:6] in (b"GIF89a", b"GIF87a")
    from PIL import Image

    with Image.open(gif) as im:
        assert im.size[0] >= 800 and im.size[1] >= 800 and im.n_frames == len(sim.trace)


def test_a_frame_shows_links_a_legend_and_labels_that_never_overlap():
    import matplotlib.pyplot as plt

    from lvws_ros.sim.render import _figure, draw_frame

    sim = CellSim(load_cell_config(CASE_STUDY))
    run_offline(sim, make_policy("lvws"), frame_every=1.0)
    carrying = next(f for f in sim.trace if len([t for t in f.robot_task.values() if t == "t10"]) == 2)
    fig, ax = _figure()
    draw_frame(ax, sim.cfg, carrying, 14)
    fig.canvas.draw()
    assert fig.legends and {t.get_text() for t in fig.legends[0].get_texts()} >= {"Jackal", "Husky", "failed",
                                                                                   "subteam link to its object"}
    labels = [t for t in ax.texts if ": " in t.get_text()]
    assert len(labels) == len(sim.cfg.robots)
    boxes = [t.get_window_extent() for t in labels]  # pixels, as drawn
    for i, a in enumerate(boxes):
        for b in boxes[i + 1:]:
            assert not a.overlaps(b), (a, b)
    purple = [ln for ln in ax.lines if ln.get_color() == "tab:purple"]
    assert len(purple) >= 2  # the t10 subteam: one link per member
    plt.close(fig)


def _write(tmp_path: Path, mutate) -> Path:
    data = yaml.safe_load(CASE_STUDY.read_text())
    mutate(data)
    p = tmp_path / "cell.yaml"
    p.write_text(yaml.safe_dump(data))
    return p


@pytest.mark.parametrize(("mutate", "message"), [
    (lambda d: d["robots"][3].update(speed=-1.0), "speed: must be > 0"),
    (lambda d: d["robots"][3].update(payload=float("nan")), "payload: expected a finite number"),
    (lambda d: d["robots"][0].update(cell="cell_9"), "unknown cell 'cell_9'"),
    (lambda d: d["robots"][0].update(kind="ur5"), "unknown kind 'ur5'"),
    (lambda d: d["tasks"][0].update(object="obj9"), "unknown object 'obj9'"),
    (lambda d: d["tasks"][0].update(type="paint"), "unknown type 'paint'"),
    (lambda d: d["tasks"][0].update(after=["t14"]), "cyclic"),
    (lambda d: d.pop("cells"), "missing key 'cells'"),
    # objects that would never be where a task needs them: the run would never end
    (lambda d: d["tasks"][6].update(cell="cell_3"), "task t07: obj1 is at cell_2 when it comes, not at cell_3"),
    (lambda d: d["tasks"][12].update(after=["t05"]), "tasks t07 and t13 both work on obj1 and neither comes after"),
    (lambda d: d["tasks"][11].update({"from": "cell_3"}), "task t12: obj4 is at cell_2 when it comes, not at cell_3 "
                                                          r"\(the latest transport of it before: t06\)"),
])
def test_bad_configs_are_named(tmp_path, mutate, message):
    from lvws_ros.errors import InstanceError

    with pytest.raises((ConfigError, InstanceError), match=message):
        CellSim(load_cell_config(_write(tmp_path, mutate)))


def test_malformed_yaml(tmp_path):
    p = tmp_path / "bad.yaml"
    p.write_text("cells: [unclosed\n")
    with pytest.raises(ConfigError, match="malformed YAML"):
        load_cell_config(p)


def test_lvws_sim_command_writes_schedule_and_frames(tmp_path):
    from lvws_ros.cli.main import main
    from lvws_ros.core.formats import load_schedule

    code = main(["sim", "--policy", "grp", "--out", str(tmp_path / "s.json"), "--frames", str(tmp_path / "f"),
                 "--frame-every", "20"])
    assert code == 0
    sched = load_schedule(tmp_path / "s.json")
    assert len(sched.assignments) == 14
    frames = sorted((tmp_path / "f").glob("frame_*.png"))
    assert len(frames) >= sched.makespan / 20 and frames[0].read_bytes()[:4] == b"\x89PNG"


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.floats(-5, 5), st.floats(-5, 5), st.floats(0.5, 4)), min_size=1, max_size=12))
def test_placed_labels_never_overlap(items):
    from lvws_ros.sim.render import place_labels

    height = 0.5
    spots = place_labels([(x, y) for x, y, _ in items], [w for _, _, w in items], height)
    boxes = [(left, top, w) for (left, top), (_, _, w) in zip(spots, items, strict=True)]
    for i, (l1, t1, w1) in enumerate(boxes):
        for l2, t2, w2 in boxes[i + 1:]:
            assert not (l1 < l2 + w2 and l2 < l1 + w1 and abs(t1 - t2) < height - 1e-9)
