"""The cache (``lever cache``): where the harness keeps what it computes once - the
references, the benchmark's do-nothing twins - how much it holds, and emptying it."""
from __future__ import annotations


def cache(clear: bool = False, stale: bool = False) -> dict:
    """What the cache holds (``harness.cache``): ``folder`` (``LEVER_CACHE_DIR``, else the
    user's cache folder of this version), per part (``parts``: ``references``,
    ``do-nothing-twins``, each saying what it ``holds``) and in ``total`` its ``files`` and
    ``bytes`` and of them the stale ones (``stale_files``, ``stale_bytes``: left by other
    code, never read again).  ``clear``: remove every entry (made again when needed), with
    ``stale`` only the stale ones; what was held is returned, ``cleared`` says which."""
    from harness import cache as caches

    held = caches.clear(stale_only=stale) if clear else caches.size()
    return {**held, "cleared": ("stale" if stale else "all") if clear else None,
            "parts": {name: {**figures, "holds": caches.PARTS[name]} for name, figures in held["parts"].items()}}
