"""`lvws import`: multi-skill project scheduling files (MiniZinc data) and CSV files of
robots and tasks become lvws-instance/1 files; errors name the file and the line."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from lvws_ros.core.executor import simulate
from lvws_ros.core.formats import load_instance
from lvws_ros.core.importers import import_csv, import_mspsp, import_psplib, parse_dzn
from lvws_ros.core.schedule import check_schedule
from lvws_ros.errors import InstanceError
from lvws_ros.policies.exact import solve_exact
from lvws_ros.registry import make_policy

ROOT = Path(__file__).resolve().parents[2]

# Written for this test in the layout of the MSPSP benchmark files: a source (1) and a sink
# (6) without duration, three workers, two skills. Worker 1 holds both skills but fills one
# slot: activity 3 needs one of each, so it needs two workers. Optimal: 5 (every way to give
# activity 3 two workers for 2 s delays activity 4 or activity 2); were worker 1 allowed to
# fill both slots, 4 (activities 2 and 4 beside activity 3, then activity 5).
MSPSP = """% a small project
mint = 5;
nActs = 6;
dur = [0,3,2,3,1,0];
nSkills = 2;
sreq = [| 0,0,
        | 1,0,
        | 1,1,
        | 0,1,
        | 1,0,
        | 0,0, |];
nResources = 3;
mastery = [| true,true,
           | true,false,
           | false,true, |];
nPrecs = 7;
pred = [1,1,1,2,3,4,5];
succ = [2,3,4,5,6,6,6];
USEFUL_RES = [{}, {1,2}, {1,2,3}, {1,3}, {1,2}, {}];
"""


def test_an_mspsp_file_is_expressed_exactly_with_roles(tmp_path):
    path = tmp_path / "tiny.dzn"
    path.write_text(MSPSP)
    inst = import_mspsp(path)
    assert inst.traits == ("skill1", "skill2") and inst.task_roles.all()
    assert [t.id for t in inst.tasks] == ["act2", "act3", "act4", "act5"]  # source and sink dropped
    assert inst.tasks[inst.task_index["act5"]].after == ("act2",)
    assert dict(inst.robots[0].traits) == {"skill1": 1.0, "skill2": 1.0}
    res = solve_exact(inst, workers=2, time_limit=20)
    assert res.proven and res.makespan == pytest.approx(5.0)
    assert check_schedule(inst, res.schedule) == []
    for name in ("grp", "lvws", "rand_subteam"):
        assert check_schedule(inst, simulate(inst, make_policy(name)).schedule) == []


def test_without_roles_the_same_file_would_be_shorter(tmp_path):
    """The role rule matters: worker 1 alone would cover act3 if it counted for both skills."""
    path = tmp_path / "tiny.dzn"
    path.write_text(MSPSP)
    inst = import_mspsp(path)
    from dataclasses import replace

    free = replace(inst, roles=False)
    assert solve_exact(free, workers=2, time_limit=20).makespan == pytest.approx(4.0)


@pytest.mark.parametrize("text,message", [
    ("nActs = 2;\ndur = [1,2];\nx = 3 @;", "line 3: unexpected '@;'"),
    ("nActs = 2;\ndur = [1;", "expected ';'"),
    (MSPSP.replace("dur = [0,3,2,3,1,0];", "dur = [0,3,2,4,1];"), "dur has 5 entries, expected 6"),
    (MSPSP.replace("| 0,1,\n", "| 0,1,1,\n"), "sreq must be a 6 x 2 table"),
    (MSPSP.replace("| 1,1,\n", "| 0,0,\n"), "activity 3 lasts 2 but needs no worker"),
    (MSPSP.replace("succ = [2,3,4,5,6,6,6];", "succ = [2,3,4,5,6,6,9];"), "names an activity outside 1..6"),
    (MSPSP.replace("| 0,1,\n", "| 0,3,\n"), "can never be covered"),
])
def test_bad_mspsp_files_name_the_line_or_the_item(tmp_path, text, message):
    path = tmp_path / "bad.dzn"
    path.write_text(text)
    with pytest.raises(InstanceError, match=message.replace("(", r"\(").replace(")", r"\)")) as info:
        import_mspsp(path)
    assert str(path) in str(info.value)


def test_an_activity_without_duration_is_dropped_and_its_precedences_kept(tmp_path):
    path = tmp_path / "zero.dzn"
    path.write_text(MSPSP.replace("dur = [0,3,2,3,1,0];", "dur = [0,0,2,3,1,0];"))  # act2 (before act5) lasts 0
    inst = import_mspsp(path)
    assert [t.id for t in inst.tasks] == ["act3", "act4", "act5"]
    assert inst.tasks[inst.task_index["act5"]].after == ()  # act2 came after the source only


# The MiniZinc benchmarks' layout (mspsp.mzn), written for this test: worker 1 has both
# skills and, as that model counts a worker toward every skill it has, covers task 1 (one
# of each skill) alone, beside workers 2 and 3 on tasks 2 and 3: 2 in all (with roles, 4).
# Task 4 lasts 0: dropped, task 5 still after task 1 through it.
MZN_MSPSP = """n_skills = 2;
n_workers = 3;
has_skills = [{1, 2}, {1}, {2}];
n_tasks = 5;
d = [2, 2, 2, 0, 1];
rr = [| 1, 1, 0, 1, 1
      | 1, 0, 1, 0, 0 |];
