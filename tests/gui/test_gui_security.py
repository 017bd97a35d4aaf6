"""The GUI against a scripted attacker speaking viser's wire protocol: a page from another origin
is refused at the handshake; a client of the right origin still cannot start a file it names,
nor freeze the simulation with Steps = 1e9; a non-loopback bind address is announced loudly."""

from __future__ import annotations

import socket
import subprocess
import sys
import threading
import time

import msgspec
import pytest
import viser
from websockets.exceptions import ConnectionClosed, InvalidStatus
from websockets.sync.client import connect

from helpers import free_port, wait_until
from mexone.gui.app import MAX_STEPS, GuiApp
from mexone.gui.security import allowed
from mexone.lab import Lab
from mexone.physics import CompileOptions


@pytest.fixture(scope="module")
def app(tmp_path_factory):
    folder = tmp_path_factory.mktemp("routines")
    (folder / "wave.py").write_text("from mexone import rospy\nrospy.sleep(0.1)\n")
    outside = tmp_path_factory.mktemp("elsewhere") / "evil.py"
    outside.write_text("open(__file__ + '.ran', 'w').write('ran')\n")
    gui = GuiApp(lambda options: Lab.create(options=options), CompileOptions(), port=free_port(),
                 routine_dirs=[folder])
    gui.evil = outside
    loop = threading.Thread(target=gui.serve_forever, daemon=True)
    loop.start()
    yield gui
    gui.stop()
    loop.join(timeout=5)


def client(app, origin: str | None, host: str = "127.0.0.1", headers=None):
    """A websocket to the app, as a page at `origin` would open it to ws://host:port."""
    port = app.server.get_port()
    sock = socket.create_connection(("127.0.0.1", port))  # whatever `host` resolves to
    return connect(f"ws://{host}:{port}", sock=sock, origin=origin, additional_headers=headers,
                   subprotocols=[f"viser-v{viser.__version__}"], open_timeout=10)


def join(ws) -> None:
    """What the page sends first: its camera (viser counts a client as connected after it)."""
    ws.send(msgspec.msgpack.encode({
        "type": "ViewerCameraMessage", "wxyz": [1.0, 0.0, 0.0, 0.0], "position": [2.0, 0.0, 1.0],
        "fov": 0.8, "near": 0.01, "far": 100.0, "image_height": 600, "image_width": 800,
        "look_at": [0.0, 0.0, 0.5], "up_direction": [0.0, 0.0, 1.0]}))
    time.sleep(0.3)


def send(ws, handle, value) -> None:
    ws.send(msgspec.msgpack.encode({"type": "GuiUpdateMessage", "uuid": handle._impl.uuid,
                                    "updates": {"value": value}}))


def refused(ws, within: float = 3.0) -> bool:
    """The server closed the connection (policy violation) instead of serving it."""
    end = time.monotonic() + within
    try:
        while time.monotonic() < end:
            ws.recv(timeout=max(0.01, end - time.monotonic()))
    except ConnectionClosed as exc:
        return exc.rcvd is not None and exc.rcvd.code == 1008
    except TimeoutError:
        pass
    return False


def refused_at_handshake(app, origin, host="127.0.0.1", headers=None) -> bool:
    """The server answered HTTP 403 instead of upgrading: nothing was served."""
    try:
        client(app, origin, host, headers).close()
    except InvalidStatus as exc:
        return exc.response.status_code == 403
    return False


def test_a_page_from_another_origin_is_refused(app):
    port = app.server.get_port()
    assert refused_at_handshake(app, "http://evil.example:8000")
    assert refused_at_handshake(app, f"http://localhost:{port + 1}")  # another port: another origin
    # DNS rebinding: the right port, but a name that is not this machine
    assert refused_at_handshake(app, f"http://evil.example:{port}", host="evil.example")
    # two Origin headers
    assert refused_at_handshake(app, f"http://127.0.0.1:{port}", headers={"Origin": "http://evil.example"})


