"""Did-you-mean hints for the names a user types: environment ids and keyword arguments.

Gymnasium suggests near ids only inside one namespace, so ``gym.make("StereoVO-v0")`` (the
``vo_gym/`` prefix left out) would say only that ``StereoVO`` does not exist; the registration
therefore also registers each bare name to :func:`missing_namespace`, which names the full id.
A mistyped keyword of ``gym.make`` reaches the environment's constructor, whose error then
carries :func:`keyword_hint`.
"""

from __future__ import annotations

import difflib
import inspect
from typing import Any, Iterable

NAMESPACE = "vo_gym"


def did_you_mean(name: str, candidates: Iterable[str]) -> str:
    """``" (did you mean 'x'?)"`` for the closest candidate (difflib ratio >= 0.6), else ``""``."""
    close = difflib.get_close_matches(name, sorted(set(candidates)), n=1, cutoff=0.6)
    return f" (did you mean {close[0]!r}?)" if close else ""


def constructor_keywords(cls: type) -> list[str]:
    """The named keyword parameters of ``cls.__init__`` (not ``self``, not ``*args`` / ``**kwargs``)."""
    return [p.name for p in inspect.signature(cls.__init__).parameters.values()
            if p.name != "self" and p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)]


def keyword_hint(given: Iterable[str], cls: type, options: Iterable[str]) -> str:
    """Did-you-mean text for each keyword of ``given`` that is neither a parameter of ``cls`` nor one
    of ``options`` (the estimator options it forwards); ``""`` when none is close to a known name."""
    known = set(constructor_keywords(cls)) | set(options)
    hints = []
    for name in given:
        if name not in known and (hint := did_you_mean(name, known)):
            hints.append(f"{name!r}{hint}")
    return f"; {', '.join(hints)}" if hints else ""


def missing_namespace(full_id: str, **_: Any):
    """The entry point of a bare name (``StereoVO-v0``): refuses it, naming the namespaced id."""
    import gymnasium

    bare = full_id.partition("/")[2]
    raise gymnasium.error.NamespaceNotFound(
        f"{bare!r} has no namespace; did you mean {full_id!r}? (gym.make({full_id!r}) after import vo_gym,"
        f" or gym.make('{NAMESPACE}:{full_id}') without it)"
    )