suc = [{4}, {}, {}, {5}, {}];
"""
MSPSP_DIR = ROOT / "examples" / "mspsp"


def test_the_minizinc_benchmarks_layout_is_read_exactly_without_roles(tmp_path):
    path = tmp_path / "tiny.dzn"
    path.write_text(MZN_MSPSP)
    inst = import_mspsp(path)
    assert inst.traits == ("skill1", "skill2") and not inst.task_roles.any()
    assert [r.id for r in inst.robots] == ["worker1", "worker2", "worker3"]
    assert [dict(r.traits) for r in inst.robots] == [{"skill1": 1.0, "skill2": 1.0}, {"skill1": 1.0}, {"skill2": 1.0}]
    assert [t.id for t in inst.tasks] == ["task1", "task2", "task3", "task5"]
    assert inst.tasks[0].requires == (("skill1", 1.0), ("skill2", 1.0))
    assert inst.tasks[inst.task_index["task5"]].after == ("task1",)
    res = solve_exact(inst, workers=2, time_limit=20)
    assert res.proven and res.makespan == pytest.approx(3.0)  # tasks 1-3 at once, then task 5
    assert check_schedule(inst, res.schedule) == []


def test_a_minizinc_benchmark_file_by_eye_and_its_published_optimum():
    inst = import_mspsp(MSPSP_DIR / "easy_01.dzn")
    assert inst.num_robots == 9 and inst.num_tasks == 20 and len(inst.traits) == 5
    by_id = {t.id: t for t in inst.tasks}
    assert by_id["task1"].duration == 4  # d[1]; rr's first column: skills 1, 4, 5
    assert by_id["task1"].requires == (("skill1", 1.0), ("skill4", 1.0), ("skill5", 1.0))
    assert by_id["task9"].requires == (("skill1", 1.0), ("skill2", 2.0))
    assert by_id["task6"].after == ("task1",) and by_id["task5"].after == ("task2", "task4")
    assert dict(inst.robots[3].traits) == {"skill2": 1.0, "skill4": 1.0, "skill5": 1.0}  # has_skills[4] = {2, 4, 5}
    medium = import_mspsp(MSPSP_DIR / "medium_05.dzn")  # MiniZinc Challenge 2012: 18, proven
    res = solve_exact(medium, workers=2, time_limit=20)
    assert res.proven and res.makespan == pytest.approx(18.0)  # with roles it would be 27


@pytest.mark.parametrize("edit,message", [
    (lambda t: t.replace("suc = [{4}, {}", "suc = [{4}, {9}"), "suc[2] names task 9, outside 1..5"),
    (lambda t: t.replace("{1, 2}, {1}", "{1, 3}, {1}"), "has_skills[1] names skill 3, outside 1..2"),
    (lambda t: t.replace("[{1, 2}, {1}, {2}]", "[1, 2, 3]"), "has_skills must be an array of sets of skills"),
    (lambda t: t.replace("d = [2, 2, 2, 0, 1]", "d = [2, 2, 2, 0]"), "d has 4 entries, expected 5"),
    (lambda t: t.replace("d = [2, 2, 2, 0, 1]", "d = [2, -2, 2, 0, 1]"), "d[2] is -2, expected a duration >= 0"),
    (lambda t: t.replace("| 1, 0, 1, 0, 0 |]", "| 1, 0, 1, 0 |]"), "rr must be a 2 x 5 table of ints"),
    (lambda t: t.replace("| 1, 0, 1, 0, 0 |]", "| 1, 0, -1, 0, 0 |]"), "rr[2, 3] is -1"),
    (lambda t: t.replace("n_workers = 3;", "n_workers = true;"), "n_workers must be a non-negative integer"),
    (lambda t: t.replace("[| 1, 1, 0, 1, 1", "[| 1, 1, 0, 1, 0").replace("| 1, 0, 1, 0, 0 |]", "| 1, 0, 1, 0, 0 |]"),
     "task 5 lasts 1 but needs no worker"),
    (lambda t: t.replace("| 1, 0, 1, 0, 0 |]", "| 1, 0, 3, 0, 0 |]"), "'task3' can never be covered"),
    (lambda t: t.replace("{1, 2}, {1}", "{1, 2, {1}"), "line 3"),
])
def test_bad_minizinc_benchmark_files_name_the_item(tmp_path, edit, message):
    path = tmp_path / "bad.dzn"
    path.write_text(edit(MZN_MSPSP))
    with pytest.raises(InstanceError, match=re.escape(message)) as info:
        import_mspsp(path)
    assert str(path) in str(info.value)


def test_the_datazinc_reader_takes_values_not_code():
    data = parse_dzn("a = 1; % note\nb = [| true, false | false, true |];\nc = {1, 2};\nd = [];", "x.dzn")
    assert data == {"a": 1, "b": [[True, False], [False, True]], "c": [1, 2], "d": []}
    with pytest.raises(InstanceError, match=r"x\.dzn line 1"):
        parse_dzn('a = "import os";', "x.dzn")
    assert parse_dzn("trueRes = true;", "x.dzn") == {"trueRes": True}
    with pytest.raises(InstanceError, match="nested deeper than 8 levels"):
        parse_dzn("x = " + "[" * 5000 + "]" * 5000 + ";", "x.dzn")


ROBOTS = "id,site,speed,home,welder,gripper,payload\nw1,dock,1.0,,1,,1\nw2,dock,1.0,,1,1,\narm,c,,,,2,2\n"
TASKS = ("id,duration,after,site,roles,welder,gripper,payload\nweld,6,,c,,2,1,\naudit,2,weld,c,true,1,1,\n"
         "lift,3,,c,,,,3\n")
SITES = "name,x,y\ndock,0,0\nb,4,3\nc,0,3\n"


def test_csv_files_become_a_trait_instance_with_travel(tmp_path):
    for name, text in (("robots.csv", ROBOTS), ("tasks.csv", TASKS), ("sites.csv", SITES)):
        (tmp_path / name).write_text(text)
    inst = import_csv(tmp_path / "robots.csv", tmp_path / "tasks.csv", tmp_path / "sites.csv", objective="return")
    assert inst.traits == ("welder", "gripper", "payload") and inst.objective == "return"
    assert dict(inst.robots[1].traits) == {"welder": 1.0, "gripper": 1.0}
    assert list(inst.task_roles) == [False, True, False] and inst.travel is not None
    assert inst.tasks[1].after == ("weld",)
    s = simulate(inst, make_policy("grp")).schedule
    assert check_schedule(inst, s) == []


@pytest.mark.parametrize("edit,message", [
    (lambda r, t: (r, t.replace("weld,6,", "weld,six,")), "tasks.csv line 2: duration: expected a number, got 'six'"),
    (lambda r, t: (r, t.replace("lift,3,,c,,,,3", "lift,3,,c,,,,-3")), "tasks.csv line 4: payload: expected a finite"),
    (lambda r, t: (r.replace("w2,dock,1.0,,1,1,", "w2,dock,1.0,,1,1"), t), "robots.csv line 3: 7 columns expected"),
    (lambda r, t: (r, t.replace("roles,welder,gripper,payload", "roles,welder,gripper,laser")),
     "column(s) ['laser'] are neither task fields nor robot traits"),
    (lambda r, t: (r, t.replace("audit,2,weld,c,true", "audit,2,weld,c,maybe")), "line 3: roles: expected true"),
    (lambda r, t: (r, t.replace("audit,2,weld", "audit,2,wled")), "unknown task id(s) ['wled']"),
    (lambda r, t: (r.replace("arm,c,", "arm,moon,"), t), "unknown site 'moon'"),
])
def test_bad_csv_files_name_the_line(tmp_path, edit, message):
    robots, tasks = edit(ROBOTS, TASKS)
    for name, text in (("robots.csv", robots), ("tasks.csv", tasks), ("sites.csv", SITES)):
        (tmp_path / name).write_text(text)
    with pytest.raises(InstanceError, match=message.replace("(", r"\(").replace(")", r"\)")
                       .replace("[", r"\[").replace("]", r"\]")):
        import_csv(tmp_path / "robots.csv", tmp_path / "tasks.csv", tmp_path / "sites.csv")


def test_lvws_import_writes_the_file_and_exits_2_on_bad_input(tmp_path):
    (tmp_path / "tiny.dzn").write_text(MSPSP)
    out = tmp_path / "tiny.json"
    done = subprocess.run([sys.executable, "-m", "lvws_ros.cli", "import", "mspsp", str(tmp_path / "tiny.dzn"),
                           "--out", str(out)], capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    assert load_instance(out).num_tasks == 4 and "roles" in done.stdout
    (tmp_path / "bad.dzn").write_text(MSPSP.replace("nResources = 3;", "nResources = 4;"))
    bad = subprocess.run([sys.executable, "-m", "lvws_ros.cli", "import", "mspsp", str(tmp_path / "bad.dzn"),
                          "--out", str(tmp_path / "x.json")], capture_output=True, text=True, check=False)
    assert bad.returncode == 2 and "mastery must be a 4 x 2 table" in bad.stderr and "Traceback" not in bad.stderr
    assert not (tmp_path / "x.json").exists()


def test_csv_from_a_spreadsheet_and_errors_on_the_robots_file_name_its_line(tmp_path):
    (tmp_path / "robots.csv").write_bytes(b"\xef\xbb\xbf" + ROBOTS.encode())  # a byte-order mark
    (tmp_path / "tasks.csv").write_text(TASKS)
    (tmp_path / "sites.csv").write_text(SITES + "\n\n")  # blank lines at the end
    inst = import_csv(tmp_path / "robots.csv", tmp_path / "tasks.csv", tmp_path / "sites.csv")
    assert inst.num_robots == 3
    for robots, message in ((ROBOTS + "w1,dock,1.0,,1,,1\n", "robots.csv line 5: id 'w1' already on line 2"),
                            (ROBOTS.replace("arm,c,", "arm,moon,"), "robots.csv line 4: site: unknown site 'moon'"),
                            (ROBOTS.replace("welder,", "duration,"), "robots.csv line 1: column(s) ['duration'] "
                                                                     "are task fields")):
        (tmp_path / "robots.csv").write_text(robots)
        with pytest.raises(InstanceError, match=re.escape(message)):
            import_csv(tmp_path / "robots.csv", tmp_path / "tasks.csv", tmp_path / "sites.csv")
    (tmp_path / "robots.csv").write_text("id,welder,gripper,payload\nw1,1,,1\nw2,1,1,\narm,,2,2\n")
    with pytest.raises(InstanceError, match=re.escape("tasks.csv line 2: site, from and to need the sites file")):
        import_csv(tmp_path / "robots.csv", tmp_path / "tasks.csv")


# ---------------------------------------------------------------- PSPLIB

PSPLIB = ROOT / "examples" / "psplib"


def _sm_table(path):
    """The REQUESTS/DURATIONS and PRECEDENCE RELATIONS rows of an .sm file, read here
    independently of the importer: {job: (duration, demands, successors)}."""
    lines = path.read_text().splitlines()
    prec = lines.index("PRECEDENCE RELATIONS:")
    req = lines.index("REQUESTS/DURATIONS:")
    succ = {int(v[0]): [int(x) for x in v[3:]] for v in (lines[k].split() for k in range(prec + 2, req - 1))}
    rows = {}
    for text in lines[req + 3:]:
        if text.startswith("*"):
            break
        v = [int(x) for x in text.split()]
        rows[v[0]] = (v[2], v[3:], succ[v[0]])
    return rows


def test_a_j30_file_is_read_exactly():
    path = PSPLIB / "j301_1.sm"
    inst = import_psplib(path)
    assert inst.name == "j301_1" and inst.traits == ("R1", "R2", "R3", "R4") and inst.travel is None
    assert inst.num_robots == 12 + 13 + 4 + 12  # RESOURCEAVAILABILITIES: one robot per unit
    assert sum(1 for r in inst.robots if r.traits == (("R3", 1.0),)) == 4
    rows = _sm_table(path)
    assert len(rows) == 32 and [t.id for t in inst.tasks] == [f"job{n}" for n in range(2, 32)]  # source, sink dropped
    for t in inst.tasks:
        duration, demands, _ = rows[int(t.id[3:])]
        assert t.duration == duration
        assert dict(t.requires) == {f"R{k + 1}": float(d) for k, d in enumerate(demands) if d}
        preds = {f"job{a}" for a, (_, _, s) in rows.items() if int(t.id[3:]) in s and a != 1}
        assert set(t.after) == preds
    by_id = {t.id: t for t in inst.tasks}  # a few rows read by eye
    assert by_id["job3"].duration == 4 and by_id["job3"].requires == (("R1", 10.0),)
    assert by_id["job20"].requires == (("R2", 10.0),) and by_id["job20"].duration == 7
    assert by_id["job22"].after == ("job16", "job17", "job18") and by_id["job2"].after == ()


def test_a_patterson_file_is_read_and_activities_without_demand_wait_for_nothing():
    inst = import_psplib(PSPLIB / "pat1.rcp")
    assert inst.num_tasks == 12 and [r.id for r in inst.robots][:3] == ["R1_1", "R1_2", "R2_1"]
    by_id = {t.id: t for t in inst.tasks}
    assert by_id["job2"].duration == 6 and by_id["job2"].requires == (("R1", 1.0),)
    assert by_id["job2"].after == () and by_id["job9"].after == ("job2",)
    idle = [t for t in inst.tasks if t.requires == (("no_resource", 1.0),)]
    assert idle and sum(r.id.startswith("no_resource") for r in inst.robots) == len(idle)
    res = solve_exact(inst, workers=2, time_limit=20)
    assert res.proven and res.makespan == 19  # the published optimum of pat1
    assert check_schedule(inst, res.schedule) == []


def _rcp_table(path):
    """The jobs of a Patterson file, read here independently of the importer (its numbers
    in order, whatever the line breaks): capacities, {job: (duration, demands, successors)}."""
    v = [int(x) for x in path.read_text().split()]
    n, k = v[0], 2 + v[1]
    rows = {}
    for job in range(1, n + 1):
        count = v[k + 1 + v[1]]
        rows[job] = (v[k], v[k + 1:k + 1 + v[1]], v[k + 2 + v[1]:k + 2 + v[1] + count])
        k += 2 + v[1] + count
    assert k == len(v)
    return v[2:2 + v[1]], rows


def test_an_rg300_file_is_read_exactly():
    """RanGen's 300 activities in the Patterson format, successor lists wrapped over lines."""
    path = PSPLIB / "RG300_1.rcp"
    inst = import_psplib(path)
    capacity, rows = _rcp_table(path)
    assert capacity == [10, 10, 10, 10] and len(rows) == 302
    assert inst.name == "RG300_1" and inst.num_robots == 40 and inst.num_tasks == 300
    assert [t.id for t in inst.tasks] == [f"job{n}" for n in range(2, 302)]  # source and sink dropped
    for t in inst.tasks:
        duration, demands, _ = rows[int(t.id[3:])]
        assert t.duration == duration
        assert dict(t.requires) == {f"R{k + 1}": float(d) for k, d in enumerate(demands) if d}
        assert set(t.after) == {f"job{a}" for a, (_, _, s) in rows.items() if int(t.id[3:]) in s and a != 1}
    by_id = {t.id: t for t in inst.tasks}  # rows read by eye: line 3 (job 2, 33 successors on three lines), the last
    assert by_id["job2"].duration == 3 and by_id["job2"].requires == (("R2", 1.0),) and by_id["job2"].after == ()
    assert "job2" in by_id["job60"].after and "job2" in by_id["job293"].after and "job2" not in by_id["job33"].after
    assert by_id["job301"].duration == 8 and by_id["job301"].requires == (("R2", 3.0),)


