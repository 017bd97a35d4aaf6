"""What one student's lab costs the machine: `mexone sim` at real time, headless and with its page
open, as CPU share (of one core) and resident memory, with the real-time factor it kept.

A "page" here is the page's wire traffic: a websocket client that joins as viser's browser
client does (its first camera message) and reads every message the lab sends -- the server's
whole cost of a page, without a browser drawing it on the same two cores. The class benchmark
(benchmarks/hub_class.py) puts 20 of these behind a real JupyterHub.

    python benchmarks/lab_cost.py [--seconds 20] [--pages 0 1]
    python benchmarks/lab_cost.py --stages    # where the memory goes: VmRSS after each stage
    python benchmarks/lab_cost.py --ab OTHER/src --rounds 3   # A/B: alternate another checkout
"""

from __future__ import annotations

import argparse
import json
import os
import re
import struct
import subprocess
import sys
import threading
import time
from dataclasses import asdict, dataclass
from pathlib import Path

SIM_TIME = re.compile(rb"sim time\*\*\s+([0-9]+\.[0-9]+) s")
CLOCK = os.sysconf("SC_CLK_TCK")


@dataclass
class Cost:
    pages: int
    cpu_percent: float  # of one core, over the window
    rss_mb: float
    rtf: float  # sim time over wall time the page saw (status line), or the lab's own
    messages_per_s: float
    kbytes_per_s: float


def cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / CLOCK


def rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS"):
            return int(line.split()[1]) / 1024
    return float("nan")


def unpack(data: bytes) -> bytes:
    """The msgpack of one viser websocket message (its wire format: two little-endian sizes,
    then the zstd-compressed msgpack, then raw binary buffers)."""
    import zstandard

    size, compressed = struct.unpack_from("<QQ", data, 0)
    return zstandard.ZstdDecompressor().decompress(data[16:16 + compressed], max_output_size=size)


CAMERA = {"type": "ViewerCameraMessage", "wxyz": [1.0, 0.0, 0.0, 0.0], "position": [1.3, -1.35, 0.95],
          "fov": 0.785, "near": 0.01, "far": 100.0, "image_height": 800, "image_width": 1100,
          "look_at": [0.0, 0.0, 0.52], "up_direction": [0.0, 0.0, 1.0]}


class Page(threading.Thread):
    """A page's traffic: join, then read everything; remember the sim time the status shows."""

    def __init__(self, url: str, headers: dict | None = None):
        super().__init__(daemon=True)
        self.url, self.headers = url, headers or {}
        self.messages = self.bytes = 0
        self.samples: list[tuple[float, float]] = []  # (wall, sim time shown)
        self.stop = threading.Event()
        self.error: str | None = None

    def run(self) -> None:
        import msgspec
        import viser
        from websockets.sync.client import connect

        try:
            with connect(self.url, additional_headers=self.headers, open_timeout=120, max_size=None,
                         subprotocols=[f"viser-v{viser.__version__}"]) as ws:
                ws.send(msgspec.msgpack.encode(CAMERA))
                while not self.stop.is_set():
                    try:
                        data = ws.recv(timeout=0.5)
                    except TimeoutError:
                        continue
                    self.messages += 1
                    self.bytes += len(data)
                    found = SIM_TIME.findall(unpack(data))
                    if found:
                        self.samples.append((time.monotonic(), float(found[-1])))
        except Exception as exc:  # noqa: BLE001 - reported with the result
            self.error = f"{type(exc).__name__}: {exc}"

    def rtf(self, since: float) -> float:
        window = [s for s in self.samples if s[0] >= since]
        if len(window) < 2:
            return float("nan")
        (w0, s0), (w1, s1) = window[0], window[-1]
        return (s1 - s0) / (w1 - w0)


