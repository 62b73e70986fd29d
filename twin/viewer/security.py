"""Who may connect and what a client's messages can reach: the only room of the live view that touches
viser's internals (its websocket server's construction, its message handlers, a client's outgoing buffer).

Nothing a client sends is trusted. The websocket handshake is refused (HTTP 403) unless its ``Host`` header
names this server and its ``Origin`` is the page's own origin, so a web page on another site cannot drive
the twin through the user's browser. GUI messages that are not a plain value of the right type for a known
control are dropped before viser applies them; the share tunnel and file uploads are closed."""

from __future__ import annotations

import contextlib
import http
import ipaddress
import math
import socket
import threading
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any
from urllib.parse import urlsplit

import numpy as np
import viser
from viser import _messages as viser_messages

from twin.viewer.common import _WS_LOGGER, ViewerError, _log, _show

MAX_MESSAGE_BYTES = 1 << 20  # a GUI message is a few hundred bytes; viser's own limit is 50 MB


_LOOPBACK_NAMES = frozenset({"localhost", "127.0.0.1", "::1"})


def _is_ip(name: str) -> bool:
    try:
        ipaddress.ip_address(name)
    except ValueError:
        return False
    return True


def is_loopback(host: str) -> bool:
    """Whether ``host`` (as given to ``--host``) reaches this machine only."""
    name = host.strip().lower().strip("[]")
    if name in _LOOPBACK_NAMES:
        return True
    if _is_ip(name):
        return ipaddress.ip_address(name).is_loopback
    try:
        infos = socket.getaddrinfo(name, None)
    except (socket.gaierror, UnicodeError):
        return False
    return bool(infos) and all(
        ipaddress.ip_address(str(info[4][0]).split("%")[0]).is_loopback for info in infos
    )


def _is_wildcard(host: str) -> bool:
    name = host.strip().strip("[]")
    return name == "" or (_is_ip(name) and ipaddress.ip_address(name).is_unspecified)


def _split_host(value: str) -> tuple[str, int] | None:
    """A ``Host`` header as (name, port), or None if it is not a plain host[:port]."""
    if not value or "@" in value or "/" in value or any(c.isspace() for c in value):
        return None
    try:
        parts = urlsplit("//" + value)
        port = parts.port
    except ValueError:
        return None
    if not parts.hostname or parts.path or parts.query or parts.fragment:
        return None
    return parts.hostname.lower(), port if port is not None else 80


def _split_origin(value: str) -> tuple[str, str, int] | None:
    """An origin as (scheme, name, port), or None if it is not a plain http(s)://host[:port]."""
    try:
        parts = urlsplit(value)
        port = parts.port
    except ValueError:
        return None
    if parts.scheme not in ("http", "https") or not parts.hostname or parts.username or parts.password:
        return None
    if parts.path not in ("", "/") or parts.query or parts.fragment:
        return None
    return (
        parts.scheme,
        parts.hostname.lower(),
        port if port is not None else (80 if parts.scheme == "http" else 443),
    )


