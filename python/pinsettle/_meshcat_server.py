"""A meshcat server that listens on the loopback interface only (run by ``pinsettle.play``).

meshcat's own ``meshcat-server`` binds its ZeroMQ socket to 127.0.0.1 but its web server to
every interface; this one binds both to 127.0.0.1. It prints ``zmq_url=...`` and
``web_url=...`` on stdout (as meshcat's server does), then stops writing anything, and exits
by itself when the process that started it (``--parent PID``) is gone.

With ``--page FILE`` it also serves that page at /pinsettle/ (pinsettle's live page: meshcat's
viewer and the playback's overlay) and prints that address as web_url.

Usage: ``python -m pinsettle._meshcat_server --parent PID [--page FILE]``.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from tornado.httpserver import HTTPServer
    from tornado.web import Application

HOST = "127.0.0.1"


def _bridge_class(page: str | None = None) -> type[Any]:
    import tornado.web
    from meshcat.servers.zmqserver import ZMQWebSocketBridge

    class PageHandler(tornado.web.RequestHandler):
        """pinsettle's live page (meshcat's viewer and the playback's overlay)."""

        def get(self) -> None:
            self.set_header("Cache-Control", "no-store")
            self.write(page or "")

    class LoopbackBridge(ZMQWebSocketBridge):  # type: ignore[misc]  # meshcat: no types
        """meshcat's bridge with its web server bound to 127.0.0.1 (not every interface)."""

        def make_app(self) -> Application:
            app: Application = super().make_app()
            listen = app.listen

            def listen_on_loopback(
                port: int, address: str | None = None, **kwargs: Any
            ) -> HTTPServer:
                return listen(port, HOST, **kwargs)  # whatever address was asked for

            # The bridge looks the method up on the instance (mypy forbids assigning a method).
            app.listen = listen_on_loopback  # type: ignore[method-assign]
            if page is not None:
                app.wildcard_router.add_rules([(r"/pinsettle/", PageHandler)])
            return app

    return LoopbackBridge


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m pinsettle._meshcat_server")
    parser.add_argument("--parent", type=int, default=None, help="exit when this process is gone")
    parser.add_argument("--page", default=None, help="an HTML file to serve at /pinsettle/")
    args = parser.parse_args(argv)

    import tornado.ioloop

    page = None if args.page is None else Path(args.page).read_text(encoding="utf-8")
    bridge = _bridge_class(page)(host=HOST)
    web_url = bridge.web_url if page is None else bridge.web_url.replace("/static/", "/pinsettle/")
    print(f"zmq_url={bridge.zmq_url}", flush=True)
    print(f"web_url={web_url}", flush=True)
    # Nothing reads our output from now on: send it nowhere, so that a full pipe never blocks.
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)
    os.dup2(devnull, 2)

    if args.parent is not None:
        parent = args.parent

        def check_parent() -> None:
            if os.getppid() != parent:
                tornado.ioloop.IOLoop.current().stop()

        tornado.ioloop.PeriodicCallback(check_parent, 500).start()
    bridge.run()
    return 0


if __name__ == "__main__":
    sys.exit(main())
