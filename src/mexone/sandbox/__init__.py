"""Starting a process for a student's code: the one way mexone does it.

Every piece of student code that runs outside the lab's trust -- a controller's worker, a
routine's process, a graded run -- is started by `spawn` inside a `Jail`: what it may write (its
scratch folder only), read, use (CPU, memory, wall time) and reach (no network), and a handle
that ends it together with everything it started. The policy lives here, once; the protocols
spoken with the process live with their callers.
"""

from mexone.sandbox.spawn import Jail, Limits, StudentProcess, spawn

__all__ = ["Jail", "Limits", "StudentProcess", "spawn"]
