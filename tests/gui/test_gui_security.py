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


def test_a_page_from_another_origin_is_refused(app):
    port = app.server.get_port()
    with client(app, "http://evil.example:8000") as ws:
        assert refused(ws)
    with client(app, f"http://localhost:{port + 1}") as ws:  # another port is another origin
        assert refused(ws)
    with client(app, f"http://evil.example:{port}", host="evil.example") as ws:
        assert refused(ws)  # DNS rebinding: the right port, but a name that is not this machine
    with pytest.raises(InvalidStatus):  # two Origin headers: refused at the handshake
        client(app, f"http://127.0.0.1:{port}", headers={"Origin": "http://evil.example"})


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
