"""The app's server starts, binds loopback, and serves its page."""

from __future__ import annotations

import urllib.request


def test_server_serves_its_page(server_url):
    assert server_url.startswith("http://127.0.0.1:")
    with urllib.request.urlopen(server_url, timeout=30) as resp:
        assert resp.status == 200
        body = resp.read(200).decode(errors="replace").lower()
    assert "<!doctype html>" in body
