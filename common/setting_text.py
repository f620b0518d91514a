"""A setting given as text — an environment variable, ``--set FIELD=VALUE`` — read one way
for both (light: ``--help`` answers before pydantic is imported)."""

from __future__ import annotations

import json
from typing import Any


def setting_value(value: str) -> Any:
    """A setting's value given as text (an environment variable, ``--set FIELD=VALUE``): a
    list, table or quoted string in JSON, ``null`` for none; anything else as it is written,
    for the field's type to read (``7`` is a number to a number and a name to a name)."""
    if value == "null":
        return None
    if value[:1] in ("[", "{", '"'):
        try:
            return json.loads(value)
        except json.JSONDecodeError:
            return value
    return value
