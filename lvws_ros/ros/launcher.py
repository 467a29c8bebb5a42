"""``lvws launch``: simulator + scheduler + recorder as separate processes (launch_ros is
not on pip, so this is plain Python).

The three run on a DDS domain (a random ROS_DOMAIN_ID unless given, localhost discovery),
in the namespace ``namespace`` when given (``-r __ns:=/NAME`` and the cell's own clock,
``-r /clock:=clock``), so several cells can share one domain, each with its own bag.
Scheduler parameters: explicit arguments (``policy``, ``seed``, ``model_path``) win over
the parameter file, which wins over the launcher's defaults. While the run goes on, the
simulator's progress (sim time, tasks done, decisions) is printed every few seconds.
The recorder starts first and the simulator waits for both other nodes, so the bag
holds the whole run. When the simulator finishes, the scheduler and recorder get
SIGINT (then SIGTERM, then SIGKILL if they hang); on Ctrl-C, SIGTERM or a crashed child
every child is stopped the same way and the launcher exits non-zero with the reason.
Children also get SIGTERM from the kernel if the launcher itself dies (PR_SET_PDEATHSIG),
so no orphan outlives it.
"""

from __future__ import annotations

import ctypes
import json
import os
import random
import secrets
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import yaml

from lvws_ros.errors import ConfigError, LaunchError, PolicyError
from lvws_ros.ros.topics import CLOCK_REMAP
from lvws_ros.rosbase.names import check_namespace

PR_SET_PDEATHSIG = 1
DASHBOARD_TOKEN_ENV = "LVWS_DASHBOARD_TOKEN"  # the dashboard's token, given by the environment (never printed)


def new_token() -> str:
    """A fresh token for a dashboard (:func:`secrets.token_urlsafe`: 32 random bytes)."""
    return secrets.token_urlsafe(32)


def _die_with_parent() -> None:
    try:
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
    except OSError:  # not Linux: the launcher's own handlers still stop the children
        pass


@dataclass
class Child:
    name: str
    proc: subprocess.Popen[bytes]
    log_path: Path
    log: IO[bytes]

    def alive(self) -> bool:
        return self.proc.poll() is None


@dataclass
class LaunchResult:
    bag: Path
    out_dir: Path
    summary: dict[str, Any]
    gif: Path | None = None
    codes: dict[str, int | None] = field(default_factory=dict)


def stop(children: Sequence[Child], grace: float = 10.0) -> dict[str, int | None]:
    """SIGINT, then SIGTERM, then SIGKILL; returns each child's exit code."""
    for sig, wait in ((signal.SIGINT, grace), (signal.SIGTERM, 5.0), (signal.SIGKILL, 5.0)):
        live = [c for c in children if c.alive()]
        if not live:
            break
        for c in live:
            c.proc.send_signal(sig)
        end = time.monotonic() + wait
        while time.monotonic() < end and any(c.alive() for c in live):
            time.sleep(0.05)
    for c in children:
        c.log.close()
    return {c.name: c.proc.poll() for c in children}


def check_port(host: str, port: int) -> None:
    """LaunchError when nothing can listen on ``host:port`` (taken, or not an address here)."""
    with socket.socket() as probe:
        try:
            probe.bind((host, port))
        except OSError as exc:
            raise LaunchError(f"cannot serve on {host}:{port}: {exc.strerror or exc}") from None


def _tail(path: Path, lines: int = 15) -> str:
    try:
        return "\n".join(path.read_text(errors="replace").splitlines()[-lines:])
    except OSError:
        return ""


