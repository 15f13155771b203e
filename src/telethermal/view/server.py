"""``telethermal view``: the page, its live frames and its recordings over
HTTP on 127.0.0.1.

Python's own HTTP server (threads, one per connection) and Server-Sent
Events: the page is static HTML, CSS and ~300 lines of JavaScript drawing on
canvases, shipped in the package, so the browser requests nothing from
anywhere else. Routes: ``/`` the page; ``/static/*``; ``/api/info`` (live or
not, the recordings); ``/api/events`` (the live frames, SSE);
``/api/recording?name=N`` (one recording of the recordings folder as
series, or ``{"error": ...}`` with status 422 naming the file and why).
"""

from __future__ import annotations

import json
import queue
import logging
import threading
import time
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from pathlib import Path
from urllib.parse import parse_qs, urlparse

from telethermal.errors import TelethermalError
from telethermal.view.feed import LiveFeed

log = logging.getLogger(__name__)

STATIC = {"index.html": "text/html; charset=utf-8", "view.js": "text/javascript; charset=utf-8",
          "view.css": "text/css; charset=utf-8"}
#: Seconds between SSE comments on an idle stream (finds closed tabs).
KEEPALIVE_S = 1.0
#: The view's HTTP port on 127.0.0.1 unless one is given.
DEFAULT_PORT = 8050


def _static(name: str) -> bytes:
    return resources.files("telethermal.view").joinpath("static", name).read_bytes()


class ViewServer:
    """The HTTP server; ``feed`` (a :class:`LiveFeed`) may be None (recordings
    only); ``recordings``: a folder of ``*.mcap`` files, or None."""

    def __init__(self, port: int = 0, feed: LiveFeed | None = None,
                 recordings: str | Path | None = None, message: str = "",
                 bind: str = "127.0.0.1"):
        self.feed = feed
        self.recordings = Path(recordings) if recordings else None
        self.message = message
        self.stopping = threading.Event()
        self.started_s = time.monotonic()
        try:
            self.httpd = ThreadingHTTPServer((bind, port), _handler(self))
        except OSError as exc:
            raise TelethermalError(f"view: cannot listen on {bind}:{port}: {exc}") from exc
        self.httpd.daemon_threads = True
        self.port = self.httpd.server_address[1]
        self.url = f"http://127.0.0.1:{self.port}/"
        self._thread = threading.Thread(target=self.httpd.serve_forever, name="view-http",
                                        daemon=True)

    def start(self) -> "ViewServer":
        if self.feed is not None:
            self.feed.start()
        self._thread.start()
        return self

    def close(self) -> None:
        self.stopping.set()
        self.httpd.shutdown()
        self.httpd.server_close()
        if self.feed is not None:
            self.feed.close()

    def recording_names(self) -> list[str]:
        if self.recordings is None or not self.recordings.is_dir():
            return []
        return sorted(p.name for p in self.recordings.glob("*.mcap"))

    def playback(self, name: str) -> tuple[int, dict]:
        """(status, body) for one recording; never raises for a bad file."""
        from telethermal.view.playback import RecordingError, load_playback

        if name not in self.recording_names():
            return HTTPStatus.NOT_FOUND, {"error": f"no recording {name!r} in "
                                                  f"{self.recordings}"}
        try:
            return HTTPStatus.OK, load_playback(self.recordings / name)
        except RecordingError as exc:
            log.warning("view: %s", exc)
            return HTTPStatus.UNPROCESSABLE_ENTITY, {"error": f"cannot play {name}: {exc}"}
        except Exception as exc:             # noqa: BLE001 - a damaged file of any kind
            log.exception("view: %s", name)
            return HTTPStatus.UNPROCESSABLE_ENTITY, {
                "error": f"cannot play {name}: {type(exc).__name__}: {exc}"}


def _handler(view: ViewServer):
    class Handler(BaseHTTPRequestHandler):
        server_version = "telethermal-view"

        def log_message(self, fmt, *args):          # to logging, not stderr
            log.debug("%s " + fmt, self.address_string(), *args)

        def _send(self, status: int, body: bytes, ctype: str) -> None:
            self.send_response(status)
            self.send_header("Content-Type", ctype)
            self.send_header("Content-Length", str(len(body)))
            self.send_header("Cache-Control", "no-store")
            self.end_headers()
            self.wfile.write(body)

        def _json(self, status: int, value) -> None:
            self._send(status, json.dumps(value, allow_nan=False).encode(), "application/json")

        def do_GET(self):                               # noqa: N802 - the stdlib's name
            url = urlparse(self.path)
            path = url.path
            if path == "/":
                self._send(HTTPStatus.OK, _static("index.html"), STATIC["index.html"])
            elif path.startswith("/static/") and path[8:] in STATIC:
                self._send(HTTPStatus.OK, _static(path[8:]), STATIC[path[8:]])
            elif path == "/api/info":
                self._json(HTTPStatus.OK, {"live": view.feed is not None,
                                           "recordings": view.recording_names(),
                                           "message": view.message})
            elif path == "/api/recording":
                name = parse_qs(url.query).get("name", [""])[0]
                self._json(*view.playback(name))
            elif path == "/api/events" and view.feed is not None:
                self._events()
            else:
                self._json(HTTPStatus.NOT_FOUND, {"error": f"no such page {path!r}"})

        def _events(self) -> None:
            frames = view.feed.frames
            q = frames.subscribe()
            try:
                self.send_response(HTTPStatus.OK)
                self.send_header("Content-Type", "text/event-stream")
                self.send_header("Cache-Control", "no-store")
                self.end_headers()
                self.wfile.flush()
                while not view.stopping.is_set():
                    try:
                        frame = q.get(timeout=KEEPALIVE_S)
                    except queue.Empty:
                        self.wfile.write(b": keep-alive\n\n")
                    else:
                        self.wfile.write(b"data: " + json.dumps(frame).encode() + b"\n\n")
                    self.wfile.flush()
            except (BrokenPipeError, ConnectionResetError):
                pass                                    # the tab was closed
            finally:
                frames.unsubscribe(q)

    return Handler
