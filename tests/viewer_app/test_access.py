"""Only the page the user opened drives the server; typed paths stay in the started folders."""

from __future__ import annotations

import http.client
import urllib.error
import urllib.request
from pathlib import Path

import pytest
import viser
from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect

from viewer_app import ViewerApp
from viewer_app.access import PATCHED_VISER_VERSION

PROTOCOL = f"viser-v{viser.__version__}"


def _ws(app: ViewerApp, origin: str | None, token: str | None, cookie: str | None = None):
    query = f"?token={token}" if token is not None else ""
    headers = {"Cookie": cookie} if cookie else None
    return connect(f"ws://127.0.0.1:{app.port}/{query}", origin=origin,  # type: ignore[arg-type]
                   subprotocols=[PROTOCOL], additional_headers=headers, open_timeout=10)


def _get(app: ViewerApp, path: str, host: str | None = None,
         cookie: str | None = None) -> tuple[int, dict[str, str], bytes]:
    conn = http.client.HTTPConnection("127.0.0.1", app.port, timeout=10)
    headers = {"Host": host or f"127.0.0.1:{app.port}"}
    if cookie:
        headers["Cookie"] = cookie
    conn.request("GET", path, headers=headers)
    resp = conn.getresponse()
    body = resp.read()
    conn.close()
    return resp.status, {k.lower(): v for k, v in resp.getheaders()}, body


def test_the_pinned_viser_is_the_patched_one() -> None:
    assert viser.__version__ == PATCHED_VISER_VERSION


def test_a_websocket_needs_the_token_and_the_apps_own_origin(app: ViewerApp) -> None:
    own = f"http://127.0.0.1:{app.port}"
    token = app.server_guard.token
    with _ws(app, own, token) as ws:  # the page's own handshake: accepted, and viser talks
        assert ws.recv(timeout=10)
    for origin, given in [
        ("https://evil.example", token),          # a page of another site, even with the token
        (f"http://localhost:{app.port + 1}", token),
        (None, token),                            # no Origin at all
        (own, None),                              # the right origin without the token
        (own, token[:-1] + ("A" if token[-1] != "A" else "B")),
    ]:
        with pytest.raises(InvalidStatus) as err:
            _ws(app, origin, given)
        assert err.value.response.status_code == 403, (origin, given)
    assert len(app.server_guard.refused) == 5


def test_the_token_comes_back_as_a_cookie_that_later_requests_carry(app: ViewerApp) -> None:
    token = app.server_guard.token
    status, headers, _ = _get(app, "/")
    assert status == 403
    status, headers, body = _get(app, f"/?token={token}")
    assert status == 200 and b"<html" in body.lower()
    cookie = headers["set-cookie"].split(";")[0]
    assert cookie == f"{app.server_guard.cookie_name}={token}"
    assert "HttpOnly" in headers["set-cookie"] and "SameSite=Strict" in headers["set-cookie"]
    assert _get(app, "/", cookie=cookie)[0] == 200  # a reload without the query
    with _ws(app, f"http://127.0.0.1:{app.port}", None, cookie=cookie) as ws:
        assert ws.recv(timeout=10)
    # a DNS name rebound to 127.0.0.1 is not this server's address, token or not
    assert _get(app, f"/?token={token}", host=f"evil.example:{app.port}")[0] == 403
    # a very long path is a 404, not a server error
    assert _get(app, "/" + "a" * 5000, cookie=cookie)[0] == 404


def test_typed_paths_outside_the_started_folders_are_refused(
    app: ViewerApp, tmp_path: Path, demo_case: dict[str, Path]
) -> None:
    outside = Path("/etc/hostname") if Path("/etc/hostname").exists() else Path("/etc/passwd")
    assert app.open_pair(str(outside), str(demo_case["b"])) is False
    level, _, body = app.notifications[-1]
    assert level == "error" and "outside the folders this viewer was started with" in body
    assert str(outside) in body and "\n" not in body
    assert app.views["a"].angio.path.endswith("a.dcm")  # nothing else was opened
    for typed in (str(outside), str(demo_case["a"].parent / ".." / ".." / "etc" / "passwd")):
        assert app.load_seeds(typed) is False
        assert "outside the folders" in app.notifications[-1][2]
    for typed in ("/tmp/stolen.json", "../stolen.json", str(tmp_path)):
        with pytest.raises(ValueError, match="outside the output folder"):
            app.save_seeds(typed)
    assert not (tmp_path.parent / "stolen.json").exists()
    written = app.save_seeds("sub/seeds.json")  # relative: inside the output folder
    assert written == (tmp_path / "sub" / "seeds.json").resolve() and written.is_file()
    assert app.load_seeds("sub/seeds.json") is True


def test_a_symlink_out_of_the_output_folder_is_refused(app: ViewerApp, tmp_path: Path) -> None:
    target = tmp_path.parent / f"{tmp_path.name}-elsewhere"
    target.mkdir()
    (tmp_path / "link").symlink_to(target)
    with pytest.raises(ValueError, match="outside the output folder"):
        app.save_seeds("link/seeds.json")
    assert not list(target.iterdir())


def test_coronary3d_view_prints_an_address_with_its_token(start_view) -> None:
    view = start_view()
    assert view.url is not None, (view.line, view.stop())
    with urllib.request.urlopen(view.url, timeout=10) as resp:
        assert resp.status == 200
    with pytest.raises(urllib.error.HTTPError) as err:
        urllib.request.urlopen(f"http://127.0.0.1:{view.port}/", timeout=10)
    assert err.value.code == 403
