"""Whether numba's on-disk cache holds the compiled kernels, and one line when they compile.

Every kernel of the package compiles with ``cache=True``: the first call in the first process
after installing (or after a source file changed) compiles it, about half a minute for all of
them on one core, and later processes load the machine code from disk in about a second. So
that the first ``reset()`` or estimate does not sit silent for that half minute, importing
``stereovo`` calls :func:`announce_compiling` once, which prints one line to stderr when one of
the package's kernels starts compiling: it listens to numba's ``"numba:compile"`` event, which numba raises only for
a kernel it did not find in its cache (a load from the cache raises none). So the line comes
exactly when a compilation starts, for the kernels the caller really uses, at most once per
process, and never on a run whose kernels all load from the cache, even when kernels of
methods it does not run were never compiled.

Before workers are started (the trials runner), the parent asks instead whether the package's
kernels are cached, without calling them (:func:`uncached_kernels`), prints the line if not and
silences the workers (:data:`QUIET_ENV`). A kernel counts as cached when numba's index file for it
(``<module>.<qualname>-<line>.pyXY.nbi`` in the dispatcher's ``stats.cache_path``, beside the
source or in numba's user-wide cache folder) exists and numba would load it: not older than its
source file (the quick test, without reading the index), or else accepted by numba's own reader
of it (the stamp stored there is the source's, which has not changed since the kernel was
defined; this module never unpickles the index itself). Recent numba (0.68 here;
numba/numba#10659) stamps a hash of the source's bytes, earlier ones its time and size, so with
the former a file that was only touched (a checkout, a merge) keeps its cache, and numba never
rewrites that index: a test of the times alone would announce a compilation on every run.
Kernels inlined into others (``inline="always"``) and helpers that only compiled code calls never
get an index of their own, so a source file counts as compiled when any of its kernels has one:
the first run compiles every file's kernels, a later edit recompiles that file's.
"""

from __future__ import annotations

import importlib
import os
import sys
from pathlib import Path
from typing import Iterable, TextIO

from numba.core import event
from numba.core.dispatcher import Dispatcher

# The modules whose kernels an estimate or an environment step compiles; their submodules too.
KERNEL_MODULES = ("stereovo", "vo_gym.features")

MESSAGE = ("vo-gym: compiling the numba kernels on this first run (about 30 s on one core); "
           "they are cached on disk, later runs start in about a second")

KERNEL_PACKAGES = ("stereovo", "vo_gym")
"""The top-level packages whose kernels' compilation the line announces."""

_announced = False  # once per process: a second line would only repeat the first
_listener: "CompileNotice | None" = None

QUIET_ENV = "VO_GYM_COMPILE_NOTICE_SHOWN"
"""Set (to any value) in a worker's environment when the process that started it printed the notice."""


def cache_index_path(kernel: Dispatcher) -> Path | None:
    """Where numba keeps ``kernel``'s cache index; None when the kernel is not cached (``cache=False``)."""
    folder = kernel.stats.cache_path
    if folder is None:
        return None
    func = kernel.py_func
    source = Path(func.__code__.co_filename)
    qualname = func.__qualname__.replace("<", "").replace(">", "")
    flags = getattr(sys, "abiflags", "")
    name = f"{source.stem}.{qualname}-{func.__code__.co_firstlineno}.py{sys.version_info[0]}{sys.version_info[1]}{flags}.nbi"
    return Path(folder) / name


def is_cached(kernel: Dispatcher) -> bool:
    """True when ``kernel`` will load from numba's cache instead of compiling (see the module docstring)."""
    index = cache_index_path(kernel)
    if index is None:
        return False
    try:
        if index.stat().st_mtime >= os.stat(kernel.py_func.__code__.co_filename).st_mtime:
            return True
    except OSError:
        return False
    return _index_is_fresh(kernel)


