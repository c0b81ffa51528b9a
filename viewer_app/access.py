"""Who may drive the viewer's server, and which files the page may name.

The server holds patient data (both angiograms) and acts on files, so:

- **Only the page the user opened may connect.** Every start makes a secret
  token, carried by the printed address (``http://127.0.0.1:PORT/?token=...``).
  The page request with the token gets it back as a cookie (HttpOnly,
  SameSite=Strict); every later request, and the websocket handshake, must
  carry it (cookie, or ``?token=`` for a script). The websocket handshake must
  also come from the app's own address: its ``Origin`` must be
  ``http://<Host>`` and the Host one of the server's own names, so a page of
  another site (or a DNS name rebound to 127.0.0.1) is refused with 403.
- **File paths typed in the page stay inside the folders the viewer was
  started with** (:class:`FileAccess`): those of A, B and the seeds file,
  the output folder and the private folder of uploads; saving writes only
  inside the output folder.

viser 1.1.1 has no hook for the websocket handshake. :func:`guarded_serve`
wraps ``websockets.asyncio.server.serve`` while the ViserServer binds, so
that viser's own ``process_request`` (its static file server) runs behind
:meth:`ServerGuard.process_request`; :data:`PATCHED_VISER_VERSION` is the
version this was written against (pinned in pyproject.toml), and the viewer
refuses to serve when the wrapper was not called.
"""

from __future__ import annotations

import contextlib
import http
import http.cookies
import ipaddress
import os
import secrets
import threading
import urllib.parse
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

__all__ = ["PATCHED_VISER_VERSION", "ServerGuard", "FileAccess", "guarded_serve"]

PATCHED_VISER_VERSION = "1.1.1"

_LOOPBACK_NAMES = ("127.0.0.1", "localhost", "::1")
_serve_lock = threading.Lock()


def _is_wildcard(host: str) -> bool:
    return host in ("", "0.0.0.0", "::")


class ServerGuard:
    """The token and Origin checks of one server start (see the module docstring).

    ``host`` is the address the server binds; ``port`` is set once it is bound.
    """

    def __init__(self, host: str) -> None:
        self.token = secrets.token_urlsafe(24)
        self.host = host
        self.port: int | None = None
        self.installed = False  # set when the handshake wrapper is in viser's server
        self.refused: list[str] = []  # one line per refused request (tests, logs)

    @property
    def cookie_name(self) -> str:
        return f"coronary3d_token_{self.port}"  # cookies are per host, not per port

    def allowed_host(self, hostname: str) -> bool:
        """True for a Host header name the page may use: the server's own names."""
        name = hostname.strip("[]").lower()
        if _is_wildcard(self.host):
            return True  # every interface: any of this machine's names (the token still holds)
        if name == self.host.strip("[]").lower():
            return True
        with contextlib.suppress(ValueError):
            if ipaddress.ip_address(self.host.strip("[]")).is_loopback:
                return name in _LOOPBACK_NAMES
        return False

    def _token_in(self, path: str, cookie_header: str | None) -> tuple[bool, bool]:
        """(the token is present and right, it came in the URL)."""
        query = urllib.parse.parse_qs(urllib.parse.urlsplit(path).query)
        for given in query.get("token", []):
            if secrets.compare_digest(given, self.token):
                return True, True
        if cookie_header:
            jar = http.cookies.SimpleCookie()
            with contextlib.suppress(http.cookies.CookieError):
                jar.load(cookie_header)
            morsel = jar.get(self.cookie_name)
            if morsel is not None and secrets.compare_digest(morsel.value, self.token):
                return True, False
        return False, False

    def check(self, path: str, headers: dict[str, str]) -> str | None:
        """Why a request is refused (one line), or None when it may go on.

        ``headers`` are the request's headers with lower-case names.
        """
        host = headers.get("host", "")
        hostname = urllib.parse.urlsplit(f"//{host}").hostname or ""
        if not self.allowed_host(hostname):
            return f"Host {host!r} is not this server's address"
        if headers.get("upgrade", "").lower() == "websocket":
            origin = headers.get("origin", "")
            if origin.lower() != f"http://{host}".lower():
                return f"websocket from Origin {origin or 'none'!r}, not http://{host}"
        ok, _ = self._token_in(path, headers.get("cookie"))
        if not ok:
            return "no valid access token (open the address printed by coronary3d view)"
        return None

    def process_request(self, connection: object, request: object,
                        delegate: Callable[[object, object], object] | None) -> object:
        """websockets' process_request: refuse (403), or run viser's own and add the cookie."""
        from websockets.datastructures import Headers
        from websockets.http11 import Response

        headers = {k.lower(): v for k, v in request.headers.raw_items()}  # type: ignore[attr-defined]
        why = self.check(request.path, headers)  # type: ignore[attr-defined]
        if why is not None:
            self.refused.append(why)
            body = f"coronary3d viewer: refused: {why}\n".encode()
            return Response(http.HTTPStatus.FORBIDDEN, "Forbidden",
                            Headers({"Content-Type": "text/plain; charset=utf-8",
                                     "Content-Length": str(len(body))}), body)
        try:
            response = delegate(connection, request) if delegate is not None else None
        except (OSError, ValueError):  # a path too long for a file name, an odd byte
            body = b"NOT FOUND"
            return Response(http.HTTPStatus.NOT_FOUND, "NOT FOUND",
                            Headers({"Content-Length": str(len(body))}), body)
        _, in_url = self._token_in(request.path, None)  # type: ignore[attr-defined]
        if response is not None and in_url:
            response.headers["Set-Cookie"] = (  # type: ignore[attr-defined]
                f"{self.cookie_name}={self.token}; Path=/; HttpOnly; SameSite=Strict")
        return response

    def url(self, shown_host: str) -> str:
        return f"http://{shown_host}:{self.port}/?token={self.token}"


