"""Where candidate samplers stand against issue 31's transfer target, from two transfer matrices.

The target (issue 31, item 3) for a sampler trained on a randomised mix of match errors:

- *transfer*: on every domain, at eps 0.8 with 16 hypotheses, success within 2 points of the best
  sampler trained on that domain. No sampler is trained on the hostile or rendered domains, so
  the best shipped learned row (either kind) of the reference matrix stands for it;
- *in-domain*: no worse than the shipped samplers on their own domain (``default``): here, at 16
  hypotheses and every epsilon of the matrix, within the same 2 points of the best shipped row;
- *in-frame* (in-frame candidates only): >= 99 % success at eps 0.9 under its own stop with a
  mean of <= 16 hypotheses, on every domain.

Inputs are ``transfer.csv`` files of :mod:`agents.transfer` (rates in [0, 1]; ``point`` is a
budget such as ``"16"`` or ``"own stop"``); every domain and in-domain epsilon of either must be in both
(a candidate matrix that leaves one out is refused, naming the missing cell). Run:
``python -m agents.transfer_target CANDIDATES.csv [--reference docs/data/transfer.csv] [--domains a,b]``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

__all__ = ["Check", "assess", "verdict_markdown", "main"]

TOLERANCE = 0.02  # success-rate points a candidate may trail the best shipped row by
TRANSFER_EPSILON = 0.8
BUDGET = "16"
IN_DOMAIN = "default"
IN_FRAME_EPSILON = 0.9
IN_FRAME_SUCCESS = 0.99
IN_FRAME_HYPOTHESES = 16.0
OWN_STOP = "own stop"


@dataclass(frozen=True)
class Check:
    """One requirement of the target for one candidate on one cell.

    ``value`` and ``bound`` are success rates in [0, 1] (``hypotheses`` the candidate's mean under
    its own stop for the in-frame check, else None); ``best`` names the reference row behind ``bound``.
    """

    sampler: str
    requirement: str
    domain: str
    epsilon: float
    value: float
    bound: float
    met: bool
    best: str = ""
    hypotheses: float | None = None


def _learned(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    return [r for r in rows if r["kind"] in ("one-shot", "in-frame")]


def _best(reference: Sequence[dict[str, Any]], domain: str, epsilon: float, point: str) -> dict[str, Any]:
    cell = [r for r in _learned(reference) if r["domain"] == domain and r["epsilon"] == epsilon and r["point"] == point]
    if not cell:
        raise ValueError(f"the reference matrix has no learned row at domain {domain!r}, eps {epsilon:g}, {point!r}")
    return max(cell, key=lambda r: r["success"])


def assess(candidates: Sequence[dict[str, Any]], reference: Sequence[dict[str, Any]],
           domains: Sequence[str] | None = None) -> list[Check]:
    """Every check of the target (module doc) for every learned sampler of ``candidates``, on every
    domain of either matrix, or on ``domains`` only (a partial verdict: see :func:`verdict_markdown`).

    Raises:
        ValueError: ``candidates`` has no learned row, or a cell it needs is missing from either matrix.
    """
    rows = _learned(candidates)
    if not rows:
        raise ValueError("the candidate matrix holds no learned sampler's rows")
    index = {(r["sampler"], r["domain"], r["epsilon"], r["point"]): r for r in rows}

    def row(sampler: str, domain: str, epsilon: float, point: str) -> dict[str, Any]:
        try:
            return index[sampler, domain, epsilon, point]
        except KeyError:
            raise ValueError(f"the candidate matrix has no row for {sampler!r} at domain {domain!r}, "
                             f"eps {epsilon:g}, {point!r}") from None

    checks = []
    # The cells come from the reference: a candidate matrix that leaves a domain or an epsilon out is
    # missing a check, not spared it.
    learned = _learned(reference)
    every = {r["domain"] for r in learned} | {r["domain"] for r in rows}
    domains = sorted(every if domains is None else set(domains), key=lambda d: (d != IN_DOMAIN, d))
    in_domain = sorted({r["epsilon"] for r in learned + rows if r["domain"] == IN_DOMAIN})
    for sampler, kind in dict.fromkeys((r["sampler"], r["kind"]) for r in rows):
        for domain in domains:
            cells = [("transfer", TRANSFER_EPSILON)]
            if domain == IN_DOMAIN:
                cells += [("in-domain", e) for e in in_domain]
            for requirement, epsilon in cells:
                mine, best = row(sampler, domain, epsilon, BUDGET), _best(reference, domain, epsilon, BUDGET)
                bound = best["success"] - TOLERANCE
                checks.append(Check(sampler, requirement, domain, epsilon, mine["success"], bound,
                                    mine["success"] >= bound - 1e-9, best["sampler"]))
            if kind == "in-frame":
                mine = row(sampler, domain, IN_FRAME_EPSILON, OWN_STOP)
                met = mine["success"] >= IN_FRAME_SUCCESS and mine["mean_hypotheses"] <= IN_FRAME_HYPOTHESES
                checks.append(Check(sampler, "in-frame", domain, IN_FRAME_EPSILON, mine["success"], IN_FRAME_SUCCESS,
                                    met, hypotheses=mine["mean_hypotheses"]))
    return checks


def verdict_markdown(checks: Sequence[Check], unchecked: Sequence[str] = ()) -> str:
    """A table of every check and one verdict line per sampler (``met`` only if all its checks are);
    with ``unchecked`` domains, a met verdict says it holds on the checked domains only."""
    lines = ["| sampler | requirement | domain | eps | success % | needs % | met |", "|---|---|---|---|---|---|---|"]
    for c in checks:
        if c.requirement == "in-frame":
            needs = f">= {100 * c.bound:.1f} at <= {IN_FRAME_HYPOTHESES:g} hypotheses (own stop: {c.hypotheses:.1f})"
        else:
            needs = f">= {100 * c.bound:.1f} (best shipped {c.best} - {100 * TOLERANCE:g})"
        lines.append(f"| {c.sampler} | {c.requirement} | {c.domain} | {c.epsilon:g} | {100 * c.value:.1f} | {needs} | "
                     f"{'yes' if c.met else '**no**'} |")
    lines.append("")
    for sampler in dict.fromkeys(c.sampler for c in checks):
        missed = [c for c in checks if c.sampler == sampler and not c.met]
        verdict = "target met" if not missed else f"target not met ({len(missed)} check(s) missed)"
        if unchecked and not missed:
            verdict = f"target met on the domains checked ({', '.join(unchecked)} not checked)"
        lines.append(f"- `{sampler}`: {verdict}")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    """``python -m agents.transfer_target CANDIDATES.csv [--reference CSV] [--out MD] [--domains a,b]``: exit 0 if
    every candidate meets the target, 1 if not, 2 on bad input."""
    import argparse
    from pathlib import Path

    from agents.transfer import read_results

    parser = argparse.ArgumentParser(description="candidate samplers against issue 31's transfer target")
    parser.add_argument("candidates", help="transfer.csv of the candidates (python -m agents.transfer --samplers ...)")
    parser.add_argument("--reference", default="docs/data/transfer.csv", help="transfer.csv of the shipped samplers")
    parser.add_argument("--out", default=None, help="also write the table here (markdown)")
    parser.add_argument("--domains", default=None,
                        help="comma-separated domains to check (default: every domain of the reference); a verdict "
                             "on fewer says which it did not check")
    args = parser.parse_args(argv)
    domains = None if args.domains is None else [d for d in args.domains.split(",") if d]
    try:
        reference = read_results(args.reference)
        known = {r["domain"] for r in _learned(reference)}
        if domains is not None and (not domains or set(domains) - known):
            parser.error(f"--domains must name domains of the reference ({', '.join(sorted(known))}), "
                         f"got {args.domains!r}")
        checks = assess(read_results(args.candidates), reference, domains)
    except (OSError, ValueError, KeyError) as err:
        parser.error(f"{type(err).__name__}: {err}" if isinstance(err, KeyError) else str(err))
    text = verdict_markdown(checks, sorted(known - set(domains)) if domains is not None else ())
    print(text, end="")
    if args.out:
        Path(args.out).write_text(text)
    return 0 if all(c.met for c in checks) else 1


if __name__ == "__main__":
    raise SystemExit(main())