def _commands(bag: Path, *, policy: str | None, seed: int | None, model_path: str, rate: float, config: str,
              file_params: dict[str, Any], summary: Path, gif: Path | None, sync: bool,
              namespace: str = "", events: str | None = None, dashboard: int | None = None,
              protocol: str = "snapshots", retire_after: float = -1.0, instance: str = "") -> dict[str, list[str]]:
    """The children's command lines, recorder first, simulator last (the dashboard, when
    asked for, before the simulator)."""
    from lvws_ros.ros.scheduler_node import DEFAULT_POLICY

    # one precedence, applied here: explicit arguments > the parameter file (its values for
    # this node, ``file_params``) > our defaults; the file's values go on as -p (rcl would
    # not match a file's `scheduler:` to /<ns>/scheduler)
    audience = 3 if dashboard is not None else 2  # the recorder, the world or the scheduler, and the dashboard
    defaults = {"policy": DEFAULT_POLICY, "seed": 0, "use_sim_time": True, "expect_subscribers": audience}
    explicit = {k: v for k, v in (("policy", policy), ("seed", seed), ("model_path", model_path or None))
                if v is not None}
    sched: dict[str, object] = {**defaults, **file_params, **explicit}
    sched_params = [a for k, v in sched.items() for a in ("-p", f"{k}:={_param(v)}")]
    sim_params = ["-p", f"rate:={float(rate)}", "-p", f"summary:={summary}", "-p", f"expect_subscribers:={audience}",
                  "-p", f"sync:={'true' if sync else 'false'}", "-p", f"protocol:={protocol}",
                  "-p", f"retire_after:={float(retire_after)}"]
    wait = float(str(sched.get("first_plan_wait", 0.0) or 0.0))  # the first decision waits that long for the plan:
    if wait > 0:  # so does the simulator, for that decision (its own wait is 5 s of wall time)
        sim_params += ["-p", f"first_sync_timeout:={wait + 5.0}"]
    if gif is not None:
        sim_params += ["-p", f"gif:={gif}"]
    if config:
        sim_params += ["-p", f"config:={config}"]
    if instance:  # the simulator runs an instance file instead of an assembly-cell config
        sim_params += ["-p", f"instance:={Path(instance).resolve()}"]
    if events:
        sim_params += ["-p", f"events:={Path(events).resolve()}"]
    ns = ["-r", f"__ns:={namespace}", *CLOCK_REMAP] if namespace else []
    out = {
        "recorder": [sys.executable, "-m", "lvws_ros.ros.recorder", "-o", str(bag), "--ros-args", *ns,
                     "-p", "use_sim_time:=true"],
        "scheduler": [sys.executable, "-m", "lvws_ros.ros.scheduler_node", "--ros-args", *ns, *sched_params],
    }
    if dashboard is not None:
        out["dashboard"] = [sys.executable, "-m", "lvws_ros.ros.dashboard", "--port", str(dashboard),
                            *(["--namespace", namespace] if namespace else [])]
    out["cell_sim"] = [sys.executable, "-m", "lvws_ros.ros.cell_sim_node", "--ros-args", *ns, *sim_params]
    return out


def actions_cell(out: Path, config: str = "", instance: str = "") -> Path:
    """The cell of a run with ``--robots actions``: ``instance`` (checked), else the
    simulator's cell (``config``, default the case study) written as an instance file."""
    from lvws_ros.core.formats import load_instance, save_instance

    if instance:
        load_instance(instance)
        return Path(instance).resolve()
    from lvws_ros.ros.resources import case_study_config
    from lvws_ros.sim.config import load_cell_config
    from lvws_ros.sim.world import CellSim

    path = out / "cell.json"
    save_instance(CellSim(load_cell_config(config or case_study_config())).inst, path)
    return path.resolve()


