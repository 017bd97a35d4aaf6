"""The Foxglove bridge's front door: which web pages may connect (mexone.origins' rule).

foxglove-sdk's server has no hook to see a websocket handshake's Origin, and any web page the
user has open can open ws://127.0.0.1:8765. So the SDK's server listens on a loopback port of
its own behind TLS with a certificate made for this run (a browser cannot complete that
handshake: it does not trust the certificate, and a page cannot make it), and this gate listens
where the user asked: it reads each handshake's request head, refuses (HTTP 403, one warning
line) an Origin that is neither this machine's nor in the allowlist (`--foxglove-origin`), and
passes the accepted ones through to the SDK's server, byte for byte.
"""

from __future__ import annotations

import asyncio
import contextlib
import datetime
import ipaddress
import logging
import ssl
import threading
from collections.abc import Iterable

from mexone.errors import InputError
from mexone.origins import allowed

__all__ = ["Gate", "loopback_certificate"]

log = logging.getLogger("mexone.foxglove")

_HEAD_LIMIT = 16 * 1024  # bytes of a handshake's request head
_HEAD_SECONDS = 10.0  # to send it
_FORBIDDEN = (b"HTTP/1.1 403 Forbidden\r\nContent-Type: text/plain\r\nConnection: close\r\n"
              b"Content-Length: 19\r\n\r\norigin not allowed\n")


def loopback_certificate() -> tuple[bytes, bytes]:
    """(certificate, PKCS#8 key), PEM: a self-signed certificate for 127.0.0.1, made now, kept
    in memory only: what the SDK's server serves TLS with, and all the gate trusts."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import NameOID

    key = ec.generate_private_key(ec.SECP256R1())
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "mexone foxglove bridge")])
    now = datetime.datetime.now(datetime.UTC)
    cert = (x509.CertificateBuilder().subject_name(name).issuer_name(name)
            .public_key(key.public_key()).serial_number(x509.random_serial_number())
            .not_valid_before(now - datetime.timedelta(minutes=5))
            .not_valid_after(now + datetime.timedelta(days=3650))
            .add_extension(x509.SubjectAlternativeName(
                [x509.IPAddress(ipaddress.ip_address("127.0.0.1"))]), critical=False)
            .add_extension(x509.BasicConstraints(ca=True, path_length=None), critical=True)
            .sign(key, hashes.SHA256()))
    return (cert.public_bytes(serialization.Encoding.PEM),
            key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                              serialization.NoEncryption()))


class Gate:
    """Listens on host:port in a thread of its own; each accepted websocket is spliced to the
    SDK's TLS server at 127.0.0.1:`inner_port` (trusting `certificate` only)."""

    def __init__(self, host: str, port: int, inner_port: int, certificate: bytes,
                 trusted: Iterable[str] = ()):
        self.inner_port = inner_port
        self.trusted = tuple(trusted)
        self._tls = ssl.create_default_context(cadata=certificate.decode())
        self._loop = asyncio.new_event_loop()
        started = threading.Event()
        failure: list[BaseException] = []

        async def listen() -> bool:
            try:
                self._server = await asyncio.start_server(self._client, host, port,
                                                          limit=_HEAD_LIMIT)
                return True
            except OSError as exc:
                failure.append(exc)
                return False
            finally:
                started.set()

        self._closing = False
        self._thread = threading.Thread(target=self._run, args=(listen,), daemon=True,
                                        name="mexone-foxglove-gate")
        self._thread.start()
        started.wait()
        if failure:
            self.close()
            raise InputError(f"cannot serve Foxglove on {host}:{port}: {failure[0].strerror or failure[0]}",
                             hint="pick another port: --foxglove PORT")
        self.port = self._server.sockets[0].getsockname()[1]

    def _run(self, listen) -> None:
        asyncio.set_event_loop(self._loop)
        # not serving (the port taken), or closed already: a close() whose stop ran inside
        # run_until_complete would not stop a run_forever started after it
        if self._loop.run_until_complete(listen()) and not self._closing:
            self._loop.run_forever()
        left = asyncio.all_tasks(self._loop)  # cancelled by close(): let them end
        self._loop.run_until_complete(asyncio.gather(*left, return_exceptions=True))
        self._loop.close()

    async def _client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            await self._serve(reader, writer)
        except asyncio.CancelledError:  # close(): the connection ends with the gate
            pass
        finally:
            with contextlib.suppress(Exception):
                writer.close()

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            head = await asyncio.wait_for(reader.readuntil(b"\r\n\r\n"), _HEAD_SECONDS)
        except (asyncio.IncompleteReadError, asyncio.LimitOverrunError, TimeoutError,
                ConnectionError):
            writer.close()
            return
        ok, reason = self.check(head)
        if not ok:
            log.warning("refused a Foxglove client: %s (to allow a web page's origin: "
                        "--foxglove-origin ORIGIN)", reason)
            with contextlib.suppress(ConnectionError):
                writer.write(_FORBIDDEN)
                await writer.drain()
            writer.close()
            return
        try:
            inner_reader, inner_writer = await asyncio.open_connection(
                "127.0.0.1", self.inner_port, ssl=self._tls, server_hostname="127.0.0.1")
        except (OSError, ssl.SSLError):
            writer.close()
            return
        inner_writer.write(head)
        await asyncio.gather(_pipe(reader, inner_writer), _pipe(inner_reader, writer))

    def check(self, head: bytes) -> tuple[bool, str]:
        """(accepted, reason) for a handshake's request head: one Host, at most one Origin,
        mexone.origins.allowed on them (this machine's pages and the allowlist)."""
        origins, hosts = [], []
        for line in head.split(b"\r\n")[1:]:
            name, _, value = line.partition(b":")
            key = name.strip().lower()
            if key in (b"origin", b"host"):
                (origins if key == b"origin" else hosts).append(
                    value.strip().decode("latin-1"))
        if len(origins) > 1 or len(hosts) != 1:
            return False, "several Origin or Host headers"
        return allowed(origins[0] if origins else None, hosts[0], self.trusted,
                       loopback_pages=True)

    def close(self) -> None:
        def stop() -> None:
            server = getattr(self, "_server", None)
            if server is not None:
                server.close()
            for task in asyncio.all_tasks(self._loop):
                task.cancel()
            self._loop.stop()

        self._closing = True  # before the stop is scheduled: _run reads it (see there)
        with contextlib.suppress(RuntimeError):  # the loop closed already: nothing to stop
            self._loop.call_soon_threadsafe(stop)
        self._thread.join(timeout=5)


async def _pipe(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
    """Copy until either side closes, then close the other."""
    try:
        while data := await reader.read(1 << 16):
            writer.write(data)
            await writer.drain()
    except (ConnectionError, ssl.SSLError, asyncio.CancelledError):
        pass
    finally:
        with contextlib.suppress(Exception):
            writer.close()
