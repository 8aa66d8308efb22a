"""The replay viewer: one viser server, one `ClientSession` (own scene, own clock) per tab.

A tab chooses its run by its page URL, ``http://host:port/?run=12`` (and ``&compare=13``), or in
the GUI's "Runs" folder. Started on one recording file (`flybo viewer --recording FILE`), tabs
without a query show that recording, and the GUI accepts other recording paths: that mode is for
one user on their own machine. Started for the service, only run ids are accepted.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sqlalchemy.orm import Session, sessionmaker

from server.db import make_engine, make_session_factory
from server.settings import Settings
from server.storage import ArtifactStore, settings_store
from web.replay.cache import RunCache
from web.replay.session import ClientSession
from web.replay.source import (
    RunData,
    RunLookupError,
    load_file_run,
    load_stored_run,
    recent_runs,
)

log = logging.getLogger(__name__)


class ReplayApp:
    """Serves replays to every tab connected to `server`."""

    def __init__(self, settings: Settings, server: Any, *, recording: Path | None = None,
                 compare: Path | None = None) -> None:
        self.settings, self.server = settings, server
        self.file_mode = recording is not None
        self.default_key = None if recording is None else self._file_key(recording)
        self.default_compare = None if compare is None else self._file_key(compare)
        self.cache = RunCache(self._load)
        self.sessions: dict[int, ClientSession] = {}
        self._lock = threading.Lock()
        self._db: tuple[sessionmaker[Session], ArtifactStore] | None = None
        server.on_client_connect(self._connect)
        server.on_client_disconnect(self._disconnect)

    @staticmethod
    def _file_key(path: Path) -> str:
        return f"file:{path.expanduser().resolve()}"

    # -- hooks for the sessions ----------------------------------------------------------------
    def initial_keys(self, query: dict[str, str]) -> tuple[str | None, str | None]:
        """The runs a new tab opens: from its URL query, else the recording given at start."""
        primary, compare = self.default_key, self.default_compare
        try:
            if "run" in query:
                primary, compare = self._run_key(query["run"]), None
            if "compare" in query:
                compare = self._run_key(query["compare"])
        except RunLookupError as exc:
            log.info("ignoring the page query %s: %s", query, exc)
        return primary, compare

    def key_for(self, text: str) -> str:
        """The cache key of what a user typed: a run id, or (file mode only) a recording path."""
        text = text.strip()
        if text.isdigit():
            return self._run_key(text)
        if self.file_mode and text:
            path = Path(text).expanduser()
            if not path.is_file():
                raise RunLookupError(f"no recording at {path}")
            return self._file_key(path)
        raise RunLookupError(f"not a run id: {text!r}")

    def recent_runs(self) -> list[tuple[int, str]]:
        try:
            return recent_runs(self._database()[0])
        except Exception as exc:  # no database yet: the picker is simply empty
            log.info("cannot list recent runs: %s", exc)
            return []

    # -- loading -------------------------------------------------------------------------------
    @staticmethod
    def _run_key(text: str) -> str:
        try:
            run_id = int(text)
        except ValueError:
            raise RunLookupError(f"not a run id: {text!r}") from None
        if run_id < 1:
            raise RunLookupError(f"not a run id: {text!r}")
        return f"run:{run_id}"

    def _database(self) -> tuple[sessionmaker[Session], ArtifactStore]:
        """The session factory and artifact store, made on first use: file mode needs neither."""
        with self._lock:
            if self._db is None:
                sessions = make_session_factory(make_engine(self.settings.db_url))
                store = settings_store(self.settings)
                self._db = (sessions, store)
            return self._db

    def _load(self, key: str) -> RunData:
        kind, _, rest = key.partition(":")
        if kind == "file":
            return load_file_run(Path(rest))
        sessions, store = self._database()
        return load_stored_run(sessions, store, int(rest))

    # -- tabs ----------------------------------------------------------------------------------
    def _connect(self, client: Any) -> None:
        session = ClientSession(self, client)
        with self._lock:
            self.sessions[client.client_id] = session
        session.start()

    def _disconnect(self, client: Any) -> None:
        with self._lock:
            session = self.sessions.pop(client.client_id, None)
        if session is not None:
            session.close()

    def close(self) -> None:
        with self._lock:
            sessions = list(self.sessions.values())
            self.sessions.clear()
        for session in sessions:
            session.close()
        self.cache.close()


@dataclass
class ViewerHandle:
    """A running viewer; `stop()` closes every tab's session and the server."""

    app: ReplayApp
    server: Any
    host: str
    port: int

    @property
    def url(self) -> str:
        return f"http://{self.host}:{self.port}"

    def stop(self) -> None:
        self.app.close()
        self.server.stop()


def start_viewer(settings: Settings, host: str, port: int, *, recording: Path | None = None,
                 compare: Path | None = None) -> ViewerHandle:
    """Start the viewer in background threads and return at once.

    Args:
        recording: replay this file in tabs that name no run (the library and CLI use).
        compare: with `recording`, a second recording on the same area to compare with.

    Raises:
        RunLookupError: `recording` cannot be read.
    """
    import viser  # loads only once a viewer starts (the site imports web.replay too)

    server = viser.ViserServer(host=host, port=port, label="FLYBO replay", verbose=False)
    try:
        app = ReplayApp(settings, server, recording=recording, compare=compare)
        for key in (app.default_key, app.default_compare):
            if key is not None:  # fail now, in the caller, on a bad file; and warm the cache
                app.cache.get(key)
    except BaseException:
        server.stop()
        raise
    return ViewerHandle(app, server, host, server.get_port())


def serve_viewer(settings: Settings, host: str, port: int, *, recording: Path | None = None,
                 compare: Path | None = None) -> None:
    """Run the viewer until interrupted (Ctrl-C)."""
    handle = start_viewer(settings, host, port, recording=recording, compare=compare)
    print(f"FLYBO replay viewer at {handle.url}/" + ("" if recording else "?run=ID"), flush=True)
    try:
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        pass
    finally:
        handle.stop()