@dataclass(frozen=True)
class OriginPolicy:
    """Which HTTP requests and websocket handshakes the server accepts.

    A request's ``Host`` header must name this server: the bound host or ``localhost`` at the bound port
    (and 127.0.0.1 / ::1 when bound to loopback; any IP address or this machine's name when bound to every
    interface) — a name an attacker's DNS could point here (DNS rebinding) is refused. A websocket
    handshake must carry an ``Origin`` that is the page's own origin, http://HOST:PORT with HOST one of
    those names (bound to every interface: the Host header's own name), or one of ``extra_origins`` — a page
    on another site cannot open one through the user's browser."""

    port: int
    host_names: frozenset[str]
    any_ip: bool = False  # bound to every interface: any IP literal names this server
    extra_origins: frozenset[tuple[str, str, int]] = frozenset()

    @classmethod
    def for_bind(cls, host: str, port: int, extra_origins: Sequence[str] = ()) -> OriginPolicy:
        names = {host.strip().lower().strip("[]"), "localhost"}
        wildcard = _is_wildcard(host)
        if wildcard or is_loopback(host):
            names |= _LOOPBACK_NAMES
        if wildcard:
            names |= {socket.gethostname().lower(), socket.getfqdn().lower()}
        names.discard("")
        extra = set()
        for origin in extra_origins:
            parsed = _split_origin(origin.strip()) if isinstance(origin, str) else None
            if parsed is None:
                raise ViewerError(
                    f"allowed origin {_show(origin)} is not scheme://host[:port] (http or https, no path)"
                )
            extra.add(parsed)
        return cls(port, frozenset(names), wildcard, frozenset(extra))

    def _host_ok(self, name: str, port: int) -> bool:
        if port == self.port and (name in self.host_names or (self.any_ip and _is_ip(name))):
            return True
        return any((name, port) == (n, p) for _, n, p in self.extra_origins)  # behind a proxy of theirs

    def refusal(self, hosts: Sequence[str], origins: Sequence[str], *, websocket: bool) -> str | None:
        """Why a request with these ``Host`` and ``Origin`` header values is refused, or None."""
        if len(hosts) != 1:
            return f"{len(hosts)} Host headers"
        host = _split_host(hosts[0])
        if host is None or not self._host_ok(*host):
            return f"Host {_show(hosts[0])} does not name this server"
        if not origins:
            return "a websocket without an Origin header" if websocket else None
        if len(origins) != 1:
            return f"{len(origins)} Origin headers"
        origin = _split_origin(origins[0])
        if origin is None:
            return f"Origin {_show(origins[0])} is not this page's"
        scheme, name, port = origin
        if origin in self.extra_origins:
            return None
        if scheme == "http" and port == self.port and name in self.host_names:
            return None
        if self.any_ip and scheme == "http" and (name, port) == host:
            return None
        return f"Origin {_show(origins[0])} is not this page's"


class _WebsocketHook:
    """Installs the origin policy, a message size limit and one-line error logs on viser's websocket server.

    viser 1.1 builds its server inside its own thread with ``websockets.asyncio.server.serve(ws_handler, host,
    port, process_request=…, max_size=50 MB, …)`` and exposes no hook. While the ``ViserServer`` is being
    constructed, ``serve`` is replaced by a wrapper that, for viser's call only, puts the policy in front of
    viser's ``process_request`` (a refused handshake gets HTTP 403), lowers ``max_size`` and routes the
    library's logs through ``_WS_LOGGER``. The constructor returns only once viser's thread has called
    ``serve``; ``installed`` says whether it did (if not, the viewer refuses to start)."""

    _lock = threading.Lock()  # one construction at a time patches the module

    def __init__(self, policy: OriginPolicy, on_refused: Callable[[str], None]) -> None:
        self.policy = policy
        self.on_refused = on_refused
        self.installed = False

    def process_request(self, inner: Callable[..., Any] | None) -> Callable[..., Any]:
        def process_request(connection: Any, request: Any) -> Any:
            headers = request.headers
            websocket = any("websocket" in v.lower() for v in headers.get_all("Upgrade"))
            reason = self.policy.refusal(
                headers.get_all("Host"), headers.get_all("Origin"), websocket=websocket
            )
            if reason is not None:
                self.on_refused(reason)
                return connection.respond(http.HTTPStatus.FORBIDDEN, f"Forbidden: {reason}\n")
            return inner(connection, request) if inner is not None else None

        return process_request

    @contextlib.contextmanager
    def installed_on_viser(self) -> Iterator[None]:
        import websockets.asyncio.server as ws_server

        original = ws_server.serve

        def serve(handler: Any, *args: Any, **kwargs: Any) -> Any:
            if getattr(handler, "__module__", "") == "viser.infra._infra":
                kwargs["process_request"] = self.process_request(kwargs.get("process_request"))
                kwargs["max_size"] = MAX_MESSAGE_BYTES
                kwargs["logger"] = _WS_LOGGER
                self.installed = True
            return original(handler, *args, **kwargs)

        with self._lock:
            ws_server.serve = serve  # type: ignore[misc,assignment]
            try:
                yield
            finally:
                ws_server.serve = original  # type: ignore[misc]


def _loop_exception(loop: Any, context: dict[str, Any]) -> None:
    """viser's event loop: a client message whose handler raised is one line, not a traceback."""
    exc = context.get("exception")
    text = f"{type(exc).__name__}: {exc}" if exc is not None else str(context.get("message", ""))
    _log(f"a client message failed ({text})", key="message failed")


