"""ROS names: a namespace checked and made fully qualified, the one rule of the nodes,
the robots' servers, the launcher and the dashboard (rclpy's own validation, imported on
first use so that a module holding a namespace loads without ROS)."""

from __future__ import annotations

from lvws_ros.errors import ConfigError

__all__ = ["check_namespace"]


def check_namespace(namespace: str, option: str = "") -> str:
    """``namespace`` made fully qualified ('' stays ''), or ConfigError naming it; with
    ``option`` (the command-line option it came from) the error names the option and
    rclpy's reason too."""
    if not namespace:
        return ""
    from rclpy.exceptions import InvalidNamespaceException
    from rclpy.validate_namespace import validate_namespace

    ns = namespace if namespace.startswith("/") else f"/{namespace}"
    try:
        validate_namespace(ns)
    except InvalidNamespaceException as exc:
        if option:
            raise ConfigError(f"{option} {namespace!r}: not a valid ROS namespace ({exc})") from None
        raise ConfigError(f"namespace {namespace!r} is not a valid ROS namespace") from None
    return ns
