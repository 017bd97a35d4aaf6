"""Who may drive the simulator from a browser: the page mexone served, nobody else.

Any web page the user has open can open a websocket to ws://127.0.0.1:8080. A browser always
sends the page's Origin with that handshake, so the server refuses a websocket whose Origin is
not the page it served itself (same scheme, host and port as the request's Host header), and a
Host header that names some other site (DNS rebinding: evil.example resolving to 127.0.0.1).
Clients that send no Origin are not web pages (scripts, tests) and pass the Origin check. The
rule itself is mexone.origins', which the Foxglove bridge applies too.

viser has no hook for this, so the check runs as the first connect callback of its websocket
server, before the client's first message is read; tests/gui/test_gui_security.py keeps that true
across viser releases.
"""

from __future__ import annotations

import logging
import sys

import viser

from mexone.origins import allowed, is_loopback  # the rule, shared with the Foxglove bridge

__all__ = ["guard", "allowed", "is_loopback", "warn_if_exposed"]

log = logging.getLogger("mexone.gui")


def guard(server: viser.ViserServer) -> None:
    """Refuse foreign websocket clients of `server` before they can send anything."""
    ws = server._websock_server  # noqa: SLF001 - viser offers no public hook (see module doc)

    async def check(client) -> None:
        connection = ws._live_connections.get(client.client_id)  # noqa: SLF001
        if connection is None:
            return
        headers = connection.request.headers
        origins, hosts = headers.get_all("Origin"), headers.get_all("Host")
        if len(origins) > 1 or len(hosts) != 1:
            ok, reason = False, "several Origin or Host headers"
        else:
            ok, reason = allowed(origins[0] if origins else None, hosts[0])
        if not ok:
            log.warning("refused a websocket client: %s", reason)
            await connection.close(1008, "origin not allowed")

    ws._client_connect_cb.insert(0, check)  # noqa: SLF001 - first, before viser's own


def warn_if_exposed(host: str, port: int) -> None:
    """Say loudly when the GUI listens beyond this machine, and where it really listens."""
    if is_loopback(host):
        return
    shown = host or "0.0.0.0"
    print(f"mexone: WARNING: the GUI listens on {shown}:{port}: anyone who can reach this "
          "machine on the network can control the simulator and start its routines "
          "(use --host 127.0.0.1 to keep it to this machine)", file=sys.stderr)