def harden_messages(
    server: viser.ViserServer, refusal: Callable[[Any], str | None], on_drop: Callable[[str], None]
) -> None:
    """What a client's messages can reach: only the value of a known control, of its own type (``refusal``
    of the message says why not, before viser applies it; the loop checks the value itself); never the share
    tunnel (which the hidden Share button would otherwise still open to the internet on request) nor file
    uploads; and a handler that raises is one log line."""
    ws = server._websock_server
    handlers = ws._incoming_handlers.get(viser_messages.GuiUpdateMessage, [])
    original = server.gui._handle_gui_updates
    index = next((i for i, cb in enumerate(handlers) if cb == original), None)
    if index is None:
        server.stop()
        raise ViewerError(f"viser {viser.__version__}: its GUI update handler was not found")

    async def checked(client_id: Any, message: Any) -> None:
        reason = refusal(message)
        if reason is not None:
            on_drop(reason)
            return
        await original(client_id, message)

    handlers[index] = checked
    for message_type in (
        viser_messages.ShareUrlRequest,  # the share tunnel
        viser_messages.ShareUrlDisconnect,
        viser_messages.FileTransferStartUpload,  # uploads (there is no upload button: only memory to fill)
        viser_messages.FileTransferPart,
    ):
        if message_type in ws._incoming_handlers:
            ws.unregister_handler(message_type)
    loop = ws._background_event_loop
    if loop is not None:
        loop.call_soon_threadsafe(loop.set_exception_handler, _loop_exception)


def gui_update_refusal(server: viser.ViserServer, message: Any) -> str | None:
    """Why a client's GUI update is not a plain value of the right type for a known control, or None."""
    uuid, updates = getattr(message, "uuid", None), getattr(message, "updates", None)
    handle = server.gui._gui_input_handle_from_uuid.get(uuid) if isinstance(uuid, str) else None
    if handle is None:
        return f"no control {_show(uuid)}"
    if not isinstance(updates, dict) or set(updates) != {"value"}:
        return f"only a control's value may change, not {_show(updates)}"
    value, kind = updates["value"], type(handle.value)
    if kind is bool:
        ok = isinstance(value, bool)
    elif kind is str:
        ok = isinstance(value, str) and len(value) <= 200
    elif kind in (int, float):
        ok = isinstance(value, (int, float)) and not isinstance(value, bool)
    else:
        ok = False
    return None if ok else f"{handle.label!r} = {_show(value)} is not a {kind.__name__}"


def control_uuid(handle: Any) -> str:
    """The id a client names a control by in its messages."""
    return str(handle._impl.uuid)


def download_bytes_queued(client: Any) -> int:
    """Bytes of file downloads still waiting in ``client``'s outgoing buffer (viser keeps a message there
    until its connection has taken it): while a download is on its way, another click builds nothing and
    queues nothing, so clicks cannot pile copies of the record up in memory."""
    buffer = client._websock_connection.get_message_buffer()
    with buffer.buffer_lock:
        messages = list(buffer.message_from_id.values())
    return sum(len(m.content) for m in messages if isinstance(m, viser_messages.FileTransferPart))


def free_port_or_raise(host: str, port: int) -> None:
    """viser moves silently to the next free port; a taken port is an error here instead."""
    if not 1 <= port <= 65535:
        raise ViewerError(f"--port {port} is not a TCP port (1–65535)")
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
    except socket.gaierror as exc:
        raise ViewerError(f"--host {host!r} cannot be resolved: {exc}") from None
    family, _, _, _, address = infos[0]
    with socket.socket(family, socket.SOCK_STREAM) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind(address)
        except OSError as exc:
            raise ViewerError(
                f"port {port} on {host} is taken ({exc.strerror}); choose another with --port"
            ) from None


def send_uplot_data(handle: Any, data: tuple[Any, ...]) -> None:
    """Set a uPlot chart's data, a column being a numpy array (sent as binary) or a list with None for a gap.

    viser's ``handle.data = …`` casts every column to a float64 array, where a gap can only be NaN (which
    empties the chart); the update message it would queue is queued here with the columns as given. The
    handle's own copy keeps the arrays (NaN for a gap) for whoever reads ``handle.data``."""
    arrays = tuple(
        np.asarray([math.nan if v is None else v for v in c] if isinstance(c, list) else c) for c in data
    )
    object.__setattr__(handle._impl.props, "data", arrays)
    handle._impl.gui_api._websock_interface.queue_message(
        viser_messages.GuiUpdateMessage(handle._impl.uuid, {"data": data})
    )