def measure(pid: int, pages: list[Page], seconds: float, warmup: float = 5.0) -> Cost:
    time.sleep(warmup)
    c0, t0, m0, b0 = cpu_seconds(pid), time.monotonic(), sum(p.messages for p in pages), \
        sum(p.bytes for p in pages)
    time.sleep(seconds)
    c1, t1 = cpu_seconds(pid), time.monotonic()
    rtfs = [p.rtf(t0) for p in pages]
    return Cost(len(pages), 100 * (c1 - c0) / (t1 - t0), rss_mb(pid),
                min(rtfs) if rtfs else float("nan"),
                (sum(p.messages for p in pages) - m0) / (t1 - t0),
                (sum(p.bytes for p in pages) - b0) / (t1 - t0) / 1024)


def start_lab(port: int, env: dict | None = None) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "mexone", "sim", "--port", str(port)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            env={**os.environ, **(env or {})})


STAGES = """
import json, sys
def rss():
    for line in open("/proc/self/status"):
        if line.startswith("VmRSS"):
            return int(line.split()[1]) / 1024
stages = [("python", rss())]
from mexone.cli import build_parser
from mexone.cli.common import lab_from_args, options_from_args
import mexone.gui.app
args = build_parser().parse_args(["sim", "--port", "0"])
stages.append(("imports (the CLI, MuJoCo, viser, numpy)", rss()))
lab = lab_from_args(args)
stages.append(("the Lab (Mex-One, its controllers)", rss()))
app = mexone.gui.app.GuiApp(lambda options: lab, options_from_args(args), port=0)
stages.append(("the page (scene, panels)", rss()))
heavy = sorted({"trimesh", "scipy", "networkx", "mink", "qpsolvers", "matplotlib", "control",
                "rosbags"} & {name.split(".")[0] for name in sys.modules})
app.stop()
print(json.dumps({"stages": stages, "heavy_imports": heavy}))
"""


def stages() -> None:
    """VmRSS after each stage of what `mexone sim` builds, in a fresh process (as a lab starts)."""
    done = subprocess.run([sys.executable, "-c", STAGES], capture_output=True, text=True, check=True)
    report = json.loads(done.stdout.strip().splitlines()[-1])
    previous = 0.0
    for name, mb in report["stages"]:
        print(f"{name:45s} {mb:6.1f} MB  (+{mb - previous:5.1f})")
        previous = mb
    print(f"heavy modules imported: {report['heavy_imports'] or 'none'}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--pages", type=int, nargs="+", default=[0, 1])
    parser.add_argument("--stages", action="store_true",
                        help="print resident memory after each stage of a lab's start, then exit")
    parser.add_argument("--ab", metavar="SRC", type=Path,
                        help="another checkout's src folder: alternate its labs with this one's, "
                             "--rounds times (each row says which side it is)")
    parser.add_argument("--rounds", type=int, default=1)
    args = parser.parse_args()
    if args.stages:
        stages()
        return
    print(f"load: {os.getloadavg()}", file=sys.stderr)
    if args.ab is None:
        for n in args.pages:
            print(json.dumps(asdict(run_lab(n, args.seconds))))
        return
    here = str(Path(__file__).resolve().parents[1] / "src")
    for r in range(args.rounds):
        for side, src in (("other", str(args.ab.resolve())), ("this", here)):
            for n in args.pages:
                env = {"PYTHONPATH": os.pathsep.join([src, os.environ.get("PYTHONPATH", "")])}
                row = {"round": r + 1, "side": side, "load": os.getloadavg()[0],
                       **asdict(run_lab(n, args.seconds, env))}
                print(json.dumps(row), flush=True)


def run_lab(n: int, seconds: float, env: dict | None = None) -> Cost:
    """One `mexone sim` on a free port with `n` pages' traffic, measured over `seconds`."""
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    lab = start_lab(port, env)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            try:
                socket.create_connection(("127.0.0.1", port), timeout=1).close()
                break
            except OSError:
                time.sleep(0.2)
        pages = [Page(f"ws://127.0.0.1:{port}/") for _ in range(n)]
        for page in pages:
            page.start()
        cost = measure(lab.pid, pages, seconds)
        for page in pages:
            page.stop.set()
        return cost
    finally:
        lab.terminate()
        lab.wait(timeout=20)


if __name__ == "__main__":
    main()
