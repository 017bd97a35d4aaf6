"""IsolatedRoutineRunner: a routine in a process of its own (routines.remote), the simulation here.

The grader's way to run a student's routine: the routine's process is a fresh interpreter in a
jail (mexone.sandbox.spawn: it reads the routine and Python, writes a scratch folder, has CPU-time
and memory limits and no network), holding nothing of this process (the lab, its varied model,
the grader's state); it reaches the simulation only through mexone.rospy, in JSON read against
the protocol's schema (routines.remote). Here a proxy thread stands
for it in the runtime's Scheduler, exactly where the routine's own thread stands in-process: it
holds the clock while the routine computes, waits when the routine waits, and hands it the
messages delivered meanwhile. So the lockstep, the stall watchdog (a routine that stops yielding
is abandoned after `stall` s) and determinism are those of `mexone run`.
"""

from __future__ import annotations

import contextlib
import signal
import socket
import sys
import time
from pathlib import Path

from mexone import rospy
from mexone.errors import MexoneError
from mexone.routines import remote
from mexone.routines.runner import Routine, RoutineRunner
from mexone.routines.runtime import RoutineContext, Shutdown, bind
from mexone.sandbox import Jail, Limits, spawn

__all__ = ["IsolatedRoutineRunner"]

GRACE = 0.5  # wall s the routine's process gets to end by itself once the simulation ended


class _Failed(Exception):
    """The routine's process did something the protocol does not allow, or ended early."""


class _Late(Exception):
    """The routine's process did not end within GRACE."""


class IsolatedRoutineRunner(RoutineRunner):
    """RoutineRunner whose routines each run in their own process (limits: `cpu` s of CPU time,
    `memory_mb` MB of address space). Same interface, same lockstep."""

    def __init__(self, *args, cpu: float = 60.0, memory_mb: int = 2048, **kwargs):
        super().__init__(*args, **kwargs)
        self.cpu = cpu
        self.memory_mb = memory_mb

    def _main(self, entry: Routine, ready) -> None:  # the proxy thread
        context = entry.context
        bind(context)
        self.scheduler.enter(context)
        ready.set()
        proxy = None
        try:
            self._arguments(entry)
            with self.scheduler.busy("the start of the routine's process"):
                proxy = _Proxy(self, context, entry.path)
                if self._children is not None:
                    self._children.add(proxy.process.pid)  # ours to end, not a leak
                proxy.started()
            entry.error, entry.line = proxy.serve()
        except Shutdown:  # the simulation ended or gave up on the routine
            pass
        except _Failed as exc:
            entry.error = str(exc)
        except Exception as exc:  # noqa: BLE001 - a malformed request of the routine's process
            entry.error = (f"the routine's process sent a malformed request "
                           f"({type(exc).__name__}: {exc})")
        finally:
            if proxy is not None:
                proxy.close()
            if context.abandoned and not entry.error:
                entry.error = context.abandoned
            self.scheduler.leave()
            bind(None)