def test_a_bad_number_on_a_wrapped_patterson_line_names_that_line(tmp_path):
    text = (PSPLIB / "RG300_1.rcp").read_text().splitlines()
    assert text[3].split()[0] == "22"  # the second line of job 2's successors
    text[3] = text[3].replace("22", "2x", 1)
    path = tmp_path / "bad.rcp"
    path.write_text("\n".join(text) + "\n")
    with pytest.raises(InstanceError, match=re.escape("bad.rcp line 4: expected integers")):
        import_psplib(path)


SM_BAD = [
    (lambda t: t.replace("  2      1     8       4    0    0    0", "  2      1     8       4    0    x    0"),
     "line 56: expected integers"),
    (lambda t: t.replace("   5        1          1          20", "   5        1          1          99"),
     "line 23: job 5's successor 99 is outside 1..32"),
    (lambda t: t.replace("   5        1          1          20", "   5        1          2          20"),
     "line 23: job 5 lists 1 successors, declares 2"),
    (lambda t: t.replace("  3      1     4      10    0    0    0", "  3      1     4      20    0    0    0"),
     "line 57: job 3 needs 20 of resource 1, its capacity is 12"),
    (lambda t: t.replace("   4        1          3           5   9  10", "   4        2          3           5   9  10"),
     "line 22: job 4 has 2 modes"),
    (lambda t: t.replace("  - nonrenewable              :  0", "  - nonrenewable              :  2"),
     "line 10: nonrenewable resources are not supported"),
    (lambda t: t.split("RESOURCEAVAILABILITIES:")[0], "no 'RESOURCEAVAILABILITIES:' section"),
    (lambda t: t.replace("   4        1          3           5   9  10", "   4        1          3           5   9   2")
     .replace("   2        1          3           6  11  15", "   2        1          3           4  11  15"),
     "cyclic prerequisites"),
]


