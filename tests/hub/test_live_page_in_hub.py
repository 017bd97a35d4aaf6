"""A notebook's live page inside a JupyterHub (its kernel has JUPYTERHUB_SERVICE_PREFIX): the
link it shows goes through the hub's proxy with the page's own key, and the page refuses
whoever does not show that key (another student's process on the same loopback)."""

from __future__ import annotations

import http.client
import re

from mexone.lab import Lab
from mexone.notebook import serve


def _get(port: int, path: str) -> tuple[int, str | None]:
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=30)
    try:
        conn.request("GET", path, headers={"Host": "hub.school.example"})
        response = conn.getresponse()
        response.read()
        return response.status, response.getheader("Set-Cookie")
    finally:
        conn.close()


def test_the_live_page_in_a_hub_links_through_the_proxy_with_its_own_key(monkeypatch):
    monkeypatch.setenv("JUPYTERHUB_SERVICE_PREFIX", "/user/alice/")
    monkeypatch.delenv("MEXONE_LAB_TOKEN", raising=False)
    page = serve(Lab.create(controllers=False), rtf=0)
    try:
        port = page.app.server.get_port()
        match = re.fullmatch(rf"/user/alice/proxy/{port}/index\.html\?mexone-token=([\w-]+)", page.url)
        assert match, page.url
        assert page.url.replace("&", "&amp;") in page._repr_html_()  # the notebook's link
        token = match.group(1)
        assert _get(port, "/index.html")[0] == 403  # no key: another user's process
        status, cookie = _get(port, f"/index.html?mexone-token={token}")  # the link, via the hub
        assert status == 200 and cookie.startswith(f"mexone-token={token};")
    finally:
        page.stop()
