"""The ``telethermal view`` and ``telethermal bench view`` commands."""

from __future__ import annotations

import logging
import signal
import threading
from pathlib import Path

from telethermal.view.feed import LiveFeed
from telethermal.view.server import ViewServer

log = logging.getLogger(__name__)
DEFAULT_PORT = 8050


def live_feed(config) -> tuple[LiveFeed, str]:
    """A feed on the streams a master config names: its view stream and the
    slave's stream (as the master subscribes to it, with its keys). Returns
    the feed and a note for the page ('' when everything is shown)."""
    from telethermal.wire.transport import _load_public, _load_secret

    t = config.transport
    curve = None
    if t.security == "curve":
        public, secret = _load_secret(t.keys_dir, t.client_key)
        curve = (public, secret, _load_public(t.keys_dir, t.server_key))
    master_url = f"tcp://127.0.0.1:{config.view_port}" if config.view_port else None
    note = "" if master_url else ("the master's config has view_port = 0: its pad, the "
                                  "posterior, safety and link are not shown")
    return LiveFeed(master_url, f"tcp://{t.host}:{t.stream_port}", curve), note


def open_view(master_config: str | Path | None, recordings: str | Path | None,
              port: int) -> ViewServer:
    """The view server, started: live from the services of ``master_config``
    (if given), playing the ``*.mcap`` files of ``recordings``."""
    from telethermal.services.config import load_config

    feed, note = None, ""
    if master_config:
        config = load_config(master_config, "master")
        feed, note = live_feed(config)
        if recordings is None and config.record_dir:
            recordings = config.record_dir
    try:
        return ViewServer(port, feed, recordings, note).start()
    except Exception:
        if feed is not None:
            feed.close()
        raise


def wait_for_signal() -> None:
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    stop.wait()


def cmd_view(args) -> int:
    server = open_view(args.config, args.recordings, args.port)
    print(f"view: {server.url}  (live: {'yes' if server.feed else 'no'}; recordings: "
          f"{server.recordings or 'none'}); Ctrl-C to stop", flush=True)
    try:
        wait_for_signal()
    finally:
        server.close()
    return 0


def cmd_bench_view(args) -> int:
    from telethermal.bench import view

    report = view.run_and_save(args.json, touches=args.touches, contact_s=args.contact_s,
                               progress=lambda m: print(m, flush=True),
                               realtime_priority=args.realtime_priority)
    for line in view.text_report(report, args.json):
        print(line)
    return 0


def add_parsers(sub, bench_sub) -> None:
    p = sub.add_parser("view", help="a live view of a session in the browser (127.0.0.1), "
                                    "and its recordings played back")
    p.add_argument("--config", help="the master's config (services/master/config.toml): "
                                    "its view stream and the slave's stream are shown live")
    p.add_argument("--recordings", help="folder of MCAP recordings to play (default: the "
                                        "config's record_dir)")
    p.add_argument("--port", type=int, default=DEFAULT_PORT,
                   help=f"HTTP port on 127.0.0.1 (default {DEFAULT_PORT}; 0: a free one)")
    p.set_defaults(func=cmd_view)
    p = bench_sub.add_parser("view", help="the view's first paint, its lag at 1 kHz, and the "
                                          "master's loop timing with and without the page")
    p.add_argument("--json", required=True)
    p.add_argument("--touches", type=int, default=3)
    p.add_argument("--contact-s", type=float, default=3.0)
    p.add_argument("--realtime-priority", type=int, default=20,
                   help="the master loop's SCHED_FIFO priority, as in the demo (0: normal "
                        "scheduling, where the browser competes with the loop for the CPU)")
    p.set_defaults(func=cmd_bench_view)
