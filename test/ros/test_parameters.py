"""The scheduler's parameters as ROS users expect them, over real DDS: descriptors with
descriptions and ranges, read-only where a runtime change is not supported, a runtime
policy switch that works, refusals with a reason; relative names under a namespace and
a unique diagnostics hardware_id. And the launcher's precedence: explicit arguments,
then the parameter file, then its own defaults."""

from __future__ import annotations

import time
from pathlib import Path

import pytest
from lvws_msgs.msg import RobotState, Task, TaskGraph, TeamState
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient

from lvws_ros.ros.launcher import _commands
from lvws_ros.ros.scheduler_node import PARAMETERS
from lvws_ros.ros.service_call import SETTLE
from scheduler_probe import Probe, scheduler_probe

pytestmark = pytest.mark.ros


def snapshots(stamp: int) -> tuple[TeamState, TaskGraph]:
    """Three free robots and three new ready tasks (new ids: the earlier ones are gone)."""
    team = TeamState(capability_names=["lift", "drive"])
    team.header.stamp.sec = stamp
    for k, caps in enumerate(([1, 0], [0, 1], [1, 1])):
        team.robots.append(RobotState(id=f"r{k}", kind="x", available=True, capabilities=caps, payload=5.0))
    graph = TaskGraph(capability_names=["lift", "drive"])
    graph.header.stamp.sec = stamp
    for k, caps in enumerate(([1, 0], [0, 1], [1, 1])):
        graph.tasks.append(Task(id=f"s{stamp}t{k}", status=Task.STATUS_READY, capabilities=caps, payload=2.0, duration=5.0))
    return team, graph


def call(probe: Probe, future, seconds: float = 20.0):
    probe.spin(seconds, future.done)
    assert future.done(), "no answer from the parameter service"
    return future.result()


def decide(probe: Probe, stamp: int) -> str:
    """Publish a fresh world at ``stamp`` and return the policy named by the decision."""
    before = len(probe.got)
    team, graph = snapshots(stamp)
    probe.graph_pub.publish(graph)
    probe.team_pub.publish(team)
    probe.spin(30, lambda: len(probe.got) > before)
    assert len(probe.got) > before, probe.diags
    return probe.got[-1].policy


def test_parameters_under_a_namespace_switch_at_runtime_and_refuse_with_a_reason(ros_context):
    with scheduler_probe(ros_context, "lvws_param_test", ["-p", "policy:=grp"], namespace="/cellA") as probe:
        probe.wait_for_scheduler()
        assert probe.team_pub.topic_name == "/cellA/lvws/team_state"
        client = AsyncParameterClient(probe.node, "/cellA/scheduler")
        assert client.wait_for_services(timeout_sec=30)
        time.sleep(SETTLE)  # the server's side matches the client too: its answers are not dropped
        described = call(probe, client.describe_parameters(list(PARAMETERS))).descriptors
        by_name = {d.name: d for d in described}
        assert all(by_name[n].description for n in PARAMETERS)
        assert by_name["expect_subscribers"].read_only
        assert by_name["seed"].integer_range[0].to_value == 2**31 - 1
        assert by_name["decision_budget_ms"].floating_point_range[0].from_value == 0.0

        assert decide(probe, 1) == "grp"
        refused = {
            "policy": Parameter("policy", value="bogus"),
            "model_path": Parameter("model_path", value="/no/such/model.pt"),
            "seed": Parameter("seed", value=-1),
            "expect_subscribers": Parameter("expect_subscribers", value=3),
            "ack_timeout": Parameter("ack_timeout", value=0.0),
        }
        for name, param in refused.items():
            (result,) = call(probe, client.set_parameters([param])).results
            assert not result.successful and result.reason, name
        (result,) = call(probe, client.set_parameters([Parameter("policy", value="bogus")])).results
        assert "unknown 'bogus'" in result.reason
        assert decide(probe, 2) == "grp"  # a refused change changes nothing

        results = call(probe, client.set_parameters([Parameter("policy", value="lvws_rollout"),
                                                      Parameter("decision_budget_ms", value=50.0)])).results
        assert all(r.successful for r in results), [r.reason for r in results]
        assert decide(probe, 3) == "lvws_rollout"
        got = call(probe, client.get_parameters(["policy", "decision_budget_ms"])).values
        assert (got[0].string_value, got[1].double_value) == ("lvws_rollout", 50.0)
        probe.spin(2.0, lambda: bool(probe.hardware_ids))
        assert probe.hardware_ids == {"/cellA/scheduler"}  # unique per cell
    assert "policy lvws_rollout" in probe.output


