"""Who may open the simulator's page and drive it: the page mexone served, nobody else.

Any web page the user has open can open a websocket to ws://127.0.0.1:8080. A browser always
sends the page's Origin with that handshake, so the server refuses a websocket whose Origin is
not the page it served itself (same scheme, host and port as the request's Host header), and a
Host header that names some other site (DNS rebinding: evil.example resolving to 127.0.0.1).
Clients that send no Origin are not web pages (scripts, tests) and pass the Origin check. The
rule itself is mexone.origins', which the Foxglove bridge applies too.

On a machine shared by many users (a JupyterHub: every student's lab listens on the same
loopback) the Origin is no fence: another user's process can connect to 127.0.0.1:PORT and say
anything. There the lab holds a per-session secret (`LabAccess.token`), and every HTTP request
and websocket handshake must present it: in the header the hub's proxy adds for the launcher
entry (`TOKEN_HEADER`, jupyter-server-proxy's request_headers_override), in the URL mexone prints
or a notebook shows (`?mexone-token=`), or in the cookie that first visit sets (HttpOnly,
SameSite=Strict, scoped to the lab's own path). The secret never appears in a command line
(/proc/PID/cmdline is world-readable; a process's environment is not). With the secret, the Host
may be the hub's public name: the request came through the student's own authenticated Jupyter
server, which checked the Origin too, and this server checks it again (same origin).

viser has no hook for this, so the check runs inside the websockets library's opening handshake
(one wrapper, installed once, that applies only to the event loops of guarded servers): a
refused request gets HTTP 403 before anything is served or upgraded.
tests/gui/test_gui_security.py keeps that true across viser and websockets releases.
"""

from __future__ import annotations

import asyncio
import hmac
import http
import logging
import os
import secrets
import sys
import threading
import weakref
from dataclasses import dataclass
from http.cookies import CookieError, SimpleCookie
from urllib.parse import parse_qs, urlsplit

import viser
from websockets.asyncio import server as ws_server

from mexone.origins import allowed, is_loopback  # the rule, shared with the Foxglove bridge

__all__ = ["guard", "allowed", "is_loopback", "warn_if_exposed", "LabAccess", "lab_access",
           "TOKEN_ENV", "TOKEN_HEADER", "TOKEN_PARAM"]

log = logging.getLogger("mexone.gui")

TOKEN_ENV = "MEXONE_LAB_TOKEN"  # the secret a hub's launcher hands the lab it starts
TOKEN_HEADER = "X-Mexone-Token"  # what the hub's proxy adds to every request it forwards
TOKEN_PARAM = "mexone-token"  # the URL's query parameter (and the cookie's name)
HUB_ENV = "JUPYTERHUB_SERVICE_PREFIX"  # set in every process of a JupyterHub user's server
# Behind a proxy the page is opened by its file name: viser's page connects its websocket to its
# own URL less a trailing slash, and jupyter-server-proxy answers .../8123 (no slash) with a
# redirect, which a websocket cannot follow; .../8123/index.html reaches the lab either way.
PAGE = "index.html"


