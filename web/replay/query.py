"""The query string of a tab's page URL (``?run=12&compare=13``), read from the server side.

viser 1.1.1 gives the server no access to a client's page URL: the websocket URL is the page URL
with its query cut off. But viser can run JavaScript in one client and read one key of that
client's browser storage back. So the server asks the tab to copy `window.location.search` into
a storage key named after its client id (two tabs never share a key), reads the key, and
removes it. Both messages are queued on the same websocket in order, so the read happens after
the copy. The JavaScript message is viser's own (`RunJavascriptMessage`, also used for Plotly);
if a future viser drops it, `read_query` returns {} and the tab starts with the run picker.
"""

from __future__ import annotations

import json
import logging
from typing import Any
from urllib.parse import parse_qs

log = logging.getLogger(__name__)

# viser prefixes the keys its localStorage API reads and writes (client MessageHandler.tsx).
VISER_STORAGE_PREFIX = "viser-user:"


def read_query(client: Any, timeout: float = 5.0) -> dict[str, str]:
    """The first value of each parameter in the tab's URL query; {} if it cannot be read.

    Blocks until the tab answers: call it from a worker thread, never viser's event loop.
    """
    try:
        from viser import _messages  # viser loads only once a viewer starts
    except ImportError:  # pragma: no cover - viser always ships it in 1.x
        return {}
    key = f"flybo-query-{client.client_id}"
    source = (f"try {{ window.localStorage.setItem({json.dumps(VISER_STORAGE_PREFIX + key)}, "
              f"window.location.search); }} catch (e) {{}}")
    try:
        client._websock_connection.queue_message(_messages.RunJavascriptMessage(source=source))
        search = client.local_storage.get_item(key, timeout=timeout)
        client.local_storage.remove_item(key)
    except (AttributeError, RuntimeError, TimeoutError) as exc:
        log.info("could not read the page URL of client %s: %s", client.client_id, exc)
        return {}
    if not search:
        return {}
    return {k: v[0] for k, v in parse_qs(search.lstrip("?")).items() if v}