def test_params_file_wins_over_the_launchers_defaults_and_explicit_arguments_over_both(tmp_path):
    from lvws_ros.ros.launcher import _check_inputs

    params = tmp_path / "p.yaml"
    params.write_text("scheduler:\n  ros__parameters:\n    policy: grp\n    seed: 7\n    use_sim_time: true\n"
                      "/cellB/scheduler:\n  ros__parameters:\n    policy: rand\n")

    def scheduler(namespace: str = "", **kw) -> list[str]:
        file_params = _check_inputs(kw.get("policy"), "", "", str(params), namespace=namespace)
        args = {"policy": None, "seed": None, "model_path": "", "rate": 10.0, "config": "",
                "file_params": file_params, "summary": tmp_path / "s.json", "gif": None, "sync": True, **kw}
        return _commands(tmp_path / "bag", namespace=namespace, **args)["scheduler"]

    cmd = scheduler()
    assert "policy:=grp" in cmd and "seed:=7" in cmd and "policy:=lvws" not in cmd  # the file over our defaults
    assert "expect_subscribers:=2" in cmd  # a default the file does not set
    cmd = scheduler(policy="exact", seed=3)
    assert "policy:=exact" in cmd and "seed:=3" in cmd and "policy:=grp" not in cmd  # explicit over the file
    ns = scheduler(namespace="/cellB")
    assert "policy:=rand" in ns and "seed:=0" in ns  # the cell's own section; `scheduler:` is the root's
    every = _commands(tmp_path / "bag", policy=None, seed=None, model_path="", rate=10.0, config="", file_params={},
                      summary=tmp_path / "s.json", gif=None, sync=True, namespace="/cellB")
    for name, cmd in every.items():
        assert "__ns:=/cellB" in cmd and "/clock:=clock" in cmd, name
    assert "use_sim_time:=true" in every["recorder"]  # the bag is stamped in sim time
    assert not any("sync_timeout" in a for a in every["cell_sim"])  # the simulator's own 5 s
    waits = _commands(tmp_path / "bag", policy=None, seed=None, model_path="", rate=10.0, config="",
                      file_params={"first_plan_wait": 20.0}, summary=tmp_path / "s.json", gif=None, sync=True,
                      instance="cell.json")
    assert "first_sync_timeout:=25.0" in waits["cell_sim"]  # the simulator waits as long as the first decision may
    assert f"instance:={Path('cell.json').resolve()}" in waits["cell_sim"]


def test_action_robots_faster_than_real_time_follow_the_dispatchers_clock_and_at_rate_1_every_node_the_wall(tmp_path):
    from lvws_ros.ros.launcher import _actions_commands, _commands

    def actions(rate: float, file_params: dict[str, object]) -> dict[str, list[str]]:
        every = _commands(tmp_path / "bag", policy=None, seed=None, model_path="", rate=rate, config="",
                          file_params=file_params, summary=tmp_path / "s.json", gif=None, sync=True)
        return _actions_commands(every, tmp_path / "cell.json", rate, tmp_path / "s.json", "", 2)

    fast = actions(10.0, {})
    assert "rate:=10.0" in fast["dispatcher"] and "publish_clock:=true" in fast["dispatcher"]
    assert "--rate" in fast["fake_robots"] and "10.0" in fast["fake_robots"]
    assert "use_sim_time:=true" in fast["scheduler"] and "use_sim_time:=true" in fast["recorder"]
    assert "ack_timeout:=50.0" in fast["scheduler"]  # the default's 5 s of wall time, on the cell's clock
    assert "ack_timeout:=50.0" not in actions(10.0, {"ack_timeout": 2.0})["scheduler"]  # the file's own stands
    real = actions(1.0, {})
    assert "publish_clock:=false" in real["dispatcher"] and "rate:=1.0" in real["dispatcher"]
    assert not any(a.startswith(("use_sim_time:=", "ack_timeout:=")) for cmd in real.values() for a in cmd)


def test_a_float_parameter_given_an_int_is_refused_with_a_clear_message(tmp_path):
    import subprocess
    import sys

    from lvws_ros.errors import ConfigError
    from lvws_ros.ros.scheduler_node import check_params_file

    params = tmp_path / "p.yaml"
    params.write_text("scheduler:\n  ros__parameters:\n    ack_timeout: 5\n")
    with pytest.raises(ConfigError, match=r"ack_timeout: expected float, got 5 \(write 5.0\)"):
        check_params_file(params)
    out = subprocess.run([sys.executable, "-m", "lvws_ros.ros.scheduler_node", "--ros-args", "-p", "ack_timeout:=5"],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 2 and "parameter ack_timeout" in out.stderr and "Traceback" not in out.stderr


def test_the_scheduler_node_gives_the_beam_a_budget_unless_told_one_and_its_width():
    from lvws_ros.learning.search import DEFAULT_WIDTH, LVWSBeamPolicy
    from lvws_ros.ros.scheduler_node import BEAM_BUDGET_MS, build_policies

    values = {name: par.default for name, par in PARAMETERS.items()}
    values.update({"policy": "lvws_beam", "fallback_policy": "grp"})
    main, fallback = build_policies(values)
    assert isinstance(main, LVWSBeamPolicy) and main.budget_ms == BEAM_BUDGET_MS and fallback is not None
    assert main.width == DEFAULT_WIDTH
    main, _ = build_policies({**values, "decision_budget_ms": 250.0, "beam_width": 3})
    assert isinstance(main, LVWSBeamPolicy) and main.budget_ms == 250.0 and main.width == 3
    _, backup = build_policies({**values, "policy": "grp", "fallback_policy": "lvws_beam", "beam_width": 5})
    assert isinstance(backup, LVWSBeamPolicy) and backup.width == 5 and backup.budget_ms == BEAM_BUDGET_MS


def test_the_scheduler_node_gives_the_sampler_a_budget_unless_told_one_and_its_samples():
    from lvws_ros.learning.sampling import DEFAULT_SAMPLES, LVWSSamplePolicy
    from lvws_ros.ros.scheduler_node import SAMPLE_BUDGET_MS, build_policies

    values = {name: par.default for name, par in PARAMETERS.items()}
    values.update({"policy": "lvws_sample", "fallback_policy": "grp", "seed": 4})
    main, _ = build_policies(values)
    assert isinstance(main, LVWSSamplePolicy) and main.budget_ms == SAMPLE_BUDGET_MS
    assert main.samples == DEFAULT_SAMPLES and main.seed == 4
    main, _ = build_policies({**values, "decision_budget_ms": 20.0, "samples": 3})
    assert isinstance(main, LVWSSamplePolicy) and main.budget_ms == 20.0 and main.samples == 3
    _, backup = build_policies({**values, "policy": "grp", "fallback_policy": "lvws_sample", "samples": 5})
    assert isinstance(backup, LVWSSamplePolicy) and backup.samples == 5 and backup.budget_ms == SAMPLE_BUDGET_MS
