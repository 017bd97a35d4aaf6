"""Starting a process for a student's code: the one way mexone does it.

Every piece of student code that runs outside the lab's trust -- a controller's worker, a
routine's process, a graded run -- is started by `spawn` inside a `Jail`: what it may write (its
scratch folder only), read, use (CPU, memory, wall time) and reach (no network), and a handle
that ends it together with everything it started. The policy lives here, once (confine.py the
layers, spawn.py what this machine offers and one jail's plan); the protocols spoken with the
process live with their callers. `isolation()` says what the machine offers.
"""

from mexone.sandbox.spawn import (
    Isolation,
    Jail,
    Limits,
    StudentProcess,
    isolation,
    keep_private,
    spawn,
)

__all__ = ["Jail", "Limits", "StudentProcess", "spawn", "Isolation", "isolation", "keep_private"]
