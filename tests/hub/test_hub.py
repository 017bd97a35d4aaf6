"""Two students in a real class: JupyterHub from PyPI with LocalProcessSpawner (each student a
Unix user of their own), configurable-http-proxy from npm, jupyter-server-proxy starting
mexone's launcher entry, Debian's Chromium through Playwright.

Each student logs in, opens the "Mex-One lab" launcher card, sees Mex-One standing at real time
and moves a joint from the page. Neither can open the other's lab: not through the hub (their
browser), not on loopback (their processes, as their own Unix user), not by reading the other's
secret out of /proc. A foreign web page in a logged-in browser cannot open a lab's websocket.
The hub stopping a server (what its idle culler does) stops the lab with it, and the launcher
starts it again on the next visit."""

from __future__ import annotations

import re
import time

import numpy as np
import pytest

from helpers import chromium, wait_until
from mexone.gui.security import PAGE

from .classroom import PASSWORD, Classroom, as_user, class_names, labs_of, missing, students_venv

pytestmark = pytest.mark.slow

STUDENTS = tuple(class_names("a", "b"))
CARD = '.jp-LauncherCard[title^="Mex-One lab"]'  # "Mex-One lab [↗]": a new tab


@pytest.fixture(scope="module")
def room(wheel):
    why = missing()
    if why:
        pytest.skip(why)
    students_venv(wheel)  # the session's wheel of this checkout
    classroom = Classroom(list(STUDENTS)).start()
    yield classroom
    classroom.stop()


@pytest.fixture(scope="module")
def browser():
    with chromium() as b:
        yield b


def _shoulder_slider() -> int:
    """Where l_shoulder_pitch's slider is among the page's sliders (the controllers' order)."""
    from mexone.lab import Lab

    lab = Lab.create()
    joints = [j for c in lab.manager.controllers.values() if c.sliders for j in c.joints]
    return joints.index("l_shoulder_pitch")


def _log_in(browser, room, name, wait_until: str = "load"):
    """A browser context logged in as `name` and its tab on their JupyterLab."""
    context = browser.new_context(viewport={"width": 1100, "height": 800})
    jlab = context.new_page()
    jlab.goto(f"{room.url}/hub/login")
    jlab.fill("#username_input", name)
    jlab.fill("#password_input", PASSWORD)
    jlab.click("#login_submit")
    jlab.wait_for_url(re.compile(rf"/user/{name}/lab"), timeout=240_000, wait_until=wait_until)
    return context, jlab


def _open_lab(browser, room, name):
    """Log in as `name`, open the launcher card: (context, JupyterLab tab, the lab's tab)."""
    context, jlab = _log_in(browser, room, name)
    card = jlab.locator(CARD)
    card.wait_for(timeout=180_000)
    for dialog in jlab.locator(".jp-Dialog").all():  # e.g. "the server was restarted": dismiss
        if dialog.is_visible():
            jlab.keyboard.press("Escape")
    try:
        with context.expect_page(timeout=60_000) as opened:
            card.click(timeout=60_000)
    except Exception:
        jlab.screenshot(path=str(room.folder.parent / f"mexone-hub-{name}-launcher.png"))
        raise
    lab = opened.value
    assert lab.url.startswith(f"{room.url}/user/{name}/mexone/")
    return context, jlab, lab


def _rtf(lab) -> float:
    status = lab.get_by_text(re.compile("running at real-time factor")).first
    status.wait_for(timeout=180_000)
    return float(re.search(r"real-time factor\s+([0-9.]+)", status.inner_text()).group(1))


def _picture(lab, box: dict) -> np.ndarray:
    """The 3D view (`box`: the canvas's place on the page, not the panel's text), in grey."""
    from io import BytesIO

    from PIL import Image

    # a page's screenshot (the canvas redraws, never "stable"); software WebGL on a busy
    # machine may take long over one
    shot = lab.screenshot(clip=box, timeout=120_000)
    return np.asarray(Image.open(BytesIO(shot)).convert("L"), dtype=float)


@pytest.fixture(scope="module")
def sessions(room, browser):
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(len(STUDENTS)) as starting:  # both servers at once: logging in
        list(starting.map(room.spawn, STUDENTS))  # then finds each running (no wait on spawn)
    opened = {name: _open_lab(browser, room, name) for name in STUDENTS}
    yield opened
    for context, *_ in opened.values():
        context.close()