def _index_is_fresh(kernel: Dispatcher) -> bool:
    """Whether numba would load ``kernel`` from its index: numba's own reader of the index (which
    compares the stamp stored there with the source's stamp taken when the kernel was defined) finds
    a compiled signature, and the source has not changed since it was defined. This module never
    unpickles the index itself. numba has no public call for this, so a numba without these
    attributes counts the kernel as uncached (the line is then printed)."""
    try:
        cache_file = kernel._cache._cache_file
        if cache_file._source_stamp != kernel._cache._impl.locator.get_source_stamp():
            return False  # edited since it was imported: numba would compile it
        return bool(cache_file._load_index())
    except Exception:  # noqa: BLE001 - any failure of numba's private parts means "not known to be cached"
        return False


def package_kernels(prefixes: Iterable[str] = KERNEL_MODULES) -> list[Dispatcher]:
    """The cached numba kernels defined in the already imported modules under ``prefixes``."""
    prefixes = tuple(prefixes)
    kernels: dict[int, Dispatcher] = {}
    for name, module in list(sys.modules.items()):
        if module is None or not any(name == p or name.startswith(p + ".") for p in prefixes):
            continue
        for value in vars(module).values():
            if isinstance(value, Dispatcher) and value.stats.cache_path is not None:
                kernels[id(value)] = value
    return list(kernels.values())


def uncached_kernels(kernels: Iterable[Dispatcher] | None = None) -> list[str]:
    """Qualified names of the kernels in source files none of whose kernels is cached yet."""
    if kernels is None:
        for name in ("stereovo.estimation", "stereovo.simulation"):
            importlib.import_module(name)
        kernels = package_kernels()
    by_file: dict[str, list[Dispatcher]] = {}
    for k in kernels:
        if k.targetoptions.get("inline", "never") == "never":
            by_file.setdefault(k.py_func.__code__.co_filename, []).append(k)
    return sorted(f"{k.py_func.__module__}.{k.py_func.__qualname__}"
                  for group in by_file.values() if not any(is_cached(k) for k in group) for k in group)


def say_compiling(stream: TextIO | None = None) -> bool:
    """Print :data:`MESSAGE` unless this process printed it already or its parent did (:data:`QUIET_ENV`);
    returns whether it printed."""
    global _announced
    if _announced or os.environ.get(QUIET_ENV):
        return False
    _announced = True
    print(MESSAGE, file=stream if stream is not None else sys.stderr, flush=True)
    return True


def announce_compiling(kernels: Iterable[Dispatcher] | None = None, stream: TextIO | None = None) -> bool:
    """Say :data:`MESSAGE` (:func:`say_compiling`) when the package's kernels compile.

    Without ``kernels``: from now on, print it when numba starts compiling one of the package's
    kernels (:class:`CompileNotice`, installed once); returns False, nothing is printed now. With
    ``kernels``: print it now if any of them is not cached (:func:`uncached_kernels`), for a caller
    about to run them elsewhere; returns whether it printed.
    """
    global _listener
    if kernels is None:
        if _listener is None:
            _listener = CompileNotice()
            event.register("numba:compile", _listener)
        if stream is not None:  # the import's call passes none: a caller's stream stays
            _listener.stream = stream
        return False
    if _announced or os.environ.get(QUIET_ENV) or not uncached_kernels(kernels):
        return False
    return say_compiling(stream)


class CompileNotice(event.Listener):
    """Says :data:`MESSAGE` (:func:`say_compiling`) when numba starts compiling a kernel of
    :data:`KERNEL_PACKAGES`: numba raises ``"numba:compile"`` only on a cache miss."""

    def __init__(self) -> None:
        self.stream: TextIO | None = None

    def on_start(self, ev: event.Event) -> None:
        if _announced:
            return
        data = ev.data if isinstance(ev.data, dict) else {}
        module = getattr(getattr(data.get("dispatcher"), "py_func", None), "__module__", None) or ""
        if module.split(".")[0] in KERNEL_PACKAGES:
            say_compiling(self.stream)

    def on_end(self, ev: event.Event) -> None:
        pass


def reset_announcement() -> None:
    """Let :func:`announce_compiling` speak again, to stderr (for tests)."""
    global _announced
    _announced = False
    os.environ.pop(QUIET_ENV, None)
    if _listener is not None:
        _listener.stream = None
