"""The server's outer layer (a pure ASGI middleware): Host check, token, body size limit,
and a last-resort 500 that keeps the connection alive.

In order, for every HTTP request:

1. **Host** (DNS rebinding): the ``Host`` header must name this server: an IP literal
   (any one when bound to a wildcard address, else the bound one or loopback),
   ``localhost``, the bound name, this machine's host name when not bound to loopback, or a
   name of ``allowed_hosts``. Anything else is answered 400 before any work.
2. **Token** (only when one is set; ``parknss web`` requires it off loopback): the token
   in ``Authorization: Bearer``, ``X-Parknss-Token``, the ``parknss_token`` cookie or the
   ``token`` query parameter; otherwise 401. ``GET /?token=...`` sets the cookie
   (HttpOnly, SameSite=Strict) and redirects to the clean address, so the page's own
   requests carry it.
3. **Body size**: a ``Content-Length`` over ``max_body_bytes`` is answered 413 before the
   body is read; a chunked body is counted while it streams and refused (413) as soon as
   it passes the limit.
4. **Last resort**: an exception nothing else handled is logged and answered 500 JSON
   here, so uvicorn never sees it and keeps the keep-alive connection open (Starlette's
   outermost error middleware re-raises, which makes the server drop the connection).
"""

from __future__ import annotations

import hmac
import ipaddress
import json
import logging
import socket
from collections.abc import Awaitable, Callable, Iterable
from http.cookies import SimpleCookie
from urllib.parse import parse_qsl, urlencode

from parknss.errors import ConfigError
from parknss.web.errors import WebError

log = logging.getLogger("parknss.web")

COOKIE = "parknss_token"
WILDCARD = {"0.0.0.0", "::", ""}

Scope = dict
Receive = Callable[[], Awaitable[dict]]
Send = Callable[[dict], Awaitable[None]]


class BodyTooLargeError(WebError):
    """A request body over the server's ``max_body_bytes`` (413)."""

    status = 413


def is_loopback(host: str) -> bool:
    """Whether ``host`` (an address or ``localhost``) only listens on this machine."""
    if host.strip("[]").lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def exposure_warning(host: str, token: str | None) -> str | None:
    """None on loopback; off loopback a warning to print, or ConfigError without a token."""
    if is_loopback(host):
        return None
    if not token:
        raise ConfigError(
            f"--host {host} serves the simulator to other machines: give an access token "
            "with --token or PARKNSS_WEB_TOKEN (8+ characters of A-Z a-z 0-9 . _ ~ -)"
        )
    return (f"WARNING: serving on {host}, reachable from other machines; every request "
            "needs the token (open the page with ?token=<token>)")


def _ip(name: str) -> ipaddress.IPv4Address | ipaddress.IPv6Address | None:
    try:
        return ipaddress.ip_address(name)
    except ValueError:
        return None


class HostPolicy:
    """Which ``Host`` header names this server answers to (see the module docstring)."""

    def __init__(self, bind_host: str, extra: Iterable[str] = ()) -> None:
        bind = bind_host.strip("[]").lower()
        self.wildcard = bind in WILDCARD
        self.names = {"localhost", *(n.lower() for n in extra)}
        if not self.wildcard:
            self.names.add(bind)
        if not is_loopback(bind):
            self.names.add(socket.gethostname().lower())
        self.bind_ip = _ip(bind)

    def allows(self, host_header: str) -> bool:
        host = host_header.strip().lower()
        if host.startswith("["):  # [v6]:port
            host = host[1 : host.find("]")] if "]" in host else host
        elif host.count(":") == 1:
            host = host.split(":", 1)[0]
        host = host.rstrip(".")
        if host in self.names:
            return True
        ip = _ip(host)
        if ip is None:
            return False
        return self.wildcard or ip.is_loopback or ip == self.bind_ip


def _headers(scope: Scope) -> dict[str, str]:
    return {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope["headers"]}


def _json_response(status: int, message: str, extra: list[tuple[bytes, bytes]] = ()):
    body = json.dumps({"error": message, "status": status}).encode()
    headers = [
        (b"content-type", b"application/json"),
        (b"content-length", str(len(body)).encode()),
        *extra,
    ]
    return {"type": "http.response.start", "status": status, "headers": headers}, body


