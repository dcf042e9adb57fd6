"""The cache (``lever cache``): where the harness keeps what it computes once - the
references, the benchmark's do-nothing twins - how much it holds, and emptying it."""
from __future__ import annotations


def cache(clear: bool = False) -> dict:
    """What the cache holds (``harness.cache``): ``folder`` (``LEVER_CACHE_DIR``, else the
    user's cache folder of this version), per part (``parts``: ``references``,
    ``do-nothing-twins``) and in ``total`` its ``files`` and ``bytes``, and ``cleared``.
    ``clear``: remove every part (each is made again when needed) and return what they held."""
    from harness import cache as caches

    held = caches.clear() if clear else caches.size()
    return {**held, "cleared": clear, "parts": {name: {**figures, "holds": caches.PARTS[name]}
                                                for name, figures in held["parts"].items()}}
