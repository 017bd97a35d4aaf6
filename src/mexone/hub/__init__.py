"""mexone inside JupyterHub: a launcher entry in each student's JupyterLab that opens their own
lab's page, through jupyter-server-proxy (docs/teaching.md).

`setup_lab` is jupyter-server-proxy's entry point (`jupyter_serverproxy_servers` in mexone's
pyproject): the student's Jupyter server calls it once when it starts, as that student, and
starts `mexone sim` on a free loopback port on the first visit of /user/NAME/mexone/. It makes a
per-session secret that only the proxy and the lab know: the lab gets it in its environment
(which other users cannot read, unlike a command line), and the proxy adds it to every request
it forwards (request_headers_override). A request without it -- another student's process on
the same machine's loopback, or any page but the one the hub proxied -- is refused at the
handshake (gui/security.py). The hub itself already keeps one student out of another's server.

A lab with no page open and nothing else to do keeps running; the hub's idle culler
(jupyterhub-idle-culler) stops the whole server when the student has been away long enough, and
the launcher starts a fresh lab on the next visit."""

from __future__ import annotations

import secrets
import sys
from pathlib import Path

from mexone.gui.security import PAGE, TOKEN_ENV, TOKEN_HEADER

__all__ = ["setup_lab", "ICON", "TITLE"]

ICON = Path(__file__).with_name("mexone.svg")
TITLE = "Mex-One lab"
START_SECONDS = 120.0  # a cold start on a busy class machine: importing and compiling the robot


def setup_lab() -> dict:
    """jupyter-server-proxy's server description of the student's lab: the command, its secret
    (in the lab's environment and in the header the proxy adds) and the launcher entry."""
    token = secrets.token_urlsafe(32)
    return {
        "command": [sys.executable, "-m", "mexone", "sim", "--host", "127.0.0.1", "--port", "{port}"],
        "environment": {TOKEN_ENV: token},
        "request_headers_override": {TOKEN_HEADER: token},
        "timeout": START_SECONDS,
        "new_browser_tab": True,
        # the page by its file name: see gui/security.PAGE
        "launcher_entry": {"enabled": True, "title": TITLE, "icon_path": str(ICON),
                           "category": "Notebook", "path_info": f"mexone/{PAGE}"},
    }
