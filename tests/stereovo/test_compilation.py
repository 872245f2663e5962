"""The one line that says the numba kernels are compiling: spoken when a kernel is not cached, once."""

from __future__ import annotations

import importlib.util
import io
import os
import sys
import time

import pytest

from stereovo import compilation
from tests.support.processes import run_python


@pytest.fixture
def fresh_kernel(tmp_path, monkeypatch):
    """A cached numba kernel in a new module of its own, never compiled before."""
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    source = tmp_path / "vo_gym_compilation_probe.py"
    source.write_text(
        "from numba import njit\n\n"
        "@njit(cache=True)\n"
        "def twice(x):\n"
        "    return 2.0 * x\n\n"
        "@njit(cache=True)\n"
        "def helper(x):\n"
        "    return x + 1.0\n\n"
        "@njit(cache=True)\n"
        "def outer(x):\n"
        "    return helper(x) * 3.0\n\n"
        "@njit(cache=True, inline='always')\n"
        "def inlined(x):\n"
        "    return x - 1.0\n"
    )
    spec = importlib.util.spec_from_file_location("vo_gym_compilation_probe", source)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    yield module
    sys.modules.pop(spec.name, None)
    compilation.reset_announcement()


def test_a_kernel_is_cached_only_after_its_first_call(fresh_kernel):
    kernel = fresh_kernel.twice
    index = compilation.cache_index_path(kernel)
    assert index is not None and index.name.startswith("vo_gym_compilation_probe.twice-3.py")  # numba names it by the decorator's line
    assert not compilation.is_cached(kernel)
    assert compilation.uncached_kernels([kernel]) == ["vo_gym_compilation_probe.twice"]
    assert kernel(1.5) == 3.0
    assert index.exists() and compilation.is_cached(kernel)
    assert compilation.uncached_kernels([kernel]) == []


def test_a_file_counts_as_compiled_once_any_of_its_kernels_is(fresh_kernel):
    helper, outer, inlined = fresh_kernel.helper, fresh_kernel.outer, fresh_kernel.inlined
    assert compilation.uncached_kernels([helper, outer, inlined]) == [
        "vo_gym_compilation_probe.helper", "vo_gym_compilation_probe.outer"]  # inlined kernels never count
    assert outer(1.0) == 6.0
    assert compilation.is_cached(outer)
    assert compilation.uncached_kernels([helper, outer, inlined]) == []


def test_an_edited_source_counts_as_uncached_and_a_touched_one_as_cached(fresh_kernel):
    kernel = fresh_kernel.twice
    kernel(1.0)
    assert compilation.is_cached(kernel)
    source = kernel.py_func.__code__.co_filename
    later = time.time() + 10
    os.utime(source, (later, later))  # a checkout or a merge: newer, the same bytes
    # recent numba stamps a hash of the bytes and loads it; an older one stamped the time, and recompiles
    hashes_bytes = isinstance(kernel._cache._impl.locator.get_source_stamp(), bytes)
    assert compilation.is_cached(kernel) == hashes_bytes
    with open(source, "a") as fh:
        fh.write("# an edit\n")
    os.utime(source, (later + 10, later + 10))
    assert not compilation.is_cached(kernel)  # numba recompiles it


def test_a_touched_source_keeps_quiet_in_a_new_process(fresh_kernel, tmp_path):
    # What a user saw after a checkout: numba loaded every kernel, yet each run announced a compilation.
    kernel = fresh_kernel.twice
    kernel(1.0)
    source = kernel.py_func.__code__.co_filename
    later = time.time() + 10
    os.utime(source, (later, later))
    probe = (
        "import importlib.util, sys\n"
        "from stereovo import compilation\n"
        f"spec = importlib.util.spec_from_file_location('vo_gym_compilation_probe', {source!r})\n"
        "m = sys.modules[spec.name] = importlib.util.module_from_spec(spec); spec.loader.exec_module(m)\n"
        "uncached = compilation.uncached_kernels([m.twice])\n"
        "print(uncached, m.twice(2.0), sum(m.twice.stats.cache_hits.values()))\n"
    )
    uncached, value, hits = run_python(probe).strip().rsplit(" ", 2)
    assert value == "4.0" and hits in ("0", "1")
    assert (uncached == "[]") == (hits == "1")  # the notice says what numba then does