@pytest.mark.parametrize("edit,message", SM_BAD)
def test_bad_psplib_files_name_the_line(tmp_path, edit, message):
    path = tmp_path / "bad.sm"
    path.write_text(edit((PSPLIB / "j301_1.sm").read_text()))
    with pytest.raises(InstanceError, match=re.escape(message)) as info:
        import_psplib(path)
    assert str(path) in str(info.value)


@pytest.mark.parametrize("text,message", [
    ("3 1\n2\n0 0 1 2\n4 1 1 3\n0 0 0 7\n", "line 5: more numbers than the 3 jobs declared"),
    ("3 1\n2\n0 0 1 2\n4 1 1\n", "line 4: the file ends before job 2's successors"),
    ("3 1\n2\n0 0 1 2\n4 -1 1 3\n0 0 0\n", "line 4: expected non-negative integers"),
    ("3 1\n2\n0 0 1 2\n4 1 1 5\n0 0 0\n", "line 4: job 2's successor 5 is outside 1..3"),
])
def test_bad_patterson_files_name_the_line(tmp_path, text, message):
    path = tmp_path / "bad.rcp"
    path.write_text(text)
    with pytest.raises(InstanceError, match=re.escape(message)):
        import_psplib(path)


def test_lvws_import_psplib(tmp_path):
    out = tmp_path / "j301_1.json"
    done = subprocess.run([sys.executable, "-m", "lvws_ros.cli", "import", "psplib", str(PSPLIB / "j301_1.sm"),
                           "--out", str(out)], capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    assert load_instance(out) == import_psplib(PSPLIB / "j301_1.sm") and "41 robots, 30 tasks" in done.stdout
    (tmp_path / "bad.rcp").write_text("3 1\n2\n0 0 1 2\n4 1 1\n")
    bad = subprocess.run([sys.executable, "-m", "lvws_ros.cli", "import", "psplib", str(tmp_path / "bad.rcp"),
                          "--out", str(tmp_path / "x.json")], capture_output=True, text=True, check=False)
    assert bad.returncode == 2 and "bad.rcp line 4" in bad.stderr and "Traceback" not in bad.stderr