def test_the_page_itself_is_refused_to_a_rebinding_name(app):
    """The HTTP page too, not only its websocket: a name that is not this machine gets 403."""
    port = app.server.get_port()
    assert _get(port, "/", {"Host": f"127.0.0.1:{port}"})[0] == 200
    assert _get(port, "/", {"Host": f"evil.example:{port}"})[0] == 403


def _get(port, path, headers):
    import http.client

    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=10)
    try:
        conn.putrequest("GET", path, skip_host=True, skip_accept_encoding=True)
        for key, value in headers.items():
            conn.putheader(key, value)
        conn.endheaders()
        response = conn.getresponse()
        return response.status, response.getheader("Set-Cookie"), response.read()
    finally:
        conn.close()


def test_the_served_page_origin_is_accepted(app):
    port = app.server.get_port()
    with client(app, f"http://127.0.0.1:{port}") as ws:
        assert not refused(ws)


def test_the_origin_rule():
    assert allowed("http://127.0.0.1:8080", "127.0.0.1:8080")[0]
    assert allowed("http://localhost:8080", "localhost:8080")[0]
    assert allowed(None, "127.0.0.1:8080")[0]  # not a web page
    assert not allowed("https://evil.example", "127.0.0.1:8080")[0]
    assert not allowed("null", "127.0.0.1:8080")[0]  # sandboxed iframes, file:// pages
    assert not allowed("http://evil.example:8080", "evil.example:8080")[0]
    assert not allowed("http://127.0.0.1:8080", None)[0]


def test_a_same_origin_client_cannot_start_a_file_it_names(app):
    port = app.server.get_port()
    assert set(app.panels["routines"].files) >= {"wave.py", "arms", "joint_steps", "home"}
    with client(app, f"http://127.0.0.1:{port}") as ws:
        join(ws)
        send(ws, app.panels["routines"].choice, str(app.evil))
        wait_until(lambda: app.panels["routines"].choice.value == str(app.evil), timeout=5)
        start = next(h for h in app.server.gui._gui_input_handle_from_uuid.values()
                     if getattr(h, "label", None) == "Start")
        send(ws, start, True)
        refused = "is not one of the routines this server offers"
        assert wait_until(lambda: any(refused in r for r in app.refusals))
    assert app.routine is None or app.routine.path != app.evil
    assert not app.evil.with_name(app.evil.name + ".ran").exists()
    assert any("is not one of the routines this server offers" in r for r in app.refusals)


def test_steps_1e9_is_refused_and_step_n_never_freezes_the_page(app):
    port = app.server.get_port()
    with client(app, f"http://127.0.0.1:{port}") as ws:
        join(ws)
        send(ws, app.panels["simulation"].steps, 1e9)
        message = "Steps: 1e+09 must be a whole number >= 1 and <= 100000"
        assert _wait(lambda: message in app.refusals)
        assert app.panels["simulation"].steps.value == "100"  # the field shows what the server holds
        send(ws, app.panels["simulation"].steps, "NaN")
        assert _wait(lambda: "Steps: 'NaN' is not a finite number" in app.refusals)
        assert app.fields.held(app.panels["simulation"].steps) == [100]
    app.do(lambda: app.step_n(MAX_STEPS))  # the most a page may ask for
    time.sleep(0.3)
    t0 = time.perf_counter()
    app.do(app.toggle_pause)  # Play interrupts it
    while app.steps_left and time.perf_counter() - t0 < 2:
        time.sleep(0.01)
    assert app.steps_left == 0 and time.perf_counter() - t0 < 1.0


def _wait(predicate, timeout=5.0) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(0.05)
    return False