class _Proxy:
    """The simulator's end of one routine's socket."""

    def __init__(self, runner: IsolatedRoutineRunner, context: RoutineContext, path: Path):
        self.runner = runner
        self.context = context
        self.lab = context.lab
        ours, theirs = socket.socketpair()
        self.sock = ours
        jail = Jail(readable=(path,), limits=Limits(cpu=runner.cpu, memory_mb=runner.memory_mb),
                    another_user=True)  # a grader's: a uid of the pool as root
        try:
            self.process = spawn([sys.executable, "-m", "mexone.routines.remote",
                                  str(theirs.fileno())], jail, pass_fds=(theirs.fileno(),))
        finally:
            theirs.close()
        self.publishers: dict[str, rospy.Publisher] = {}
        self.subscriptions: dict[int, object] = {}
        self.outbox: list[tuple[int, object]] = []
        plain = {k: v for k, v in self.runner.params.items() if remote.plain(v)}
        private = {k: v for k, v in context.private.items() if remote.plain(v)}
        remote.send(ours, ("hello", str(path), context.node_name, plain, self.lab.sim.time,
                           self.lab.sim.time_ns, private, context.name_remap))

    def started(self) -> None:
        """Wait for the routine's process to be ready to run the routine (an interpreter's
        start is mexone's time, not the routine's: the stall watchdog allows it more)."""
        _, call = self._receive()
        if call != ["ready"]:
            raise _Failed("the routine's process did not start")

    def serve(self) -> tuple[str | None, int | None]:
        """Answer the routine until it ends: (its error, its line)."""
        while True:
            ops, call = self._receive()
            for op in ops:
                self._apply(op)
            kind = call[0]
            if kind == "wait":
                self._wait(call)
            elif kind == "count":
                topic = self.lab.bus.topics.get(str(call[1])) if len(call) == 2 else None
                remote.send(self.sock, ("count", len(topic.subscriptions) if topic else 0))
            elif kind == "end" and len(call) == 4:
                _, error, line, errors = call
                self.context.errors.extend(str(e) for e in errors or ())
                with contextlib.suppress(OSError):
                    remote.send(self.sock, ("bye",))
                return (None if error is None else str(error),
                        line if isinstance(line, int) else None)
            else:
                raise _Failed(f"the routine's process sent an unknown request {kind!r}")

    def _wait(self, call: list) -> None:
        if len(call) != 2 or isinstance(call[1], bool) or not isinstance(call[1], int | float):
            raise _Failed(f"the routine's process sent a malformed request (ValueError: wait "
                          f"until {str(call[1:])[:40]})")
        wake = float(call[1])
        try:
            self.runner.scheduler.wait(wake, ready=lambda: bool(self.outbox))
        except Shutdown:
            self._goodbye()
            raise
        delivered, self.outbox = self.outbox, []
        remote.send(self.sock, ("time", self.lab.sim.time, self.lab.sim.time_ns, delivered))

    def _goodbye(self) -> None:
        """The simulation ended: tell the routine (its sleep raises ROSInterruptException) and
        give it GRACE s to end, its last requests answered with the same."""
        self.runner.scheduler.leave()  # not holding the clock (nor interrupted) meanwhile
        deadline = time.monotonic() + GRACE

        def poll() -> None:
            if time.monotonic() > deadline:
                raise _Late

        with contextlib.suppress(Exception):
            remote.send(self.sock, ("shutdown",))
            while True:
                _, call = remote.receive(self.sock, poll)
                if call[0] == "end" and len(call) == 4:
                    self.context.errors.extend(str(e) for e in call[3] or ())
                    if call[1] is not None:
                        self.context.errors.append(str(call[1]))
                    remote.send(self.sock, ("bye",))
                    return
                remote.send(self.sock, ("shutdown",) if call[0] == "wait" else ("count", 0))

    def _receive(self) -> tuple[list, list]:
        try:
            message = remote.receive(self.sock, _idle)
        except remote.ProtocolError as exc:
            raise _Failed(self._ended() or f"the routine's process sent what mexone cannot read: "
                          f"{exc}") from None
        except OSError:
            raise _Failed(self._ended() or "the routine's process hung up") from None
        if not (len(message) == 2 and isinstance(message[0], list)
                and isinstance(message[1], list) and message[1]
                and isinstance(message[1][0], str)):
            raise _Failed("the routine's process sent a malformed request")
        return message

    def _ended(self) -> str | None:
        """Why the routine's process ended, if it did (it is waited for up to a second)."""
        status = self.process.wait(timeout=1.0)
        if status is None:
            return None
        if status >= 0:
            return (f"the routine's process ended (exit status {status}) before the routine "
                    "returned (end a routine by returning, or with sys.exit)")
        sig = -status
        if sig == signal.SIGXCPU:
            return f"the routine used more than {self.runner.cpu:g} s of CPU time"
        if sig == signal.SIGKILL:
            return "the routine's process was killed (out of memory?)"
        try:
            shown = signal.Signals(sig).name
        except ValueError:
            shown = f"signal {sig}"
        return f"the routine's process crashed ({shown})"

    def _apply(self, op: object) -> None:
        """One of the routine's queued requests, as its rospy call would do it in-process."""
        if not isinstance(op, list) or not op:
            raise _Failed("the routine's process sent a malformed request")
        kind, args = op[0], op[1:]
        try:
            if kind == "pub" and len(args) == 2:
                publisher = self.publishers.get(args[0]) if isinstance(args[0], str) else None
                if publisher is None:
                    raise _Failed(f"the routine published on {str(args[0])[:60]!r} before "
                                  "advertising it")
                publisher.publish(remote.message(args[1], publisher.data_class))
            elif kind == "adv" and len(args) == 2 and isinstance(args[0], str):
                self.publishers[args[0]] = rospy.Publisher(args[0], remote.message_type(args[1]))
            elif kind == "sub" and len(args) == 4 and isinstance(args[1], str) \
                    and isinstance(args[0], int):
                sid, name, msg_type, node = args
                self.context.node_name = str(node) or self.context.node_name
                deliver = self.context.deliver
                outbox_add = self._deliver
                self.subscriptions[int(sid)] = self.lab.bus.subscribe(
                    name, remote.message_type(msg_type),
                    lambda msg, sid=int(sid): deliver(outbox_add, (sid, msg)),
                    node=self.context.node_name)
            elif kind == "unsub" and len(args) == 1 and isinstance(args[0], int):
                sub = self.subscriptions.pop(args[0], None)
                if sub is not None:
                    sub.unregister()
            elif kind == "param" and len(args) == 2 and isinstance(args[0], str) \
                    and remote.plain(args[1]):
                self.runner.params[args[0]] = args[1]
            elif kind == "unparam" and len(args) == 1 and isinstance(args[0], str):
                self.runner.params.pop(args[0], None)
            elif kind == "node" and len(args) == 1 and isinstance(args[0], str):
                self.context.node_name = args[0]  # init_node's: declared_duration reads it
            elif kind == "log" and len(args) == 2:
                self.context.log(str(args[0]), str(args[1]))
            else:
                raise _Failed(f"the routine's process sent an unknown request {kind!r}")
        except (_Failed, Shutdown):
            raise
        except remote.ProtocolError as exc:  # a message that is not its topic's type
            raise _Failed(f"the routine's process sent what mexone cannot read: {exc}") from None
        except MexoneError as exc:  # e.g. a topic of another type: as rospy raises in-process
            raise _Failed(exc.one_line()) from None
        except Exception as exc:  # noqa: BLE001 - the routine's request, not the simulator, failed
            raise _Failed(f"the routine's request {kind} failed: {type(exc).__name__}: {exc}") \
                from None

    def _deliver(self, item: tuple[int, object]) -> None:
        self.outbox.append(item)

    def close(self) -> None:
        """End the routine's process (if it has not ended) and forget its subscriptions."""
        for sub in self.subscriptions.values():
            with contextlib.suppress(Exception):
                sub.unregister()
        self.subscriptions.clear()
        with contextlib.suppress(OSError):
            self.sock.close()
        if self.process.poll() is None:
            self.process.wait(timeout=0.2)
        self.process.kill()  # its jail, with whatever it left there


def _idle() -> None:
    """While the routine computes: Python code runs every 50 ms, so the stall watchdog's
    interruption (runtime._interrupt) reaches this thread."""