def _actions_commands(commands: dict[str, list[str]], cell: Path, rate: float, summary: Path,
                      namespace: str, audience: int) -> dict[str, list[str]]:
    """``commands`` with the dispatcher and fake robots (``lvws fake-robots``) in place of
    the simulator. At rate 1 every node is on wall time; at another rate the robots run that
    much faster on wall time, and the dispatcher publishes the cell's clock, which the
    scheduler and the recorder follow (use_sim_time)."""
    def wall(cmd: list[str]) -> list[str]:  # without "-p use_sim_time:=..."
        drop = {k for k, a in enumerate(cmd) if a.startswith("use_sim_time:=") and k and cmd[k - 1] == "-p"}
        return [a for k, a in enumerate(cmd) if k not in drop and k + 1 not in drop]

    real_time = float(rate) == 1.0
    out = {name: wall(cmd) if real_time else cmd for name, cmd in commands.items() if name != "cell_sim"}
    if not real_time and not any(a.startswith("ack_timeout:=") for a in out["scheduler"]):
        from lvws_ros.ros.scheduler_node import PARAMETERS  # the wall seconds of the default, on the cell's clock

        out["scheduler"] += ["-p", f"ack_timeout:={float(PARAMETERS['ack_timeout'].default) * float(rate)}"]
    sim = commands["cell_sim"]  # the world's protocol, the same for the dispatcher
    protocol = [x for k, a in enumerate(sim) if k and sim[k - 1] == "-p"
                and a.startswith(("protocol:=", "retire_after:=")) for x in ("-p", a)]
    ns = ["-r", f"__ns:={namespace}"] if namespace else []
    out["fake_robots"] = [sys.executable, "-m", "lvws_ros.robot.fake", str(cell), "--rate", str(float(rate)),
                          *(["--namespace", namespace] if namespace else [])]
    out["dispatcher"] = [sys.executable, "-m", "lvws_ros.ros.dispatcher_node", str(cell), "--ros-args", *ns,
                         "-p", "exit_when_done:=true", "-p", f"summary:={summary}",
                         "-p", f"expect_subscribers:={audience}", "-p", f"rate:={float(rate)}",
                         "-p", f"publish_clock:={'false' if real_time else 'true'}", *protocol]
    return out


def _param(value: object) -> str:
    """A value as ``-p name:=value`` takes it (YAML; a string that YAML would read as
    another type is quoted)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return value if isinstance(yaml.safe_load(value or "''"), str) else f"'{value}'"
    return str(value)


def _check_inputs(policy: str | None, model_path: str, config: str, params_file: str | None,
                  events: str | None = None, namespace: str = "", instance: str = "",
                  robots: str = "sim") -> dict[str, Any]:
    """Every input checked before anything starts; the parameter file's scheduler values."""
    if instance:
        from lvws_ros.core.formats import load_instance
        from lvws_ros.sim.instance_sim import check_alone

        if robots != "actions":  # the simulator runs it
            check_alone(instance, config, events or "")
        load_instance(instance)
    from lvws_ros.registry import POLICY_NAMES
    from lvws_ros.ros.resources import case_study_config
    from lvws_ros.ros.scheduler_node import check_params_file
    from lvws_ros.sim.config import load_cell_config

    load_cell_config(config or case_study_config())
    if events:
        from lvws_ros.sim.events import load_events

        load_events(events)
    in_file = check_params_file(params_file, namespace=namespace) if params_file else {}
    if policy is not None and policy not in POLICY_NAMES:
        raise PolicyError(f"unknown policy {policy!r}; choose one of {', '.join(POLICY_NAMES)}")
    if model_path and not Path(model_path).is_file():
        raise ConfigError(f"{model_path}: no such model file")
    return in_file


def _domain_in_use(domain: int) -> bool:
    """Whether a DDS participant on this machine holds ``domain``: the metatraffic unicast
    port of its first participant (the RTPS default port mapping, 7410 + 250 x domain) is
    bound."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        try:
            probe.bind(("0.0.0.0", 7410 + 250 * domain))
        except OSError:
            return True
    return False


def free_domain() -> int:
    """A random ROS_DOMAIN_ID in 1-101 that is neither this process's own nor held by a
    participant on this machine (any other if all are taken), so that a run's recorder never
    hears another cell's topics."""
    own = os.environ.get("ROS_DOMAIN_ID", "0")
    candidates = [d for d in range(1, 102) if str(d) != own]
    random.SystemRandom().shuffle(candidates)
    return next((d for d in candidates if not _domain_in_use(d)), candidates[0])


def _child_env(domain_id: int | None) -> dict[str, str]:
    env = dict(os.environ)
    env["ROS_DOMAIN_ID"] = str(domain_id if domain_id is not None else free_domain())
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env.setdefault("AMENT_PREFIX_PATH", sys.prefix)
    env["PYTHONUNBUFFERED"] = "1"
    return env


