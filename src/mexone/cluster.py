"""A Ray session for the work mexone farms out: a sweep's runs, a class's grading, a region's
rollouts (`--backend ray [--address ADDR]`).

One home for what each of them needs from Ray: the one-line error when Ray is missing, a local
instance sized to the workers asked for (or the cluster at an address), a second try when a
loaded machine made the local node miss Ray's fixed start-up wait, and the session ended by
whoever started it (a notebook's own `ray.init` is left running).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from mexone.errors import InputError, MexoneError, install_extra

__all__ = ["ray_session"]

ATTEMPTS = 3  # starts of a local Ray before giving up (each waits up to Ray's fixed 30 s)


def _import_ray() -> Any:
    try:
        import ray
    except ImportError:
        raise InputError("the ray backend needs Ray", hint=install_extra("cluster")) from None
    return ray


def _start(ray: Any, kwargs: dict[str, Any]) -> None:
    """ray.init, up to ATTEMPTS times when a local node missed Ray's fixed 30 s start-up wait (a
    loaded machine: "The current node timed out during startup"), then a one-line error."""
    for _ in range(ATTEMPTS):
        try:
            ray.init(include_dashboard=False, log_to_driver=False, configure_logging=False, **kwargs)
            return
        except Exception as exc:  # Ray raises a bare Exception for this one
            if "timed out during startup" not in str(exc):
                raise
            ray.shutdown()
    raise MexoneError(f"a local Ray did not start: its node missed Ray's 30 s start-up wait "
                      f"{ATTEMPTS} times", hint="the machine is too busy now: try again later, "
                      "or use the local backend")


@contextmanager
def ray_session(cpus: int, address: str | None = None) -> Iterator[Any]:
    """The `ray` module with a session running: the one already running in this process, else
    the cluster at `address` (`ray://head:10001`, `auto`), else a local instance of `cpus`
    CPUs whose workers inherit this process's environment. A session started here ends on
    leaving; a missing Ray is an InputError naming the extra that installs it."""
    ray = _import_ray()
    started = not ray.is_initialized()
    if started:
        _start(ray, {"address": address} if address else {"num_cpus": max(1, cpus)})
    try:
        yield ray
    finally:
        if started:
            ray.shutdown()
