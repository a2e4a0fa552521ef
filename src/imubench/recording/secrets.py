"""Secrets in recording headers: what ``convert`` drops from an old header.

Recordings made before the configuration's passwords became secret fields (issue 12)
carry the whole configuration in their header, ``mqtt.password`` in clear among it. A
secret here is what the configuration keeps secret (``mqtt.password``, ``web.password``:
every ``SecretStr`` field; ``tests/test_exports.py`` checks the rule covers them), found
at any depth of the header:

* a key named ``password``, or ending in ``_password`` / ``-password`` (any case);
* the password of a URL's user information (``mqtt://user:PASSWORD@host``), which
  becomes ``mqtt://user@host``.

The mask a current header carries (``"**********"``, pydantic's) is not a secret and is
kept as it is.
"""

from __future__ import annotations

import re
from typing import Any

MASK = "**********"
"""How the configuration's dump shows a set secret."""
_URL_PASSWORD = re.compile(r"(?P<head>[a-zA-Z][a-zA-Z0-9+.-]*://[^/@:\s]*):[^/@\s]*@")


def is_secret_key(key: str) -> bool:
    k = key.lower()
    return k == "password" or k.endswith(("_password", "-password"))


def drop_secrets(value: Any, where: str = "") -> tuple[Any, list[str]]:
    """(``value`` without its secrets, the key paths dropped). ``value`` is not changed."""
    dropped: list[str] = []
    if isinstance(value, dict):
        out: dict[Any, Any] = {}
        for key, item in value.items():
            path = f"{where}.{key}" if where else str(key)
            if isinstance(key, str) and is_secret_key(key) and item not in (None, MASK):
                dropped.append(path)
                continue
            out[key], more = drop_secrets(item, path)
            dropped += more
        return out, dropped
    if isinstance(value, list):
        items = []
        for i, item in enumerate(value):
            clean, more = drop_secrets(item, f"{where}[{i}]")
            items.append(clean)
            dropped += more
        return items, dropped
    if isinstance(value, str) and _URL_PASSWORD.search(value):
        return _URL_PASSWORD.sub(r"\g<head>@", value), [f"{where} (URL password)"]
    return value, dropped
