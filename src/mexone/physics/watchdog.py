"""The former name of `mexone.physics.divergence` (issue 40: two unrelated modules were called
watchdog; the student code's is `mexone.control.watchdog`). Kept for one release, with a
warning."""

from mexone.errors import warn_renamed
from mexone.physics.divergence import DivergenceError, Watchdog, link_speeds

__all__ = ["DivergenceError", "Watchdog", "link_speeds"]

warn_renamed("mexone.physics.watchdog", "mexone.physics.divergence")