def _start(commands: dict[str, list[str]], env: dict[str, str], out: Path, children: list[Child],
           interrupted: list[int], own_env: dict[str, dict[str, str]] | None = None) -> None:
    """Start the children in order (``own_env``: variables for one child alone)."""
    for cname, cmd in commands.items():
        log_path = out / f"{cname}.log"
        fh = open(log_path, "wb")
        proc = subprocess.Popen(cmd, env={**env, **(own_env or {}).get(cname, {})}, stdout=fh,
                                stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                preexec_fn=_die_with_parent)
        children.append(Child(cname, proc, log_path, fh))
        tmp = out / "pids.json.tmp"
        tmp.write_text(json.dumps({c.name: c.proc.pid for c in children}))
        tmp.replace(out / "pids.json")  # atomic: readers never see half a file
        if cname == "recorder":
            _wait_for_line(children[-1], "recording to", 60.0, interrupted)
        if cname == "dashboard":
            _wait_for_line(children[-1], "dashboard: http", 60.0, interrupted)


PROGRESS_EVERY = 3.0  # wall seconds between progress lines


def _progress(sim: Child) -> str:
    """The simulator's latest progress line ('' before the first)."""
    try:
        lines = [ln for ln in sim.log_path.read_text(errors="replace").splitlines() if "progress:" in ln]
    except OSError:
        return ""
    return lines[-1].split("progress:", 1)[1].strip() if lines else ""


def _supervise(children: list[Child], timeout: float, t0: float, interrupted: list[int], log: Any = print) -> None:
    """Until the simulator (the last child) exits, printing its progress; LaunchError when
    anything goes wrong."""
    sim = children[-1]
    shown, next_show, said = "", time.monotonic() + PROGRESS_EVERY, time.monotonic()
    while sim.alive():
        if time.monotonic() >= next_show:
            next_show += PROGRESS_EVERY
            now = _progress(sim)
            if now and (now != shown or time.monotonic() - said >= 2.5 * PROGRESS_EVERY):  # new, or still so
                log(f"  [{time.monotonic() - t0:5.1f} s] {now}{'' if now != shown else ' (still)'}")
                shown, said = now, time.monotonic()
        if interrupted:
            raise LaunchError(f"interrupted by signal {signal.Signals(interrupted[0]).name}")
        for c in children[:-1]:
            if not c.alive():
                raise LaunchError(f"{c.name} exited early with code {c.proc.returncode}:\n{_tail(c.log_path)}")
        if time.monotonic() - t0 > timeout:
            raise LaunchError(f"the run did not finish within {timeout:g} s")
        time.sleep(0.1)
    if sim.proc.returncode != 0:
        raise LaunchError(f"cell_sim exited with code {sim.proc.returncode}:\n{_tail(sim.log_path)}")


