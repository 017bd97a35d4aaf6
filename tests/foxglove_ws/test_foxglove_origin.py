"""`mexone sim --foxglove` lets no foreign web page in (issue 36): a websocket whose Origin is
not this machine's page or an allowed origin (--foxglove-origin) is refused before it sees a
byte of the protocol, by a real websocket client sending the Origin a browser would; the SDK's
own server behind the gate cannot be reached around it (TLS with a certificate only the gate
trusts)."""

from __future__ import annotations

import asyncio
import json
import logging

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
