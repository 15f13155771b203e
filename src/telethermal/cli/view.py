"""``telethermal view``: the live view and the recordings in the browser."""

from __future__ import annotations

from telethermal.cli._common import _port
from telethermal.view.server import DEFAULT_PORT


def cmd_view(args) -> int:
    from telethermal.services.viewer import open_view, serve_until_signal

    server = open_view(args.config, args.recordings, args.port, args.bind)
    print(f"view: {server.url}  (live: {'yes' if server.feed else 'no'}; recordings: "
          f"{server.recordings or 'none'}); Ctrl-C to stop", flush=True)
    serve_until_signal(server)
    return 0


def add_parser(sub) -> None:
    p = sub.add_parser("view", help="a live view of a session in the browser (127.0.0.1), "
                                    "and its recordings played back")
    p.add_argument("--config", help="the master's config (services/master/config.toml): "
                                    "its view stream and the slave's stream are shown live")
    p.add_argument("--recordings", help="folder of MCAP recordings to play (default: the "
                                        "config's record_dir)")
    p.add_argument("--port", type=_port, default=DEFAULT_PORT,
                   help=f"HTTP port on 127.0.0.1 (default {DEFAULT_PORT}; 0: a free one)")
    p.add_argument("--bind", default="127.0.0.1", metavar="ADDRESS",
                   help="the address the page is served on (default 127.0.0.1; 0.0.0.0 "
                        "only inside a container whose port the host publishes on its "
                        "own loopback, as docker-compose.yml's view service does)")
    p.set_defaults(func=cmd_view)
