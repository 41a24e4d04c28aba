"""What both device emulators need around ``socketserver``: a threaded TCP server that
knows its client connections (so a test or the lab can cut them: a link drop as the
client sees it) and a start/close/``with`` wrapper that serves it in a thread."""

from __future__ import annotations

import contextlib
import socket
import socketserver
import threading


class TrackedTCPServer(socketserver.ThreadingTCPServer):
    """A threaded TCP server whose handlers register their connections
    (``TrackedHandler``), so that ``drop_clients`` can close them all."""

    allow_reuse_address = True
    daemon_threads = True

    def __init__(self, address: tuple[str, int], handler: type) -> None:
        self.clients: set[socket.socket] = set()
        self.clients_lock = threading.Lock()
        super().__init__(address, handler)

    def drop_clients(self) -> None:
        """Close every client connection (the client sees the link drop)."""
        with self.clients_lock:
            clients = list(self.clients)
        for sock in clients:
            with contextlib.suppress(OSError):
                sock.shutdown(socket.SHUT_RDWR)


class TrackedHandler(socketserver.BaseRequestHandler):
    """Registers its connection with a ``TrackedTCPServer`` for its lifetime."""

    server: TrackedTCPServer

    def setup(self) -> None:
        super().setup()
        with self.server.clients_lock:
            self.server.clients.add(self.request)

    def finish(self) -> None:
        with self.server.clients_lock:
            self.server.clients.discard(self.request)
        super().finish()


class ServedEmulator:
    """Serves ``self._server`` (a ``TrackedTCPServer``, set by the subclass) in a daemon
    thread: ``start()``; ``close()`` stops it and drops every client; a ``with`` block
    does both."""

    _server: TrackedTCPServer
    thread_name = "emulator"

    @property
    def address(self) -> tuple[str, int]:
        host, port = self._server.server_address[:2]
        return str(host), int(port)

    def start(self):
        self._thread = threading.Thread(
            target=self._server.serve_forever, args=(0.05,), name=self.thread_name, daemon=True
        )
        self._thread.start()
        return self

    def drop_clients(self) -> None:
        """Cut every client connection (a link drop as the client sees it)."""
        self._server.drop_clients()

    def close(self) -> None:
        self._server.shutdown()
        self._server.drop_clients()
        self._server.server_close()
        thread = getattr(self, "_thread", None)
        if thread is not None:
            thread.join(2.0)

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()