@contextlib.contextmanager
def guarded_serve(guard: ServerGuard) -> Iterator[None]:
    """While the block runs, websockets servers are started behind ``guard``.

    Meant around ``viser.ViserServer(...)``, which binds before it returns.
    """
    import websockets.asyncio.server as ws_server

    with _serve_lock:
        original = ws_server.serve

        def serve(handler, *args, process_request=None, **kwargs):  # noqa: ANN001, ANN202
            def checked(connection, request):  # noqa: ANN001, ANN202
                return guard.process_request(connection, request, process_request)

            guard.installed = True
            return original(handler, *args, process_request=checked, **kwargs)

        ws_server.serve = serve  # type: ignore[misc, assignment]
        try:
            yield
        finally:
            ws_server.serve = original  # type: ignore[misc]


class FileAccess:
    """The folders a path typed in the page may name.

    ``read_roots`` are folders whose files (at any depth) may be opened;
    ``out_dir`` is where saving writes (and may be read too).
    """

    def __init__(self, read_roots: Sequence[str | os.PathLike], out_dir: str | os.PathLike) -> None:
        self.out_dir = Path(out_dir).resolve()
        roots = [Path(r).resolve() for r in read_roots] + [self.out_dir]
        self.read_roots = list(dict.fromkeys(roots))

    def add_read_root(self, folder: str | os.PathLike) -> None:
        root = Path(folder).resolve()
        if root not in self.read_roots:
            self.read_roots.append(root)

    def _resolve(self, path: str | os.PathLike, base: Path) -> Path:
        text = os.fspath(path)
        if not text.strip():
            raise ValueError("type a file path first")
        if "\x00" in text:
            raise ValueError(f"{text!r}: not a file path")
        p = Path(text).expanduser()
        return (p if p.is_absolute() else base / p).resolve()

    def readable(self, path: str | os.PathLike, what: str = "file") -> Path:
        """The resolved path, when inside a read root; ValueError (one line) otherwise."""
        p = self._resolve(path, self.out_dir)
        if not any(p.is_relative_to(root) for root in self.read_roots):
            shown = ", ".join(str(r) for r in self.read_roots[:4])
            raise ValueError(f"{path}: the {what} is outside the folders this viewer was "
                             f"started with ({shown}); upload it instead")
        return p

    def writable(self, path: str | os.PathLike, what: str = "file") -> Path:
        """The resolved path, when inside the output folder; ValueError (one line) otherwise."""
        p = self._resolve(path, self.out_dir)
        if not p.is_relative_to(self.out_dir) or p == self.out_dir:
            raise ValueError(f"{path}: the {what} would be outside the output folder "
                             f"{self.out_dir} (coronary3d view --out); give a name inside it")
        return p
