"""`mexone sim --foxglove` against hostile clients (issue 36): a websocket whose Origin is not
this machine's page or an allowed origin (--foxglove-origin) is refused before it sees a byte of
the protocol, by a real websocket client sending the Origin a browser would; the SDK's own
server behind the gate cannot be reached around it (TLS with a certificate only the gate
trusts); an asset that cannot be served says so by its package:// URI, never by the folder it
is installed in, and a FIFO does not hold the server."""

from __future__ import annotations

import asyncio
import json
import logging
import os
import struct

import pytest

from helpers import run_cli

pytest.importorskip("foxglove", reason="foxglove-sdk is not installed (the foxglove extra)")
websockets = pytest.importorskip("websockets")

PROTOCOL = ["foxglove.sdk.v1", "foxglove.websocket.v1"]


@pytest.fixture(scope="module")
def bridge():
    from mexone.foxglove import FoxgloveBridge

    bridge = FoxgloveBridge(0, "127.0.0.1", ["https://app.foxglove.dev"])
    yield bridge
    bridge.shutdown()


def first_message(url: str, origin: str | None) -> str:
    """The server's first message to a client sending `origin`, or why it was refused."""
    async def talk() -> str:
        try:
            async with websockets.connect(url, origin=origin, subprotocols=PROTOCOL,
                                          open_timeout=10) as ws:
                return await asyncio.wait_for(ws.recv(), 10)
        except websockets.InvalidStatus as exc:
            return f"refused {exc.response.status_code}"
        except (OSError, websockets.InvalidMessage, websockets.InvalidHandshake) as exc:
            return f"failed {type(exc).__name__}"
    return asyncio.run(talk())


@pytest.mark.parametrize("origin, accepted", [
    ("http://evil.example", False),
    ("https://evil.example:8765", False),
    ("null", False),  # a sandboxed iframe, a file:// page
    ("http://127.0.0.1.evil.example", False),
    (None, True),  # not a web page: Foxglove's desktop app, a script
    ("http://127.0.0.1:5173", True),  # a page served from this machine
    ("http://localhost", True),
    ("https://app.foxglove.dev", True),  # --foxglove-origin
])
def test_only_this_machine_and_allowed_origins_get_in(bridge, origin, accepted, caplog):
    with caplog.at_level(logging.WARNING, logger="mexone.foxglove"):
        said = first_message(f"ws://127.0.0.1:{bridge.port}", origin)
    if accepted:
        assert json.loads(said)["op"] == "serverInfo", said
    else:
        assert said == "refused 403", said
        assert any("refused a Foxglove client" in r.getMessage() and "--foxglove-origin"
                   in r.getMessage() for r in caplog.records)


def test_the_sdk_server_behind_the_gate_cannot_be_reached_around_it(bridge):
    inner = bridge.server.port
    assert inner != bridge.port
    assert first_message(f"ws://127.0.0.1:{inner}", "http://evil.example").startswith("failed")
    # a browser's wss:// does not trust the run's certificate: the handshake fails
    assert first_message(f"wss://127.0.0.1:{inner}", "http://evil.example").startswith("failed")


def test_a_bad_foxglove_origin_is_one_line():
    code, _, err = run_cli(["sim", "--foxglove", "0", "--foxglove-origin", "app.foxglove.dev",
                            "--headless", "--duration", "0.01"])
    assert code == 2 and err.count("\n") == 1, err
    assert "origin 'app.foxglove.dev' is not a web origin" in err, err
    code, _, err = run_cli(["sim", "--foxglove-origin", "https://app.foxglove.dev", "--headless",
                            "--duration", "0.01"])
    assert code == 2 and "--foxglove-origin allows a web page to connect to --foxglove" in err


def test_assets_never_name_the_install_folder_nor_block(tmp_path, monkeypatch):
    from mexone.foxglove import FoxgloveBridge
    from mexone.lab import Lab

    package = tmp_path / "pkg"
    (package / "meshes").mkdir(parents=True)
    (package / "package.xml").write_text("<package><name>pkg</name></package>\n")
    (package / "meshes" / "arm.stl").write_bytes(b"solid arm\n")
    os.mkfifo(package / "meshes" / "fifo.stl")  # read_bytes() would wait for a writer forever
    (package / "meshes" / "folder.stl").mkdir()
    (package / "meshes" / "loop.stl").symlink_to(package / "meshes" / "loop.stl")
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(tmp_path))
    bridge = FoxgloveBridge(0, "127.0.0.1")
    try:
        bridge.attach(Lab.create(controllers=False), "<robot name='r'/>")
        answers = fetch(bridge.port, ["package://pkg/meshes/arm.stl", "package://pkg/meshes/fifo.stl",
                                      "package://pkg/meshes/folder.stl",
                                      "package://pkg/meshes/loop.stl",
                                      "package://pkg/../../../etc/passwd", "package://mex_rb/nope.stl"])
    finally:
        bridge.shutdown()
    assert answers[0] == (0, b"solid arm\n")
    assert b"package://pkg/meshes/loop.stl: a symbolic link loop" in answers[3][1]  # was its folder
    for status, said in answers[1:]:
        assert status == 1 and str(tmp_path).encode() not in said and b"site-packages" not in said, said


def fetch(port: int, uris: list[str]) -> list[tuple[int, bytes]]:
    """Each URI's fetchAsset answer: (status: 0 served, 1 error; the data or the error text)."""
    async def talk() -> list[tuple[int, bytes]]:
        out = []
        async with websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=PROTOCOL) as ws:
            for request, uri in enumerate(uris):
                await ws.send(json.dumps({"op": "fetchAsset", "uri": uri, "requestId": request}))
                while True:
                    message = await asyncio.wait_for(ws.recv(), 10)
                    if isinstance(message, bytes) and message[0] == 4:  # fetchAssetResponse
                        status, size = message[5], struct.unpack_from("<I", message, 6)[0]
                        out.append((status, message[10 + size:] if status == 0 else
                                    message[10:10 + size]))
                        break
        return out
    return asyncio.run(talk())
