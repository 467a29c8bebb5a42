"""The `lvws` command as a new user runs it on the shipped example instance."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from conftest import REPO

EXAMPLE = REPO / "config" / "example_instance.json"


def lvws(*args, check=True):
    res = subprocess.run([sys.executable, "-m", "lvws_ros.cli", *map(str, args)],
                         capture_output=True, text=True, timeout=600)
    if check:
        assert res.returncode == 0, res.stderr
    return res


@pytest.mark.parametrize("verb", ["", "generate", "solve", "check", "evaluate", "gantt"])
def test_help_on_every_verb(verb):
    res = lvws(*([verb] if verb else []), "--help")
    assert "usage: lvws" in res.stdout


def test_solve_check_gantt(tmp_path):
    out = tmp_path / "exact.json"
    res = lvws("solve", EXAMPLE, "--policy", "exact", "--workers", "2", "--out", out)
    assert res.stdout == ""  # --out is where the schedule goes
    printed = json.loads(out.read_text())
    assert printed["format"] == "lvws-schedule/1" and printed["status"] == "optimal"
    assert "makespan" in res.stderr and f"written: {out}" in res.stderr  # the summary as without --out
    assert lvws("check", EXAMPLE, out).stdout.startswith("valid")
    grp = tmp_path / "grp.json"
    lvws("solve", EXAMPLE, "--policy", "grp", "--out", grp)
    assert json.loads(grp.read_text())["makespan"] >= printed["makespan"]
    png = tmp_path / "gantt.png"
    lvws("gantt", out, "--instance", EXAMPLE, "--out", png)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000


def test_out_means_the_file_and_stdout_the_schedule_without_it(tmp_path):
    out = tmp_path / "grp.json"
    written = lvws("solve", EXAMPLE, "--policy", "grp", "--out", out)
    assert "{" not in written.stdout and "lvws-schedule" not in written.stdout  # no JSON on stdout
    assert "gap" in written.stderr
    assert lvws("check", EXAMPLE, out).stdout.startswith("valid")
    printed = lvws("solve", EXAMPLE, "--policy", "grp")
    same = json.loads(printed.stdout)
    assert same["assignments"] == json.loads(out.read_text())["assignments"]  # without --out: the schedule, on stdout
    sim = lvws("sim", "--policy", "grp", "--out", tmp_path / "sim.json")
    assert "makespan" in sim.stdout and "step " not in sim.stdout  # the summary, not the decision steps
    assert len(json.loads((tmp_path / "sim.json").read_text())["assignments"]) == 14


def test_beam_search_solves_and_says_when_its_budget_left_it_to_lvws(tmp_path):
    out = tmp_path / "beam.json"
    res = lvws("solve", EXAMPLE, "--policy", "lvws_beam", "--beam-width", "8", "--out", out)  # the default: 64
    assert "decided by LVWS alone" not in res.stderr
    assert lvws("check", EXAMPLE, out).stdout.startswith("valid")
    rushed = lvws("solve", EXAMPLE, "--policy", "lvws_beam", "--budget-ms", "0")
    assert "decided by LVWS alone" in rushed.stderr
    lvws_own = lvws("solve", EXAMPLE, "--policy", "lvws")
    assert json.loads(rushed.stdout)["makespan"] == json.loads(lvws_own.stdout)["makespan"]
    assert json.loads(out.read_text())["makespan"] <= json.loads(lvws_own.stdout)["makespan"]
    narrow = lvws("solve", EXAMPLE, "--policy", "lvws_beam", "--beam-width", "1")
    assert json.loads(narrow.stdout)["makespan"] <= json.loads(lvws_own.stdout)["makespan"]
    bad = lvws("solve", EXAMPLE, "--policy", "lvws_beam", "--beam-width", "0", check=False)
    assert bad.returncode == 2 and "beam width must be at least 1" in bad.stderr and "Traceback" not in bad.stderr


def test_generate_and_evaluate(tmp_path):
    lvws("generate", "--dataset", "I", "--out", tmp_path / "ds", "--count", 804, "--quiet")
    assert len(list((tmp_path / "ds" / "test").glob("*.json"))) == 4
    res = lvws("evaluate", tmp_path / "ds" / "test", "--policies", "grp,rand", "--workers", "2",
               "--out-dir", tmp_path / "res", "--quiet")
    assert "| grp | 4 | 100.0 |" in res.stdout and "| rand | 4 | 100.0 |" in res.stdout
    assert "4/4 optima proven" in res.stdout
    csv = (tmp_path / "res" / "results.csv").read_text().splitlines()
    assert csv[0].startswith("policy,instances") and len(csv) == 3


def test_bad_input_exits_2_with_message(tmp_path):
    bad = tmp_path / "cyc.json"
    data = json.loads(EXAMPLE.read_text())
    data["tasks"][0]["after"] = [data["tasks"][-1]["id"]]
    data["tasks"][-1]["after"] = [data["tasks"][0]["id"]]
    bad.write_text(json.dumps(data))
    res = lvws("solve", bad, check=False)
    assert res.returncode == 2 and "cyclic prerequisites" in res.stderr
    res = lvws("solve", tmp_path / "missing.json", check=False)
    assert res.returncode == 2 and "cannot read" in res.stderr


def test_evaluate_paper_writes_both_tables_and_the_waiting_section(tmp_path):
    import re

    md = tmp_path / "results.md"
    lvws("evaluate", "--paper", "--limit", "2", "--policies", "grp,lvws", "--workers", "2", "--time-limit", "30",
         "--table2-time-limit", "2", "--out-dir", tmp_path, "--out-md", md, "--quiet")
    text = md.read_text()
    for heading in ("## Table I", "## Table I, other families", "## Table II", "## Decision time",
                    "## Voluntary waiting"):
        assert heading in text
    fam = re.findall(r"^\| (GRP|LVWS) \| ([\d.]+) \| ([\d.]+) \| ([\d.]+) \|$", text, re.M)
    assert {f[0] for f in fam} == {"GRP", "LVWS"}  # training family, assembly, mspsp: all valid, all measured
    assert "| mixed (training family) | assembly (held out) | mspsp (held out) |" in text
    rows = {m[0]: [float(x) for x in m[1:]] for m in re.findall(
        r"^\| (GRP|LVWS) \| ([\d.]+) \| [\d.—]+ \| ([\d.]+) \| [\d.—]+ \|$", text, re.M)}
    assert set(rows) == {"GRP", "LVWS"} and all(x >= 0 for v in rows.values() for x in v)  # vs proven optima
    assert "Dataset I: 2/2 optima proven" in text
    assert "| Method | IV | depot (held out) |" in text  # Table III: with travel, in and out of distribution
    assert re.search(r"^\| LVWS \| [\d.]+ \| [\d.]+ \|$", text, re.M) and "- depot: 2/2 optima proven" in text
    assert re.search(r"^\| exact expert \(first 2 test instances\) \| [\d.]+ \| [\d.]+ \|$", text, re.M)
    assert (tmp_path / "paper-cache" / "expert-I-s0.json").is_file()
    bad = lvws("evaluate", "--paper", "--policies", "exact", "--out-dir", tmp_path, check=False)
    assert bad.returncode == 2 and "compare" in bad.stderr


def test_the_paper_tables_in_processes_are_the_tables_of_one_process(tmp_path):
    """``--processes``: the columns run in a pool of processes, and every figure is the
    one a single process gives (the times per decision aside)."""
    from lvws_ros.cli.paper import reproduce

    def tables(processes: int) -> list[str]:
        text = reproduce(tmp_path / f"r{processes}.md", time_limit=10, table2_time_limit=2, workers=1, limit=1,
                         cache_dir=tmp_path / "cache", progress=False, log=lambda _: None,
                         policies=("rand", "grp", "lvws"), processes=processes)
        head, _, rest = text.partition("## Table I")
        assert ("2 processes at once" in head) == (processes == 2)
        timing = rest.index("## Decision time")
        return (rest[:timing] + rest[rest.index("## Voluntary waiting"):]).splitlines()

    one, two = tables(1), tables(2)
    assert one == two and any(line.startswith("| LVWS |") for line in one)


def test_bare_lvws_prints_usage_and_exits_2():
    res = lvws(check=False)
    assert res.returncode == 2 and "usage: lvws" in res.stderr and "Traceback" not in res.stderr


@pytest.mark.parametrize("text", ['{"format": "lvws-schedule/1", "instance": "x", "policy": "p", "makespan": 1e400, '
                                  '"assignments": []}',
                                  '{"format": "lvws-schedule/1", "instance": "x", "policy": "p", "makespan": 1, '
                                  '"assignments": [], "decisions": null}'])
def test_check_refuses_broken_schedules_with_exit_2(tmp_path, text):
    (tmp_path / "s.json").write_text(text)
    res = lvws("check", EXAMPLE, tmp_path / "s.json", check=False)
    assert res.returncode == 2 and "s.json" in res.stderr and "Traceback" not in res.stderr, res.stderr


def test_the_expert_cache_is_keyed_by_content_not_by_name(tmp_path):
    """Two different unnamed instances once shared one cache record (450 % suboptimality
    for an optimal schedule)."""
    from lvws_ros.core.datasets import DATASETS, dataset_instance
    from lvws_ros.core.metrics import run_policy, summarize
    from lvws_ros.core.problem import Instance
    from lvws_ros.policies.expert_cache import expert_records
    from lvws_ros.registry import make_policy

    a, b = (dataset_instance(DATASETS["I"], k, 0) for k in (800, 801))
    a, b = (Instance("", i.capabilities, i.robots, i.tasks) for i in (a, b))  # both unnamed
    cache = tmp_path / "cache.json"
    experts = expert_records([a, b], cache, 60, 2, progress=False)
    assert len(experts) == 2 and len(json.loads(cache.read_text())) == 2
    again = expert_records([b], cache, 60, 2, progress=False)  # from the cache
    exact = make_policy("exact", workers=2)
    rows = summarize([run_policy(b, exact)], again)
    assert rows[0].proven == 1 and abs(rows[0].mean_suboptimality) < 1e-9


def test_sim_compare_prints_plans_with_and_without_travel_and_refuses_a_bad_name(tmp_path):
    res = lvws("sim", "--compare", "grp,exact")
    rows = {line.split("|")[1].strip(): line for line in res.stdout.splitlines() if line.startswith("| ")}
    assert {"grp", "exact"} <= set(rows)
    plan, executed = (float(rows["exact"].split("|")[k]) for k in (2, 3))
    assert abs(executed - plan) <= 0.03 * plan
    bad = lvws("sim", "--compare", "grp,bogus", check=False)
    assert bad.returncode == 2 and "bogus" in bad.stderr and "Traceback" not in bad.stderr
    blind = tmp_path / "blind.yaml"
    blind.write_text((REPO / "config" / "assembly_cell.yaml").read_text().replace("plan_travel: true",
                                                                                   "plan_travel: false"))
    res = lvws("sim", "--compare", "grp", "--config", blind, check=False)
    assert res.returncode == 2 and "plan_travel" in res.stderr and "Traceback" not in res.stderr
