"""meshcat's ZMQ/websocket server, listening on 127.0.0.1 only (run as a subprocess by the viewer).

meshcat 0.3.2's ``ZMQWebSocketBridge`` binds its ZMQ socket to the host it is given but starts its
web server with ``app.listen(port)``, i.e. on every interface. Here the web server is told the
address too. Prints ``zmq_url=…`` and ``web_url=…`` like meshcat's own server, then serves until
its stdin ends.
"""

from __future__ import annotations

import os
import sys
import threading

import tornado.web
from meshcat.servers.zmqserver import ZMQWebSocketBridge

HOST = "127.0.0.1"


class _LocalBridge(ZMQWebSocketBridge):
    def make_app(self) -> tornado.web.Application:
        app = super().make_app()
        listen = app.listen

        def listen_locally(port: int, **kwargs: object) -> object:
            return listen(port, address=HOST, **kwargs)

        app.listen = listen_locally
        return app


def _exit_at_end_of_stdin() -> None:
    """Stop when the parent closes our stdin or dies (its end of the pipe closes either way)."""
    sys.stdin.read()
    os._exit(0)


def main() -> None:
    bridge = _LocalBridge(host=HOST)
    threading.Thread(target=_exit_at_end_of_stdin, daemon=True).start()
    print(f"zmq_url={bridge.zmq_url}", flush=True)
    print(f"web_url={bridge.web_url}", flush=True)
    try:
        bridge.run()
    except KeyboardInterrupt:
        pass


if __name__ == "__main__":
    main()
