"""Which web pages may open a websocket to a mexone server: the one rule the web GUI and the
Foxglove bridge both apply to a handshake's Origin and Host headers.

Any web page the user has open can open a websocket to ws://127.0.0.1:PORT; a browser always
sends the page's Origin with that handshake, and the page cannot change it. So a server accepts

- a handshake without Origin (not a web page: a script, a test, a desktop client);
- an Origin that is the page the server served itself (same scheme, host and port as Host);
- where the server says so, an Origin on this machine (loopback: a page served from here) or in
  an explicit allowlist (Foxglove's web app, https://app.foxglove.dev, with --foxglove-origin);

and refuses every other Origin, and a Host header naming another site (DNS rebinding:
evil.example resolving to 127.0.0.1).
"""

from __future__ import annotations

import ipaddress
import socket
from collections.abc import Iterable
from urllib.parse import urlsplit

from mexone.errors import InputError, printable

__all__ = ["allowed", "is_loopback", "origin_of", "FOXGLOVE_WEB_APP"]

FOXGLOVE_WEB_APP = "https://app.foxglove.dev"  # Foxglove's web app connects from this origin
_LOCAL_NAMES = {"localhost", "localhost.localdomain"}


def is_loopback(host: str) -> bool:
    """Whether `host` (a name or an IP literal, IPv6 in brackets or not) is this machine's
    loopback: localhost, 127.0.0.0/8, ::1."""
    if host in _LOCAL_NAMES:
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def _host_ok(hostname: str) -> bool:
    """A Host header we serve: an IP literal (no DNS name, so no rebinding), a loopback name,
    or this machine's own name."""
    if not hostname:
        return False
    try:
        ipaddress.ip_address(hostname.strip("[]"))
        return True
    except ValueError:
        pass
    own = {socket.gethostname().lower(), socket.getfqdn().lower()}
    return hostname.lower() in _LOCAL_NAMES | own


def origin_of(text: str) -> str:
    """An allowlist entry as browsers write an Origin (scheme://host[:port], lower case, no
    path), or an InputError saying what to give."""
    parts = urlsplit(text.strip())
    try:
        port = parts.port
    except ValueError:
        port = -1
    if parts.scheme not in ("http", "https") or not parts.hostname or port == -1 \
            or parts.path not in ("", "/") or parts.query or parts.fragment or parts.username:
        raise InputError(f"origin {printable(text, 80)!r} is not a web origin",
                         hint=f"scheme://host[:port], e.g. {FOXGLOVE_WEB_APP}")
    return f"{parts.scheme}://{parts.netloc.lower()}"


def allowed(origin: str | None, host_header: str | None, trusted: Iterable[str] = (),
            loopback_pages: bool = False, secret_shown: bool = False) -> tuple[bool, str]:
    """(accepted, reason) for a websocket handshake's Origin and Host headers; `trusted`: more
    origins to accept (origin_of's form), `loopback_pages`: accept any page served from this
    machine too; `secret_shown`: the request presented the lab's secret (gui.security's
    LabAccess), so its Host may be a hub's public name (the Origin must still match it)."""
    if not host_header:
        return False, "no Host header"
    hostname = urlsplit(f"//{host_header}").hostname or ""
    if not secret_shown and not _host_ok(hostname):
        return False, f"Host {printable(host_header, 80)!r} is not this machine"
    if origin is None:
        return True, "no Origin: not a web page"
    parts = urlsplit(origin)
    if parts.scheme in ("http", "https") and parts.netloc.lower() == host_header.lower():
        return True, "same origin"
    if origin.strip().lower().rstrip("/") in set(trusted):
        return True, "an allowed origin"
    if loopback_pages and parts.scheme in ("http", "https") and is_loopback(parts.hostname or ""):
        return True, "a page on this machine"
    return False, f"Origin {printable(origin, 80)!r} is not allowed"
