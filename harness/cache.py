"""The harness's cache: what it computes once and reuses - the monolithic references and
the references made from a scene's FMUs (``references/``), the benchmark's do-nothing twins
of the FMUs (``do-nothing-twins/``), the factors of the units values are given in
(``unit-factors/``, ``harness.description.units``).

Where: the folder ``LEVER_CACHE_DIR`` names, else the per-user cache folder of this
version (``platformdirs.user_cache_dir``: ``~/.cache/lever-cosim/<version>`` on Linux,
``~/Library/Caches/lever-cosim/<version>`` on macOS) - never the checkout or the output
folder, so a run with ``--out`` elsewhere leaves the project as it was.  ``lever cache``
says where it is and its size; ``lever cache --clear`` empties it, ``--clear-stale`` removes
the entries of other code.

What an entry is keyed on, besides its own inputs: ``code_digest()``, the digest of every
source file of the packages that compute it (``harness``, ``lever``), of the scenes and data
files the project ships, and the versions of the package, of Python and of the libraries that
compute (``versions``) - a change to any of them (a fixed solver, an edited plan, an upgrade)
misses the cache rather than answer from a stale entry.  The entries of one code are in a
folder of their own (``entries``): what another code left is *stale*, never read again.
"""
from __future__ import annotations

import functools
import hashlib
import os
import shutil
from pathlib import Path

from harness import paths

#: the environment variable that chooses the cache's folder
ENVIRONMENT = "LEVER_CACHE_DIR"
#: the cache's parts: folder -> what it holds
PARTS = {"references": "monolithic references and references made from a scene's FMUs",
         "do-nothing-twins": "the benchmark's do-nothing twins of the FMUs",
         "unit-factors": "the factors of the units values were given in, as pint works them out"}


def folder() -> Path:
    """The cache's folder (read anew at each call: a process that changes ``LEVER_CACHE_DIR``
    is answered from the new one)."""
    chosen = os.environ.get(ENVIRONMENT)
    return Path(chosen).expanduser().resolve() if chosen else paths.user_cache()


def part(name: str) -> Path:
    """The folder of one of the cache's ``PARTS`` (not made here: a writer makes it)."""
    if name not in PARTS:
        raise ValueError(f"cache part '{name}': one of {', '.join(PARTS)}")
    return folder() / name


def roots() -> list[tuple[Path, str]]:
    """The folders ``code_digest`` reads, each with the files it takes of it (a pattern):
    the ``harness`` and ``lever`` packages' ``.py`` files, every file of the scenes' and
    data folders."""
    import lever

    return [(paths.CODE / "harness", "*.py"), (Path(lever.__file__).resolve().parent, "*.py"),
            (paths.SCENES, "*"), (paths.DATA, "*")]


def source_files(folders=None) -> dict[str, Path]:
    """What ``code_digest`` reads: ``name -> path`` of every file of ``folders`` (default
    ``roots()``), each named by its path below its folder's parent (``harness/judges/x.py``),
    so that a copy of the same files elsewhere has the same digest."""
    files = {}
    for root, pattern in folders or roots():
        for path in root.rglob(pattern):
            inside = path.relative_to(root).parts
            if path.is_file() and "__pycache__" not in inside and "_project" not in inside:
                files["/".join((root.name, *inside))] = path
    return dict(sorted(files.items()))


def digest_of(files: dict[str, Path], version: str) -> str:
    """The digest of ``files`` (``name -> path``: their names and bytes) and ``version``."""
    digest = hashlib.sha256(version.encode())
    for name, path in files.items():
        content = path.read_bytes()
        digest.update(f"\0{name}\0{len(content)}\0".encode())
        digest.update(content)
    return digest.hexdigest()[:16]


#: the libraries whose numbers a cached entry holds (the reference's integrators, the FMUs'
#: runtime): a cache made under other versions of them is another's
COMPUTING = ("numpy", "scipy", "scikit-sundae", "fmpy", "pythonfmu")


def versions() -> str:
    """The package's version, Python's and those of the ``COMPUTING`` libraries."""
    import platform
    from importlib.metadata import PackageNotFoundError, version

    def of(name):
        try:
            return version(name)
        except PackageNotFoundError:
            return "-"
    return " ".join([f"lever-cosim {paths.version()}", f"python {platform.python_version()}",
                     *(f"{name} {of(name)}" for name in COMPUTING)])


@functools.cache
def code_digest() -> str:
    """The digest every cached entry is keyed on (the module's docstring says of what);
    computed once a process (some 1.5 MB read: a few milliseconds)."""
    return digest_of(source_files(), versions())


def entries(name: str) -> Path:
    """Where the entries of the cache's part ``name`` computed by this code are kept: a
    folder named by ``code_digest()`` in the part's."""
    return part(name) / code_digest()


def size() -> dict:
    """What the cache holds: ``folder``, and for each part its ``files`` and ``bytes`` and
    how many of them are stale (``stale_files``, ``stale_bytes``: left by other code);
    ``total`` each summed."""
    parts = {}
    for name in PARTS:
        figures = dict.fromkeys(("files", "bytes", "stale_files", "stale_bytes"), 0)
        for path in part(name).rglob("*") if part(name).is_dir() else ():
            if not path.is_file():
                continue
            held = path.stat().st_size
            figures["files"] += 1
            figures["bytes"] += held
            if path.relative_to(part(name)).parts[0] != code_digest():
                figures["stale_files"] += 1
                figures["stale_bytes"] += held
        parts[name] = figures
    return {"folder": folder(), "parts": parts,
            "total": {k: sum(p[k] for p in parts.values()) for k in next(iter(parts.values()))}}


def clear(stale_only: bool = False) -> dict:
    """Remove every entry of the cache (made again when needed), or (``stale_only``) those
    other code left; returns what it held (``size()``).  Other files in the folder (a pip
    installation's FMUs) stay."""
    held = size()
    for name in PARTS:
        if not stale_only:
            shutil.rmtree(part(name), ignore_errors=True)
        elif part(name).is_dir():
            for other in part(name).iterdir():
                if other.name == code_digest():
                    continue
                if other.is_dir():
                    shutil.rmtree(other, ignore_errors=True)
                else:
                    other.unlink(missing_ok=True)
    return held
