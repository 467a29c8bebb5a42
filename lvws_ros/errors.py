"""The one error hierarchy of lvws_ros (as rosbags keeps one ``errors.py``).

Every error a user can cause (a malformed file, an unknown policy name, a bag that is
not a run, a child process that fails) is an :class:`LvwsError` whose message names the
file and the item. The ``lvws`` command turns an ``LvwsError`` (and an ``OSError`` on a
user's path) into exit code 2 with that message; anything else is a bug and shows as
one, with its traceback.
"""

from __future__ import annotations

__all__ = [
    "AssignmentRejected",
    "BagError",
    "ConfigError",
    "DispatchRefused",
    "ExpertError",
    "InstanceError",
    "LaunchError",
    "LvwsError",
    "ModelError",
    "PolicyError",
    "ScheduleError",
    "WorldEventRejected",
    "WorldStuck",
    "dropped_answer",
]


class LvwsError(Exception):
    """Base of every error lvws_ros raises on purpose."""


class InstanceError(LvwsError):
    """An instance (file or object) that breaks the lvws-instance/1 rules."""


class ScheduleError(LvwsError):
    """A schedule file that is not lvws-schedule/1 (structure, not the validity rules)."""


class PolicyError(LvwsError):
    """A policy that is unknown, returned an assignment that breaks the rules, or made no progress."""


class ExpertError(PolicyError):
    """The exact expert cannot handle the instance or found nothing."""


class ModelError(LvwsError):
    """A model checkpoint that is missing, malformed or not of the expected format."""


class ConfigError(LvwsError):
    """A malformed configuration: the simulator's cell YAML, a parameter file."""


class AssignmentRejected(LvwsError):
    """The simulated world cannot execute an assignment (the message says why)."""


class WorldEventRejected(LvwsError):
    """The simulated world cannot take an event: a task to add, cancel, a robot to fail or repair."""


class DispatchRefused(LvwsError):
    """The dispatcher cannot carry out an assignment or a service call (the message names the item)."""


class WorldStuck(LvwsError):
    """A simulated run that can never finish (the message says which tasks and why)."""


class BagError(LvwsError):
    """A bag that cannot be read as a run (missing, truncated, wrong topics)."""


class LaunchError(LvwsError):
    """A launched child process failed or the run did not finish."""


def dropped_answer(exc: BaseException) -> bool:
    """Whether ``exc`` (rclpy's ``RCLError``) is a service answer the middleware would not
    send. Fast DDS refuses one when the client's reader of answers has not matched the
    server 100 ms after the request came ("client will not receive response"); rclpy then
    raises out of the executor, where rclcpp logs a warning and goes on. A node of ours
    goes on too: the client asks again, or says it got no answer."""
    return "failed to send response" in str(exc)