async def _send_json(send: Send, status: int, message: str, extra=()) -> None:
    start, body = _json_response(status, message, list(extra))
    await send(start)
    await send({"type": "http.response.body", "body": body})


class Guard:
    """Wraps the app: Host check, token, body limit, last-resort 500 (module docstring)."""

    def __init__(
        self, app, *, hosts: HostPolicy, token: str | None, max_body_bytes: int
    ) -> None:
        self.app = app
        self.hosts = hosts
        self.token = token or None
        self.max_body = max_body_bytes

    def _presented(self, scope: Scope, headers: dict[str, str]) -> tuple[str | None, bool]:
        """(token the request carries, whether it came in the query string)."""
        auth = headers.get("authorization", "")
        if auth.lower().startswith("bearer "):
            return auth[7:].strip(), False
        if "x-parknss-token" in headers:
            return headers["x-parknss-token"], False
        query = dict(parse_qsl(scope.get("query_string", b"").decode("latin-1")))
        if "token" in query:
            return query["token"], True
        cookie = SimpleCookie()
        try:
            cookie.load(headers.get("cookie", ""))
        except Exception:  # a malformed cookie header carries no token
            return None, False
        return (cookie[COOKIE].value if COOKIE in cookie else None), False

    def _token_ok(self, given: str | None) -> bool:
        return given is not None and hmac.compare_digest(given.encode(), self.token.encode())

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        headers = _headers(scope)
        host = headers.get("host", "")
        if not self.hosts.allows(host):
            msg = f"Host header {host[:80]!r} does not name this server (DNS rebinding guard)"
            await _send_json(send, 400, msg)
            return
        if self.token is not None:
            given, in_query = self._presented(scope, headers)
            if not self._token_ok(given):
                msg = "a token is required: open the address with ?token=<token> or send it"
                await _send_json(send, 401, msg + " as 'Authorization: Bearer <token>'",
                                 [(b"www-authenticate", b"Bearer")])
                return
            if in_query and scope["method"] == "GET" and scope["path"] == "/":
                await self._set_cookie_and_redirect(scope, send)
                return
        length = headers.get("content-length")
        if length is not None and (not length.isdigit() or int(length) > self.max_body):
            await _send_json(send, 413, self._too_large(length))
            return
        await self._app_with_last_resort(scope, self._counting(receive), send)

    def _too_large(self, size: str | int) -> str:
        return (f"request body of {size} bytes is over the server's limit of "
                f"{self.max_body} bytes (max_body_bytes in configs/web.yaml)")

    def _counting(self, receive: Receive) -> Receive:
        seen = 0

        async def counted() -> dict:
            nonlocal seen
            message = await receive()
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                if seen > self.max_body:
                    raise BodyTooLargeError(self._too_large(f"more than {self.max_body}"))
            return message

        return counted

    async def _set_cookie_and_redirect(self, scope: Scope, send: Send) -> None:
        query = [(k, v) for k, v in parse_qsl(scope.get("query_string", b"").decode("latin-1"))
                 if k != "token"]
        location = "/" + (f"?{urlencode(query)}" if query else "")
        cookie = f"{COOKIE}={self.token}; Path=/; HttpOnly; SameSite=Strict"
        await send({
            "type": "http.response.start",
            "status": 303,
            "headers": [(b"location", location.encode()), (b"set-cookie", cookie.encode()),
                        (b"content-length", b"0")],
        })
        await send({"type": "http.response.body", "body": b""})

    async def _app_with_last_resort(self, scope: Scope, receive: Receive, send: Send) -> None:
        started = False

        async def tracking_send(message: dict) -> None:
            nonlocal started
            if message["type"] == "http.response.start":
                started = True
            await send(message)

        try:
            await self.app(scope, receive, tracking_send)
        except Exception as exc:
            if started:  # nothing sane can be sent any more
                raise
            if isinstance(exc, WebError):
                await _send_json(send, exc.status, str(exc))
                return
            log.exception("unexpected error in %s %s", scope["method"], scope["path"])
            msg = f"internal error ({type(exc).__name__}); see the server log"
            await _send_json(send, 500, msg)
