"""A pytest plugin that scripts/mutation_test.py hands mutmut's runs: once tests are collected, load the
cached machine code of every numba kernel the imported modules hold, so mutmut's forked children inherit it."""
import sys


def pytest_collection_finish(session):
    try:
        from numba.core.registry import CPUDispatcher
    except ImportError:
        return
    for name, module in list(sys.modules.items()):
        if module is None or not name.startswith(("stereovo", "vo_gym", "agents")):
            continue
        for value in list(vars(module).values()):
            if not isinstance(value, CPUDispatcher) or value.overloads:
                continue
            try:  # numba's cache index: {(signature, codegen magic, hashes): file}; a stale one is empty
                magic = value.targetctx.codegen().magic_tuple()
                for key in value._cache._cache_file._load_index():
                    if key[1] == magic:
                        value.compile(key[0])
            except Exception:  # an uncached or uncacheable kernel compiles on first call, as without the plugin
                pass