def test_a_non_loopback_address_is_announced():
    code = ("from mexone.gui.security import warn_if_exposed; warn_if_exposed('0.0.0.0', 8080); "
            "warn_if_exposed('127.0.0.1', 8080)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and "WARNING" in lines[0] and "0.0.0.0:8080" in lines[0]
    assert "anyone who can reach this machine" in lines[0]


# ----- a lab in a shared machine (a JupyterHub): a per-session secret on every request ------
@pytest.fixture(scope="module")
def keyed():
    """A bare guarded viser server with a secret, as a lab in a JupyterHub is."""
    from mexone.gui.security import LabAccess, guard

    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    access = LabAccess(token="s3cret-Token_1", prefix="/user/alice/")
    guard(server, access)
    yield server.get_port(), access
    server.stop()


def _ws(port, headers=None, path="/", origin=None, host=None):
    sock = socket.create_connection(("127.0.0.1", port))
    where = host or f"127.0.0.1:{port}"  # the Host header the client sends
    return connect(f"ws://{where}{path}", sock=sock, origin=origin, additional_headers=headers,
                   subprotocols=[f"viser-v{viser.__version__}"], open_timeout=10)


def _refused_ws(port, **kwargs) -> bool:
    try:
        _ws(port, **kwargs).close()
    except InvalidStatus as exc:
        return exc.response.status_code == 403
    return False


def test_without_the_secret_nothing_is_served_not_even_the_page(keyed):
    port, _ = keyed
    here = {"Host": f"127.0.0.1:{port}"}
    assert _get(port, "/", here)[0] == 403
    assert _get(port, "/?mexone-token=guess", here)[0] == 403
    assert _get(port, "/", here | {"Cookie": "mexone-token=guess"})[0] == 403
    assert _refused_ws(port)  # another user's process on the same loopback
    assert _refused_ws(port, headers={"X-Mexone-Token": "s3cret-Token_"})  # a prefix is not it
    assert _refused_ws(port, path="/?mexone-token=s3cret-Token_12")


def test_the_proxy_header_the_url_and_its_cookie_each_open_the_lab(keyed):
    port, access = keyed
    hub = {"Host": "hub.example.org"}  # through the hub: its public name, not this machine's
    status, cookie, _ = _get(port, "/", hub | {"X-Mexone-Token": access.token})
    assert status == 200 and cookie is None
    status, cookie, body = _get(port, "/?mexone-token=s3cret-Token_1", hub)
    assert status == 200 and b"<html" in body
    assert cookie == "mexone-token=s3cret-Token_1; HttpOnly; SameSite=Strict"  # no Path: the lab's folder
    assert _get(port, "/", hub | {"Cookie": "_xsrf=1; mexone-token=s3cret-Token_1"})[0] == 200
    _ws(port, headers={"X-Mexone-Token": access.token}).close()
    _ws(port, headers={"Cookie": "mexone-token=s3cret-Token_1"}, host="hub.example.org",
        origin="http://hub.example.org").close()


def test_with_the_secret_a_foreign_page_is_still_refused(keyed):
    port, access = keyed
    secret = {"X-Mexone-Token": access.token}
    assert _refused_ws(port, headers=secret, host="hub.example.org", origin="https://evil.example")
    assert _refused_ws(port, headers=secret, host="hub.example.org", origin="http://hub.example.org:81")
    assert _get(port, "/", secret | {"Host": "hub.example.org", "Origin": "https://evil.example"})[0] == 403


def test_where_a_keyed_lab_is_opened():
    from mexone.gui.security import LabAccess, lab_access

    assert lab_access({}).token is None and lab_access({}).page_url("0.0.0.0", 8080) == "http://127.0.0.1:8080"
    hub = lab_access({"JUPYTERHUB_SERVICE_PREFIX": "/user/alice/"})
    assert len(hub.token) >= 40 and hub.token != lab_access({"JUPYTERHUB_SERVICE_PREFIX": "/u/"}).token
    assert hub.page_url("127.0.0.1", 8123) == f"/user/alice/proxy/8123/index.html?mexone-token={hub.token}"
    given = lab_access({"JUPYTERHUB_SERVICE_PREFIX": "/user/bob", "MEXONE_LAB_TOKEN": "k",
                        "JUPYTERHUB_PUBLIC_URL": "https://hub.school.example/"})
    assert given.page_url("127.0.0.1", 9) == "https://hub.school.example/user/bob/proxy/9/index.html?mexone-token=k"
    assert LabAccess("k").page_url("127.0.0.1", 9) == "http://127.0.0.1:9/?mexone-token=k"
