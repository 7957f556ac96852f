"""`scenariomax view --serve`: the viewer page on 127.0.0.1 for datasets too large for one HTML file.

A small threaded stdlib HTTP server. Start-up only indexes the records (`ShardIndex`: frame headers
and scenario ids, never the payloads); each scene is read, validated and packed when the page asks
for it, and a few packed scenes are kept in an LRU cache. A background thread computes the list's
inspect / validate summaries in file order, and the page polls for them, so the first page is
served at once and memory stays bounded whatever the dataset size.

Routes: `/` the page, `/api/index` the record list, `/api/summaries?since=N` summaries finished
since the N-th, `/api/scene/<position>` one packed scene (see `scenariomax.view.scene`).
"""

from __future__ import annotations

import collections
import json
import os
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from urllib.parse import parse_qs, urlsplit

from scenariomax.view.index import ShardIndex, compact_summary
from scenariomax.view.page import render_page, scene_for
from scenariomax.view.scene import error_scene

SCENE_CACHE_SIZE = 16


class ViewerState:
    """What the handler threads share: the index, the summaries found so far and a small scene cache."""

    def __init__(self, index: ShardIndex, initial: int = 0, summarize: bool = True):
        self.index = index
        self.initial = initial
        self.summaries: dict[int, dict] = {}
        self.order: list[int] = []  # positions in the order their summaries were finished
        self.lock = threading.Lock()
        self.cache: collections.OrderedDict[int, bytes] = collections.OrderedDict()
        self.stop = threading.Event()
        self.page = render_page({"mode": "serve", "title": f"V-Max viewer - {index.path}", "initial": initial})
        self.worker = threading.Thread(target=self._summarize_all, name="vmax-view-summaries", daemon=True)
        if summarize:
            self.worker.start()

    def _store_summary(self, position: int, summary: dict) -> None:
        with self.lock:
            if position not in self.summaries:
                self.summaries[position] = summary
                self.order.append(position)

    def _summarize_all(self) -> None:
        for position in range(len(self.index)):
            if self.stop.is_set():
                return
            with self.lock:
                done = position in self.summaries
            if not done:
                self._store_summary(position, compact_summary(self.index.check(position)))

    def scene(self, position: int) -> bytes:
        with self.lock:
            if position in self.cache:
                self.cache.move_to_end(position)
                return self.cache[position]
        try:
            blob, entry = scene_for(self.index, position)
            self._store_summary(position, entry["summary"])
        except Exception as error:  # noqa: BLE001 - a record that breaks the viewer is shown as an error, not a crash
            blob = error_scene(f"{type(error).__name__}: {error}".splitlines()[0])
        with self.lock:
            self.cache[position] = blob
            while len(self.cache) > SCENE_CACHE_SIZE:
                self.cache.popitem(last=False)
        return blob

    def index_json(self) -> dict:
        note = f"{len(self.index)} records in {len(self.index.files)} file(s); summaries fill in as they are computed"
        return {"entries": [self.index.describe(i) for i in range(len(self.index))], "note": note,
                "file_errors": list(self.index.file_errors)}

    def summaries_since(self, since: int) -> dict:
        with self.lock:
            new = self.order[since:]
            return {"done": len(self.order), "total": len(self.index),
                    "summaries": {str(p): self.summaries[p] for p in new}}


def _handler(state: ViewerState):
    class Handler(BaseHTTPRequestHandler):
        server_version = "vmax-view"

        def log_message(self, format, *args):  # noqa: A002 - quiet: the terminal shows the URL only
            pass

        def _send(self, status: int, body: bytes, content_type: str) -> None:
            self.send_response(status)
            self.send_header("Content-Type", content_type)
            self.send_header("Content-Length", str(len(body)))
            self.send_header("Cache-Control", "no-store")
            self.end_headers()
            self.wfile.write(body)

        def _json(self, value) -> None:
            self._send(200, json.dumps(value, separators=(",", ":")).encode(), "application/json")

        def do_GET(self):  # noqa: N802 - the stdlib's name
            url = urlsplit(self.path)
            route = url.path
            try:
                if route in ("/", "/index.html"):
                    self._send(200, state.page.encode("utf-8"), "text/html; charset=utf-8")
                elif route == "/api/index":
                    self._json(state.index_json())
                elif route == "/api/summaries":
                    since = int(parse_qs(url.query).get("since", ["0"])[0])
                    self._json(state.summaries_since(max(0, since)))
                elif route.startswith("/api/scene/"):
                    position = int(route.rsplit("/", 1)[1])
                    if not 0 <= position < len(state.index):
                        self._send(404, b"no such scene", "text/plain")
                        return
                    self._send(200, state.scene(position), "application/octet-stream")
                else:
                    self._send(404, b"not found", "text/plain")
            except ValueError:
                self._send(400, b"bad request", "text/plain")
            except (BrokenPipeError, ConnectionResetError):
                pass

    return Handler


def make_server(path: str | os.PathLike, *, port: int = 8765, host: str = "127.0.0.1",
                scenario_id: str | None = None, summarize: bool = True) -> tuple[ThreadingHTTPServer, ViewerState]:
    """Indexes `path` and binds the server (not yet serving). port 0 picks a free port.
    InputError for bad input; OSError when the port is taken."""
    index = ShardIndex.build(path)
    initial = index.find(scenario_id) if scenario_id is not None else 0
    state = ViewerState(index, initial=initial, summarize=summarize)
    server = ThreadingHTTPServer((host, port), _handler(state))
    server.daemon_threads = True
    return server, state


def serve_view(path: str | os.PathLike, *, port: int = 8765, host: str = "127.0.0.1", scenario_id: str | None = None,
               print_fn=print) -> None:
    """Serves the viewer until interrupted (Ctrl-C)."""
    start = time.perf_counter()
    try:
        server, state = make_server(path, port=port, host=host, scenario_id=scenario_id)
    except OSError as error:
        if getattr(error, "errno", None) in (98, 48, 10048):  # address in use (Linux, macOS, Windows)
            raise OSError(f"port {port} on {host} is in use; pick another with --port") from None
        raise
    url = f"http://{host}:{server.server_address[1]}/"
    print_fn(f"indexed {len(state.index)} records in {len(state.index.files)} file(s) in "
             f"{time.perf_counter() - start:.2f} s; serving {url} (Ctrl-C stops)")
    try:
        server.serve_forever(poll_interval=0.2)
    except KeyboardInterrupt:
        print_fn("stopped")
    finally:
        state.stop.set()
        server.server_close()


__all__ = ["ViewerState", "make_server", "serve_view"]
