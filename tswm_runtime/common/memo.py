"""Bounded memos: a value worked out once per key (a module, a run's settings) and kept until its cache
holds ``limit`` entries, when the cache starts afresh."""
from __future__ import annotations


def remember(cache: dict, key, value, limit: int = 256):
    """Store ``value`` under ``key`` (emptying a cache that holds ``limit`` entries first); return it."""
    if len(cache) >= limit:
        cache.clear()
    cache[key] = value
    return value


def remembered(cache: dict, key, build, limit: int = 256):
    """``cache[key]``, made by ``build()`` and remembered on a miss."""
    value = cache.get(key)
    return remember(cache, key, build(), limit) if value is None else value


def overrides_key(overrides: dict) -> tuple:
    """A key for run-setting overrides that tells 1 from True and 1.0, and 0.0 from -0.0 (equal in Python,
    not to a run); hashing it raises TypeError for an unhashable value."""
    return tuple((k, type(v), v.hex() if isinstance(v, float) else v) for k, v in overrides.items())