def test_each_student_sees_mex_one_standing_at_real_time_and_moves_a_joint(sessions):
    index = _shoulder_slider()
    for name, (_, _, lab) in sessions.items():
        assert wait_until(lambda lab=lab: _rtf(lab) >= 0.9, timeout=60), f"{name}: not at real time"
        # where the 3D view is, once (a page starved of CPU answers slowly)
        box = lab.locator("canvas").first.bounding_box(timeout=120_000)
        time.sleep(1.0)  # the first frames: the scene arrives
        still = _picture(lab, box)
        assert wait_until(lambda: np.abs(_picture(lab, box) - still).mean() < 1.0,  # noqa: B023
                          timeout=30, poll=0.5), f"{name}: Mex-One is not standing still"
        assert still.std() > 5.0, f"{name}: an empty page"  # the robot, not a blank canvas
        slider = lab.get_by_role("slider").nth(index)
        slider.focus(timeout=120_000)
        slider.press("End", timeout=120_000)  # l_shoulder_pitch to its upper limit, 3 rad
        assert wait_until(lambda: np.abs(_picture(lab, box) - still).mean() > 1.5,  # noqa: B023
                          timeout=30, poll=0.5), f"{name}: the arm did not move on the page"


def test_a_student_cannot_open_another_students_lab_through_the_hub(room, sessions):
    for me, other in (STUDENTS, STUDENTS[::-1]):
        context, jlab, _ = sessions[me]
        response = jlab.request.get(f"{room.url}/user/{other}/mexone/", max_redirects=0)
        assert response.status in (302, 403, 404) and b"viser" not in response.body(), me
        opened = jlab.evaluate("""(url) => new Promise(done => {
            const ws = new WebSocket(url, ['viser-v' + '0']);
            ws.onopen = () => done('open'); ws.onerror = () => done('refused');
            setTimeout(() => done('timeout'), 20000); })""",
                               f"ws://127.0.0.1:{room.port}/user/{other}/mexone/")
        assert opened == "refused", me


PROBE = """
import json, urllib.request, urllib.error
from websockets.sync.client import connect
from websockets.exceptions import InvalidStatus
out = {}
try:
    urllib.request.urlopen("http://127.0.0.1:%(port)d/", timeout=20); out["page"] = 200
except urllib.error.HTTPError as e:
    out["page"] = e.code
try:
    connect("ws://127.0.0.1:%(port)d/", open_timeout=20).close(); out["ws"] = 101
except InvalidStatus as e:
    out["ws"] = e.response.status_code
try:
    open("/proc/%(pid)d/environ", "rb").read(); out["environ"] = "read"
except PermissionError:
    out["environ"] = "denied"
out["cmdline"] = open("/proc/%(pid)d/cmdline", "rb").read().decode(errors="replace")
print(json.dumps(out))
"""


def test_a_students_process_cannot_reach_another_students_lab_on_loopback(room, sessions):
    for me, other in (STUDENTS, STUDENTS[::-1]):
        (lab,) = labs_of(other)
        seen = as_user(me, PROBE % {"port": lab.port, "pid": lab.pid})
        assert seen["page"] == 403 and seen["ws"] == 403, seen
        assert seen["environ"] == "denied"  # where the lab's secret is
        assert "token" not in seen["cmdline"].lower()  # the command line everyone can read


FOREIGN = """<script>
const ws = new WebSocket("ws://127.0.0.1:%(port)d/user/%(name)s/mexone/", ["viser-v%(version)s"]);
ws.onopen = () => { document.title = "opened"; };
ws.onerror = ws.onclose = () => { if (document.title !== "opened") document.title = "refused"; };
</script>"""


def test_a_foreign_page_cannot_drive_a_lab_through_the_hub(room, sessions):
    import http.server
    import threading

    import viser

    name = STUDENTS[0]
    context, _, _ = sessions[name]  # logged in: the hub's cookies are in this browser
    body = (FOREIGN % {"port": room.port, "name": name, "version": viser.__version__}).encode()

    class Evil(http.server.BaseHTTPRequestHandler):
        def do_GET(self):  # noqa: N802
            self.send_response(200)
            self.send_header("Content-Type", "text/html")
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, *args):
            pass

    evil = http.server.ThreadingHTTPServer(("127.0.0.2", 0), Evil)  # another origin, this machine
    threading.Thread(target=evil.serve_forever, daemon=True).start()
    try:
        page = context.new_page()
        page.goto(f"http://127.0.0.2:{evil.server_address[1]}/")
        page.wait_for_function("document.title !== ''", timeout=30_000)
        assert page.title() == "refused"
        page.close()
    finally:
        evil.shutdown()


def test_a_stopped_server_stops_its_lab_and_the_launcher_starts_it_again(room, browser, sessions):
    name = STUDENTS[1]
    (before,) = labs_of(name)
    sessions[name][0].close()
    room.stop_server(name)  # what jupyterhub-idle-culler does to an idle student
    assert wait_until(lambda: not labs_of(name), timeout=30), "the lab outlived its server"
    # the next visit: log in (the hub starts the server again) and open the lab's address, the
    # one the launcher card opens (the card itself is tested above), without JupyterLab's page
    context, jlab = _log_in(browser, room, name, wait_until="commit")
    lab = jlab
    lab.goto(f"{room.url}/user/{name}/mexone/{PAGE}", timeout=180_000)
    try:
        assert wait_until(lambda: _rtf(lab) >= 0.9, timeout=60)
        (after,) = labs_of(name)
        assert after.pid != before.pid
    finally:
        context.close()