@dataclass(frozen=True)
class LabAccess:
    """The key to one lab: `token` None is a lab on one's own machine (Origin and Host rule
    only); else every request must show the token. `prefix`: the hub user's server path
    (JUPYTERHUB_SERVICE_PREFIX, e.g. /user/alice/), where the page is reached through
    jupyter-server-proxy; `public_url`: the hub's address, when the hub says it."""

    token: str | None = None
    prefix: str | None = None
    public_url: str = ""

    def shown(self, headers, path: str) -> tuple[bool, bool]:
        """(the request shows the token, it came in the URL: set the cookie)."""
        if self.token is None:
            return True, False
        candidates = headers.get_all(TOKEN_HEADER)
        in_url = parse_qs(urlsplit(path).query).get(TOKEN_PARAM, [])
        candidates += in_url
        for line in headers.get_all("Cookie"):
            try:
                jar = SimpleCookie(line)
            except CookieError:
                continue
            if TOKEN_PARAM in jar:
                candidates.append(jar[TOKEN_PARAM].value)
        good = any(hmac.compare_digest(c.encode(), self.token.encode()) for c in candidates)
        return good, good and self.token in in_url

    def check(self, headers, path: str) -> tuple[bool, str, bool]:
        """(accepted, reason, set the cookie) for one HTTP request or websocket handshake."""
        origins, hosts = headers.get_all("Origin"), headers.get_all("Host")
        if len(origins) > 1 or len(hosts) != 1:
            return False, "several Origin or Host headers", False
        shown, from_url = self.shown(headers, path)
        if not shown:
            return False, "no valid mexone-token: this lab is another session's", False
        ok, reason = allowed(origins[0] if origins else None, hosts[0],
                             secret_shown=self.token is not None)
        return ok, reason, ok and from_url

    def cookie(self) -> str:
        """The Set-Cookie value that keeps the token after a first visit by URL. No Path: the
        browser scopes it to the lab's own folder (/user/alice/proxy/8123), not the hub's."""
        return f"{TOKEN_PARAM}={self.token}; HttpOnly; SameSite=Strict"

    def page_url(self, host: str, port: int) -> str:
        """Where a person opens the page: through the hub's proxy (with the token) when the lab
        runs in a hub, else http://host:port."""
        if self.prefix is None:
            shown = "127.0.0.1" if host in ("0.0.0.0", "") else host
            query = f"/?{TOKEN_PARAM}={self.token}" if self.token else ""
            return f"http://{shown}:{port}{query}"
        query = f"?{TOKEN_PARAM}={self.token}" if self.token else ""
        return f"{self.public_url.rstrip('/')}{self.prefix}proxy/{port}/{PAGE}{query}"


def lab_access(environ: dict[str, str] | None = None) -> LabAccess:
    """The access rule for a lab started now: in a JupyterHub user's server (or whenever
    MEXONE_LAB_TOKEN is set) a secret is required, the launcher's or a new one for this lab."""
    env = os.environ if environ is None else environ
    prefix = env.get(HUB_ENV) or None
    if prefix is not None and not prefix.endswith("/"):
        prefix += "/"
    token = env.get(TOKEN_ENV) or (secrets.token_urlsafe(32) if prefix else None)
    return LabAccess(token, prefix, env.get("JUPYTERHUB_PUBLIC_URL", ""))


# ----- the handshake wrapper: one for the process, a rule per guarded server's event loop ----
_rules: weakref.WeakKeyDictionary[asyncio.AbstractEventLoop, LabAccess] = weakref.WeakKeyDictionary()
_install_lock = threading.Lock()
_original_handshake = None


def _install() -> None:
    global _original_handshake
    with _install_lock:
        if _original_handshake is not None:
            return
        _original_handshake = original = ws_server.ServerConnection.handshake

        async def handshake(self, process_request=None, process_response=None, *args, **kwargs):
            access = _rules.get(asyncio.get_running_loop())
            if access is None:  # not a guarded server (another library's in this process)
                return await original(self, process_request, process_response, *args, **kwargs)
            set_cookie = False

            def request(connection, req):
                nonlocal set_cookie
                ok, reason, set_cookie = access.check(req.headers, req.path)
                if not ok:
                    log.warning("refused a request to the page: %s", reason)
                    return connection.protocol.reject(http.HTTPStatus.FORBIDDEN, f"mexone: {reason}\n")
                return process_request(connection, req) if process_request else None

            def response(connection, req, resp):
                if set_cookie:
                    resp.headers["Set-Cookie"] = access.cookie()
                return process_response(connection, req, resp) if process_response else None

            return await original(self, request, response, *args, **kwargs)

        ws_server.ServerConnection.handshake = handshake


def guard(server: viser.ViserServer, access: LabAccess | None = None) -> None:
    """Refuse every request to `server` (its page and its websocket) that `access` does not
    allow, at the handshake, before anything is served."""
    _install()
    loop = server._websock_server._background_event_loop  # noqa: SLF001 - viser offers no hook
    _rules[loop] = access or LabAccess()


def warn_if_exposed(host: str, port: int) -> None:
    """Say loudly when the GUI listens beyond this machine, and where it really listens."""
    if is_loopback(host):
        return
    shown = host or "0.0.0.0"
    print(f"mexone: WARNING: the GUI listens on {shown}:{port}: anyone who can reach this "
          "machine on the network can control the simulator and start its routines "
          "(use --host 127.0.0.1 to keep it to this machine)", file=sys.stderr)