def launch(*, policy: str | None = None, seed: int | None = None, model_path: str = "", rate: float = 20.0,
           config: str = "", bag_dir: str | Path = "bags", out_dir: str | Path = "out", name: str | None = None,
           params_file: str | None = None, gif: bool = True, timeout: float = 600.0,
           domain_id: int | None = None, sync: bool = True, namespace: str = "", events: str | None = None,
           dashboard: int | None = None, robots: str = "sim", instance: str = "", protocol: str = "snapshots",
           retire_after: float = -1.0, log: Any = print) -> LaunchResult:
    """Run the case study end to end; raises LaunchError (children stopped) on failure.
    The configuration, the parameter file, the policy, the model and the namespace are
    checked before any process starts (ConfigError / PolicyError). ``policy``/``seed``
    None: the parameter file's, else the scheduler's defaults. ``dashboard``: also serve the
    web dashboard of the run on this port (127.0.0.1) while it lasts, with a new token (the
    printed URL carries it). ``robots="actions"``: the dispatcher and fake robots (ExecuteTask
    servers at ``rate``) instead of the simulator, on the cell ``instance`` (an
    lvws-instance/1 file; default: the simulator's cell written as one), on wall time.
    ``protocol="changes"``: the simulator sends numbered changes after its first snapshots
    (``retire_after`` >= 0: with done work retiring that many sim seconds after it ended)."""
    from lvws_ros.ros.scheduler_node import DEFAULT_POLICY

    namespace = check_namespace(namespace, "--namespace")
    if dashboard is not None:
        check_port("127.0.0.1", dashboard)  # before anything starts
    in_file = _check_inputs(policy, model_path, config, params_file, events, namespace, instance, robots)
    run, bag, out = _run_dirs(name, namespace, policy or str(in_file.get("policy", DEFAULT_POLICY)), bag_dir, out_dir)
    summary_path = out / "summary.json"
    gif_path = out / "run.gif"
    commands = _commands(bag, policy=policy, seed=seed, model_path=model_path, rate=rate, config=config,
                         file_params=in_file, summary=summary_path, gif=gif_path if gif else None, sync=sync,
                         namespace=namespace, events=events, dashboard=dashboard, protocol=protocol,
                         retire_after=retire_after, instance=instance if robots != "actions" else "")
    if robots == "actions":
        commands = _actions_commands(commands, actions_cell(out, config, instance), rate, summary_path, namespace,
                                     3 if dashboard is not None else 2)
    children: list[Child] = []
    interrupted: list[int] = []

    def on_signal(signum: int, _frame: Any) -> None:
        interrupted.append(signum)

    old = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    t0 = time.monotonic()
    try:
        env = _child_env(domain_id)
        token = new_token()  # the dashboard's, in its environment: its log does not show it
        _start(commands, env, out, children, interrupted, {"dashboard": {DASHBOARD_TOKEN_ENV: token}})
        log(f"running {run}{' in ' + namespace if namespace else ''} (domain {env['ROS_DOMAIN_ID']}); logs in {out}")
        if dashboard is not None:
            log(f"dashboard: http://127.0.0.1:{dashboard}/?token={token} (while the run lasts)")
        _supervise(children, timeout, t0, interrupted, log)
    except BaseException:
        codes = stop(children)
        log(f"children stopped: {codes}; logs in {out}")
        raise
    finally:
        for s, h in old.items():
            signal.signal(s, h)
    log(f"  [{time.monotonic() - t0:5.1f} s] the run is over: stopping the other nodes (the recorder closes the bag)")
    codes = stop(children)
    summary = _complete_summary(summary_path, t0, codes)
    return LaunchResult(bag, out, summary, gif_path if gif_path.is_file() else None, codes)


def _run_dirs(name: str | None, namespace: str, label: str, bag_dir: str | Path, out_dir: str | Path
              ) -> tuple[str, Path, Path]:
    """The run's name (default: the case study, the cell's namespace, the policy's ``label``
    and the time), its bag (LaunchError if it exists) and its output folder (made)."""
    cell = f"{namespace.strip('/').replace('/', '-')}-" if namespace else ""
    run = name or time.strftime(f"case-study-{cell}{label}-%Y%m%d-%H%M%S")
    bag = Path(bag_dir) / run
    out = Path(out_dir) / run
    if bag.exists():
        raise LaunchError(f"{bag} already exists")
    out.mkdir(parents=True, exist_ok=True)
    return run, bag, out


def _complete_summary(summary_path: Path, t0: float, codes: dict[str, int | None]) -> dict[str, Any]:
    """The summary the world wrote (none: empty), with the run's wall seconds since ``t0``
    (monotonic) and the children's exit codes added, written back."""
    summary = json.loads(summary_path.read_text()) if summary_path.is_file() else {}
    summary.update({"wall_seconds_total": time.monotonic() - t0, "exit_codes": codes})
    summary_path.write_text(json.dumps(summary, indent=1))
    return summary


def _wait_for_line(child: Child, text: str, timeout: float, interrupted: list[int]) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if interrupted:
            raise LaunchError(f"interrupted by signal {signal.Signals(interrupted[0]).name}")
        if not child.alive():
            raise LaunchError(f"{child.name} exited with code {child.proc.returncode}:\n{_tail(child.log_path)}")
        if text in child.log_path.read_text(errors="replace"):
            return
        time.sleep(0.05)
    raise LaunchError(f"{child.name} not ready after {timeout:g} s")