def test_the_line_is_printed_once_and_only_when_compiling(fresh_kernel):
    kernel = fresh_kernel.twice
    compilation.reset_announcement()
    out = io.StringIO()
    assert compilation.announce_compiling([kernel], stream=out)
    assert out.getvalue() == compilation.MESSAGE + "\n"
    assert not compilation.announce_compiling([kernel], stream=out)  # once per process
    assert out.getvalue().count("\n") == 1

    kernel(2.0)
    compilation.reset_announcement()
    quiet = io.StringIO()
    assert not compilation.announce_compiling([kernel], stream=quiet)
    assert quiet.getvalue() == ""


PACKAGE_PROBE = (
    "import importlib.util, io, sys\n"
    "import stereovo  # nothing else: importing the package installs the notice for every entry point\n"
    "spec = importlib.util.spec_from_file_location('vo_gym.compilation_probe', {source!r})\n"
    "m = sys.modules[spec.name] = importlib.util.module_from_spec(spec); spec.loader.exec_module(m)\n"
    "sys.stderr = err = io.StringIO()\n"
    "m.twice(2.0)\n"
    "m.twice(3.0)\n"
    "sys.stderr = sys.__stderr__\n"
    "print(repr(err.getvalue()), sum(m.twice.stats.cache_hits.values()))\n"
)


def test_the_line_comes_when_a_package_kernel_compiles_and_never_from_the_cache(tmp_path, monkeypatch):
    # A user's run whose kernels all load from the cache used to hear "compiling" on every run,
    # because kernels of methods it never runs were never compiled.
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.delenv(compilation.QUIET_ENV, raising=False)
    source = tmp_path / "compilation_probe.py"
    source.write_text("from numba import njit\n\n@njit(cache=True)\ndef twice(x):\n    return 2.0 * x\n")
    first, hits = run_python(PACKAGE_PROBE.format(source=str(source))).strip().rsplit(" ", 1)
    assert first == repr(compilation.MESSAGE + "\n") and hits == "0"  # compiled: said once, not per call
    second, hits = run_python(PACKAGE_PROBE.format(source=str(source))).strip().rsplit(" ", 1)
    assert second == "''" and hits == "1"  # loaded from numba's cache: nothing said


def test_a_kernel_outside_the_packages_compiles_without_the_line(fresh_kernel):
    compilation.reset_announcement()  # and unsets the conftest's silence
    out = io.StringIO()
    assert not compilation.announce_compiling(stream=out)  # installs the listener, says nothing yet
    assert fresh_kernel.twice(1.0) == 2.0  # compiles: a module of its own, not stereovo's or vo_gym's
    assert out.getvalue() == ""


def test_the_packages_kernels_are_found():
    import stereovo.estimation  # noqa: F401  (imports the kernels)
    import stereovo.simulation  # noqa: F401
    import vo_gym.features  # noqa: F401

    names = {f"{k.py_func.__module__}.{k.py_func.__qualname__}" for k in compilation.package_kernels()}
    assert len(names) >= 20
    assert any(name.startswith("stereovo.estimation.kernels") for name in names)
    assert any(name.startswith("stereovo.simulation") for name in names)
    assert any(name.startswith("vo_gym.features") for name in names)
    assert all(name.startswith(("stereovo.", "vo_gym.")) for name in names)


def test_the_stream_a_caller_gives_stays_when_the_listener_is_installed_again(tmp_path, monkeypatch):
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    source = tmp_path / "compilation_probe_stream.py"
    source.write_text("from numba import njit\n\n@njit(cache=True)\ndef thrice(x):\n    return 3.0 * x\n")
    spec = importlib.util.spec_from_file_location("vo_gym.compilation_probe_stream", source)
    module = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, spec.name, module)
    spec.loader.exec_module(module)
    compilation.reset_announcement()
    out = io.StringIO()
    try:
        compilation.announce_compiling(stream=out)
        compilation.announce_compiling()  # what importing stereovo calls
        assert module.thrice(1.0) == 3.0  # a package kernel compiles: the line goes to the caller's stream
        assert out.getvalue() == compilation.MESSAGE + "\n"
    finally:
        compilation.reset_announcement()  # back to stderr
