"""Plain (JSON/YAML-safe) copies of nested results: dicts with str keys, lists, Python scalars."""

from __future__ import annotations

import math

import numpy as np


def to_plain(value, drop_unknown: bool = False):
    """numpy scalars -> Python, arrays and tuples -> lists, dict keys -> str.

    With ``drop_unknown`` everything that is not a str/int/float/bool/None (arrays included) is
    left out, for metadata that must stay small (bag sidecars).
    """
    if isinstance(value, dict):
        items = ((str(k), to_plain(v, drop_unknown)) for k, v in value.items())
        return {k: v for k, v in items if not (drop_unknown and v is None)}
    if isinstance(value, list | tuple):
        items = [to_plain(v, drop_unknown) for v in value]
        lost = any(p is None and v is not None for p, v in zip(items, value, strict=True))
        return None if drop_unknown and lost else items
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return None if drop_unknown else value.tolist()
    if drop_unknown and not isinstance(value, str | int | float | bool):
        return None
    return value


def json_safe(value):
    """:func:`to_plain`, and every non-finite float (NaN, infinity: JSON has neither) as None,
    e.g. the distance of an empty map, so the output parses with any JSON reader."""
    value = to_plain(value)
    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, list):
        return [json_safe(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value
