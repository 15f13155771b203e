"""The viewer: the live view's server (``telethermal view``) on a master's
streams and a folder of recordings, kept up until SIGINT or SIGTERM."""

from __future__ import annotations

import signal
import threading
from pathlib import Path

from telethermal.control.loop import RealClock
from telethermal.services.config import load_config
from telethermal.view.feed import LiveFeed
from telethermal.view.server import ViewServer
from telethermal.wire.keys import load_public, load_secret


def live_feed(config) -> tuple[LiveFeed, str]:
    """A feed on the streams a master config names: its view stream and the
    slave's stream (as the master subscribes to it, with its keys). Returns
    the feed and a note for the page ('' when everything is shown)."""
    t = config.transport
    curve = None
    if t.security == "curve":
        public, secret = load_secret(t.keys_dir, t.client_key)
        curve = (public, secret, load_public(t.keys_dir, t.server_key))
    master_url = f"tcp://127.0.0.1:{config.view_port}" if config.view_port else None
    note = "" if master_url else ("the master's config has view_port = 0: its pad, the "
                                  "posterior, safety and link are not shown")
    # The services' times are on their clock (time_scale): so are the feed's.
    clock = RealClock(scale=config.time_scale).monotonic
    return LiveFeed(master_url, f"tcp://{t.host}:{t.stream_port}", curve, clock=clock), note


def open_view(master_config: str | Path | None, recordings: str | Path | None,
              port: int, bind: str = "127.0.0.1") -> ViewServer:
    """The view server, started: live from the services of ``master_config``
    (if given), playing the ``*.mcap`` files of ``recordings``; its HTTP on
    ``bind`` (loopback unless a container publishes it to its host)."""
    feed, note = None, ""
    if master_config:
        config = load_config(master_config, "master")
        feed, note = live_feed(config)
        if recordings is None and config.record_dir:
            recordings = config.record_dir
    try:
        return ViewServer(port, feed, recordings, note, bind).start()
    except Exception:
        if feed is not None:
            feed.close()
        raise


def wait_for_signal() -> None:
    """Block until SIGINT or SIGTERM."""
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    stop.wait()


def serve_until_signal(server: ViewServer) -> None:
    """Keep ``server`` up until SIGINT or SIGTERM, then close it."""
    try:
        wait_for_signal()
    finally:
        server.close()
