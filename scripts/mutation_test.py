#!/usr/bin/env python
"""Mutation testing of the core, the environment and the trainers' losses with mutmut 3.

    .venv/bin/python scripts/mutation_test.py                      # every module, in priority order
    .venv/bin/python scripts/mutation_test.py --only rewards prosac  # some of them
    .venv/bin/python scripts/mutation_test.py --report-only          # rewrite the report from the last run's results file

mutmut changes one thing in the code (an operator, a constant, a comparison, an argument) and runs
the tests that call the changed function; a mutant they let pass ("survived") is a change of
behaviour nobody would notice. Each module runs in its own copy of the repository (``--workdir``,
never the working tree, where mutmut would write its ``mutants/``) against a fast subset of the
suite, in order of importance, within ``--minutes``. The modules, their tests and the verdicts on
survivors (equivalent with the reason, left on purpose, targeted by a later test) are data:
``docs/mutation-verdicts.toml``, beside the report ``docs/mutation-testing.md`` written from it and
from the run's results (kill rate: killed and timed out over the checked, non-equivalent mutants).

Not mutated: the numba kernels (``stereovo/estimation/kernels/``, ``kernels_verification.py``) and
any decorated function (mutmut leaves ``@njit``, properties and ``lru_cache``d helpers alone).
Compiled kernels are reused: numba's caches beside the sources are carried into the copies (which
keep the sources' mtimes) and back, and a pytest plugin loads every cached kernel into mutmut's fork
server once tests are collected (about 0.9 s of 2 s per mutant on the samplers). A developer's
tool: a full run takes hours on two cores, far beyond CI's budget.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
import tomllib
from dataclasses import dataclass
from fnmatch import fnmatch
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SOURCE_PACKAGES = ("stereovo", "vo_gym", "agents")


@dataclass(frozen=True)
class Module:
    """One module to mutate, the tests that check it, and which of its functions count."""

    name: str
    path: str
    tests: tuple[str, ...]
    functions: tuple[str, ...] = ("*",)  # fnmatch patterns on mutmut's function keys (x_<name>, xǁClassǁmethod)

    @property
    def dotted(self) -> str:
        return self.path.removesuffix(".py").replace("/", ".")

    @property
    def patterns(self) -> list[str]:
        return [f"{self.dotted}.{f}__mutmut_*" for f in self.functions]


@dataclass(frozen=True)
class Verdicts:
    """The data file: modules in order of importance, the reasons given for survivors, the report's text."""

    modules: tuple[Module, ...]
    equivalent: dict[str, str]  # mutant name -> why it cannot change behaviour
    noted: dict[str, str]  # mutant name -> why it is left on purpose (counted as survived)
    addressed: dict[str, str]  # mutant name -> the test added after the recorded run that targets it
    preamble: str  # the report's opening, in Markdown
    planted: tuple[tuple[str, str], ...]  # (bug planted by hand, the tests that fail on it)


def load_verdicts(path: Path) -> Verdicts:
    """Read ``path`` (TOML); each verdict lists its mutants as ``"function key" = [mutant numbers]``."""
    data = tomllib.loads(path.read_text(encoding="utf-8"))

    def by_mutant(table: str, key: str) -> dict[str, str]:
        return {f"{function}__mutmut_{number}": entry[key] for entry in data.get(table, [])
                for function, numbers in entry["mutants"].items() for number in numbers}

    modules = tuple(Module(m["name"], m["path"], tuple(m["tests"]), tuple(m.get("functions", ("*",))))
                    for m in data["module"])
    planted = tuple((p["bug"], p["tests"]) for p in data.get("planted", []))
    return Verdicts(modules, by_mutant("equivalent", "reason"), by_mutant("noted", "reason"),
                    by_mutant("addressed", "test"), data["report"]["preamble"], planted)


# mutmut's exit codes (mutmut/stats.py): 1 and 3 killed, 0 survived, timeouts, None not checked.
STATUS = {1: "killed", 3: "killed", 0: "survived", 5: "no tests", 33: "no tests", 34: "skipped", 35: "suspicious",
          36: "timeout", -24: "timeout", 24: "timeout", 152: "timeout", 255: "timeout", -11: "segfault",
          -9: "segfault", None: "not checked"}


def copy_tree(destination: Path, commit: str | None) -> None:
    """The repository's files (tracked plus untracked-not-ignored, or ``commit``'s) into ``destination``."""
    if destination.exists():
        shutil.rmtree(destination)
    destination.mkdir(parents=True)
    if commit is not None:
        archive = subprocess.run(["git", "archive", commit], cwd=ROOT, check=True, capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", str(destination)], input=archive, check=True)
        return
    listed = subprocess.run(["git", "ls-files", "--cached", "--others", "--exclude-standard", "-z"], cwd=ROOT,
                            check=True, capture_output=True).stdout.decode().split("\0")
    for name in filter(None, listed):
        source = ROOT / name
        if source.is_file():
            target = destination / name
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(source, target)


_NUMBA_CACHE = ("*.nbi", "*.nbc")
_WARM_PLUGIN = "vo_gym_mutmut_numba_warm"  # tests/support/mutmut_numba_warm.py, copied under this name


def copy_numba_cache(source: Path, destination: Path, skip: str | None = None) -> int:
    """Copy numba's cache files of ``source``'s packages to the same places under ``destination``.

    A cache entry is checked against its source file's mtime and size, which the copies keep, so
    only entries of unchanged sources are used. ``skip``: a mutated module, whose entries belong to
    its mutated text. Returns the number of files copied.
    """
    copied = 0
    for package in SOURCE_PACKAGES:
        for pattern in _NUMBA_CACHE:
            for cached in (source / package).rglob(f"__pycache__/{pattern}"):
                relative = cached.relative_to(source)
                if skip is not None and relative.parent.parent == Path(skip).parent and \
                        cached.name.startswith(Path(skip).stem + "."):
                    continue
                target = destination / relative
                if target.parent.parent.is_dir():
                    target.parent.mkdir(exist_ok=True)
                    shutil.copy2(cached, target)
                    copied += 1
    return copied


def write_config(workdir: Path, modules: list[Module]) -> None:
    tests = sorted({t for m in modules for t in m.tests})
    config = {
        "source_paths": list(SOURCE_PACKAGES),
        "only_mutate": [m.path for m in modules],
        "pytest_add_cli_args_test_selection": tests,
        "pytest_add_cli_args": ["-p", "no:cacheprovider", "-W", "ignore", "-p", _WARM_PLUGIN],
        # Fork each mutant from a server that only imported and collected the tests, not from the
        # process that ran them for mutmut's statistics: there lru_caches (the stopping bound's) are
        # already filled with the unmutated answers, and a mutant under them would pass unseen.
        "process_isolation": "forkserver",
        "timeout_multiplier": 4.0,  # of the tests' CPU time, plus the constant: a hung mutant costs 40 s, not 100
        "timeout_constant": 5.0,
    }
    lines = ["[tool.mutmut]"] + [f"{k} = {json.dumps(v, ensure_ascii=False)}" for k, v in config.items()]
    (workdir / "pyproject.toml").write_text("\n".join(lines) + "\n", encoding="utf-8")
    (workdir / "setup.cfg").unlink(missing_ok=True)
    plugins = workdir / "_mutmut_plugins"
    plugins.mkdir(exist_ok=True)
    shutil.copy2(ROOT / "tests" / "support" / "mutmut_numba_warm.py", plugins / f"{_WARM_PLUGIN}.py")


def mutmut_environment(workdir: Path | None = None) -> dict[str, str]:
    env = dict(os.environ)
    # One thread per process: the machines this runs on have two shared cores. CI=1 selects the
    # deterministic hypothesis profile of tests/conftest.py, so a mutant's verdict does not vary.
    env.update(OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", NUMBA_NUM_THREADS="1", CI="1")
    env.pop("PYTHONPATH", None)
    env.pop("NUMBA_CACHE_DIR", None)  # the caches beside the sources are the ones carried between copies
    if workdir is not None:
        env["PYTHONPATH"] = str(workdir / "_mutmut_plugins")
    return env


def run_module(workdir: Path, module: Module, minutes: float, max_children: int,
               names: list[str] | None = None) -> str:
    """Run mutmut on one module's mutants (or only ``names``); returns ``"done ..."`` or ``"stopped after N min"``."""
    mutmut = Path(sys.executable).with_name("mutmut")
    command = [str(mutmut), "run", "--max-children", str(max_children), *(names or module.patterns)]
    log = (workdir / f"mutmut-{module.name}.log").open("w")
    start = time.monotonic()
    process = subprocess.Popen(command, cwd=workdir, env=mutmut_environment(workdir), stdout=log, stderr=subprocess.STDOUT,
                               start_new_session=True)
    try:
        process.wait(timeout=minutes * 60)
        return f"done in {(time.monotonic() - start) / 60:.1f} min (mutmut exit {process.returncode})"
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, 15)
        process.wait()
        return f"stopped after {minutes:g} min"


def read_results(workdir: Path, module: Module) -> dict[str, str]:
    """Status of each of the module's mutants (only the counted functions) from mutmut's meta file."""
    meta = workdir / "mutants" / (module.path + ".meta")
    if not meta.is_file():
        return {}
    codes = json.loads(meta.read_text(encoding="utf-8"))["exit_code_by_key"]
    return {name: STATUS.get(code, "suspicious") for name, code in codes.items()
            if any(fnmatch(name, p) for p in module.patterns)}


def mutant_diff(workdir: Path, name: str) -> str:
    mutmut = Path(sys.executable).with_name("mutmut")
    shown = subprocess.run([str(mutmut), "show", name], cwd=workdir, env=mutmut_environment(), capture_output=True,
                           text=True).stdout
    changed = [line for line in shown.splitlines()
               if line[:1] in "+-" and not line.startswith(("+++", "---"))]
    return "\n".join(changed)


def record(store: Path, workdir: Path, module: Module, note: str) -> None:
    """Merge one module's verdicts (and the diffs of its survivors) into the results file."""
    results = json.loads(store.read_text()) if store.is_file() else {}
    statuses = read_results(workdir, module)
    diffs = {name: mutant_diff(workdir, name) for name, status in statuses.items()
             if status not in ("killed", "timeout", "not checked")}
    results[module.name] = {"note": note, "status": statuses, "diff": diffs}
    store.write_text(json.dumps(results, indent=1, ensure_ascii=False), encoding="utf-8")


def carry_from_report(report: Path, store: Path, modules: tuple[Module, ...]) -> list[str]:
    """Seed a missing results file from the report it wrote: each module's row and its survivors.

    The results file lives outside the tree and can be lost (a reboot clears /tmp); the report keeps
    every survivor's name and diff but only counts of the other verdicts, so those are carried as
    counts. A module rerun later replaces its carried entry. Returns the modules carried.
    """
    if store.is_file() or not report.is_file():
        return []
    by_path = {m.path: m for m in modules}
    columns = ("killed", "timeout", "survived", "equivalent", "no tests", "not checked")
    results: dict[str, dict] = {}
    lines = report.read_text(encoding="utf-8").splitlines()
    for line in lines:
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        module = by_path.get(cells[0].strip("`")) if len(cells) == 11 else None
        if module is None or not cells[2].isdigit() or cells[10] == "not run":
            continue
        counts = dict(zip(columns, map(int, cells[3:9])))
        # Survivors (and equivalents) are listed by name below; only the other verdicts stay counts.
        counts["survived"] = counts["equivalent"] = 0
        carried = "; carried from an earlier report"
        note = cells[10].replace(carried, "") + carried  # said once, however often it was carried
        results[module.name] = {"note": note, "status": {}, "diff": {},
                                "counts": {k: v for k, v in counts.items() if v}}
    prefixes = {m.name: f"{m.dotted}." for m in modules}
    i = 0
    while i < len(lines):
        line = lines[i]
        i += 1
        if not line.startswith("- `") or "` (" not in line:
            continue
        name, status = line[3:].split("` (", 1)
        status = status.split(")", 1)[0]
        module = next((m for m, prefix in prefixes.items() if name.startswith(prefix) and m in results), None)
        if module is None:
            continue
        diff = []
        while i < len(lines) and not lines[i].startswith("- `"):
            if lines[i].startswith("  ") and lines[i].strip()[:1] in "+-":
                diff.append(lines[i][2:])
            i += 1
        results[module]["status"][name] = "survived" if status == "equivalent" else status
        results[module]["diff"][name] = "\n".join(diff)
    store.write_text(json.dumps(results, indent=1, ensure_ascii=False), encoding="utf-8")
    return sorted(results)


def selection_cell(tests: tuple[str, ...]) -> list[str]:
    """A module's selected tests for the report: each test named, or a file and its count past three."""
    by_file: dict[str, list[str]] = {}
    for test in tests:
        by_file.setdefault(test.split("::")[0].removeprefix("tests/"), []).append(test.removeprefix("tests/"))
    return [f"{file} ({len(picked)} of its tests)" if len(picked) > 3 else ", ".join(picked)
            for file, picked in by_file.items()]


def write_report(path: Path, store: Path, verdicts: Verdicts) -> dict[str, dict]:
    """The report over every module of the data file from the results file (modules never run: "not run")."""
    stored = json.loads(store.read_text()) if store.is_file() else {}
    modules = list(verdicts.modules)
    notes = {name: entry["note"] for name, entry in stored.items()}
    summary, survivors = {}, []
    for module in modules:
        results = stored.get(module.name, {}).get("status", {})
        counts = {s: 0 for s in ("killed", "timeout", "survived", "equivalent", "no tests", "not checked", "other")}
        # Verdicts carried over from an earlier report (see carry_from_report) come as counts, not names.
        for status, count in stored.get(module.name, {}).get("counts", {}).items():
            counts[status if status in counts else "other"] += count
        for name, status in sorted(results.items()):
            if status == "survived" and name in verdicts.equivalent:
                status = "equivalent"
            counts[status if status in counts else "other"] += 1
            if status in ("survived", "equivalent", "suspicious"):
                survivors.append((module, name, status, stored[module.name]["diff"].get(name, "")))
        decided = counts["killed"] + counts["timeout"] + counts["survived"]
        counts["kill rate"] = (counts["killed"] + counts["timeout"]) / decided if decided else None
        counts["total"] = len(results) + sum(stored.get(module.name, {}).get("counts", {}).values())
        summary[module.name] = counts
    lines = [verdicts.preamble.rstrip("\n"), "", "| planted bug | failing tests |", "|---|---|",
             *(f"| {bug} | {tests} |" for bug, tests in verdicts.planted), "",
        "## Kill rate by module",
        "",
        "| module | tests | mutants | killed | timeout | survived | equivalent | no tests | not checked | kill rate | run |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for module in modules:
        c = summary[module.name]
        rate = "-" if c["kill rate"] is None else f"{100 * c['kill rate']:.1f} %"
        tests = ", ".join(selection_cell(module.tests))
        lines.append(f"| `{module.path}` | {tests} | {c['total']} | {c['killed']} | {c['timeout']} | {c['survived']} "
                     f"| {c['equivalent']} | {c['no tests']} | {c['not checked']} | {rate} "
                     f"| {notes.get(module.name, 'not run')} |")
    totals = {k: sum(summary[m.name][k] for m in modules) for k in ("killed", "timeout", "survived", "equivalent",
                                                                   "not checked", "total")}
    decided = totals["killed"] + totals["timeout"] + totals["survived"]
    overall = f"{100 * (totals['killed'] + totals['timeout']) / decided:.1f} %" if decided else "-"
    lines += ["", f"Totals over the modules that ran: {totals['total']} mutants, {decided} decided and not equivalent, "
                  f"{totals['equivalent']} equivalent, {totals['not checked']} not checked; kill rate {overall}.", ""]
    lines += ["## Surviving mutants", ""]
    if not survivors:
        lines.append("None.")
    for module, name, status, diff in survivors:
        if name in verdicts.addressed:
            default = f"survived this run; a test added since targets it: {verdicts.addressed[name]}"
        elif name in verdicts.noted:
            default = verdicts.noted[name]
        else:
            default = "not yet addressed: needs a test" if status == "survived" else status
        reason = verdicts.equivalent.get(name, default)
        lines += [f"- `{name}` ({'equivalent' if status == 'equivalent' else status}): {reason}", "",
                  "  ```diff", *("  " + line for line in diff.splitlines()), "  ```", ""]
    path.write_text("\n".join(lines).rstrip() + "\n", encoding="utf-8")
    return summary


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--verdicts", type=Path, default=ROOT / "docs" / "mutation-verdicts.toml",
                        help="modules, their tests and the verdicts on survivors (default docs/mutation-verdicts.toml)")
    parser.add_argument("--only", nargs="+", metavar="MODULE", help="modules to run, by name in the data file (default all)")
    parser.add_argument("--workdir", type=Path, default=Path("/tmp/vo-gym-mutation"),
                        help="where the copies of the repository (base/, then one per module with mutmut's mutants/) go")
    parser.add_argument("--commit", help="mutate this commit's files instead of the working tree's")
    parser.add_argument("--minutes", type=float, default=60.0, help="time cap per module (default 60)")
    parser.add_argument("--max-children", type=int, default=1, help="mutants checked in parallel (default 1)")
    parser.add_argument("--report", type=Path, default=ROOT / "docs" / "mutation-testing.md")
    parser.add_argument("--results", type=Path, default=Path("/tmp/vo-gym-mutation-results.json"),
                        help="verdicts of every run so far, merged per module (the report is built from it)")
    parser.add_argument("--report-only", action="store_true", help="rewrite the report from the results file")
    parser.add_argument("--keep", action="store_true", help="reuse the workdir of the last run (resume it)")
    parser.add_argument("--mutants", nargs="+", metavar="NAME",
                        help="recheck only these mutants (names as in the report) in the copies of the last run, "
                             "with the working tree's current test files of their module copied in: confirms the tests written for them")
    args = parser.parse_args(argv)
    verdicts = load_verdicts(args.verdicts)
    unknown = sorted(set(args.only or ()) - {m.name for m in verdicts.modules})
    if unknown:
        parser.error(f"--only: unknown module(s) {', '.join(unknown)}; the data file lists "
                     f"{', '.join(m.name for m in verdicts.modules)}")
    if not args.report_only and shutil.which("mutmut", path=str(Path(sys.executable).parent)) is None:
        print("mutmut is not installed in this environment: pip install -e '.[dev]'", file=sys.stderr)
        return 2
    if args.report_only and not args.results.is_file():
        # The report alone keeps each module's counts but not its survivors' diffs: rewriting it from
        # itself would drop them (and the notes under its totals).
        print(f"--report-only needs the results file of a run, and {args.results} does not exist "
              "(--results names another); the report is left as it is", file=sys.stderr)
        return 2
    modules = [m for m in verdicts.modules if args.only is None or m.name in args.only]
    carried = carry_from_report(args.report, args.results, verdicts.modules)
    if carried:
        print(f"{args.results} was missing: verdicts of {', '.join(carried)} carried from {args.report}", flush=True)
    if args.mutants and not args.report_only:
        for module in modules:
            names = [n for n in args.mutants if n.startswith(module.dotted + ".")]
            workdir = args.workdir / module.name
            if not names:
                continue
            if not (workdir / "mutants").is_dir():
                print(f"{module.name}: no earlier run in {workdir} to recheck", file=sys.stderr)
                return 1
            # Only the module's own test files (and the packages' __init__ and support modules they
            # import): others may need sources newer than the copy's.
            helpers = [p.relative_to(ROOT).as_posix() for p in (*(ROOT / "tests").rglob("__init__.py"),
                                                                *(ROOT / "tests" / "support").glob("*.py"))]
            for test in sorted({t.split("::")[0] for t in module.tests} | set(helpers)):
                for target in (workdir, workdir / "mutants"):
                    (target / test).parent.mkdir(parents=True, exist_ok=True)
                    shutil.copy2(ROOT / test, target / test)
            write_config(workdir, [module])
            previous = json.loads(args.results.read_text()).get(module.name, {}).get("note", "") \
                if args.results.is_file() else ""
            note = run_module(workdir, module, args.minutes, args.max_children, names)
            # mutmut forgets the other mutants' verdicts when given names: merge only the rechecked ones.
            fresh = read_results(workdir, module)
            results = json.loads(args.results.read_text()) if args.results.is_file() else {}
            entry = results.setdefault(module.name, {"note": "", "status": {}, "diff": {}})
            rechecked = {n: fresh[n] for n in names if fresh.get(n, "not checked") != "not checked"}
            entry["status"].update(rechecked)
            killed = sum(v in ("killed", "timeout") for v in rechecked.values())
            entry["note"] = f"{previous}; {len(rechecked)} survivors rechecked with later tests, {killed} killed"
            args.results.write_text(json.dumps(results, indent=1, ensure_ascii=False), encoding="utf-8")
            print(f"{module.name}: {len(rechecked)} rechecked, {killed} killed ({note})", flush=True)
    elif not args.report_only:
        base = args.workdir / "base"
        if not (args.keep and base.is_dir()):
            copy_tree(base, args.commit)
            if args.commit is None:
                copy_numba_cache(ROOT, base)
            # A tree caught half-edited is no baseline: mutmut needs the selected tests green first.
            check = subprocess.run([sys.executable, "-c", "import stereovo, vo_gym, agents.ngransac"],
                                   cwd=base, env=mutmut_environment(), capture_output=True, text=True)
            if check.returncode != 0:
                print(f"the copied tree does not import:\n{check.stderr[-2000:]}", file=sys.stderr)
                return 1
        for module in modules:
            # One copy per module, with only its own tests: mutmut's statistics run (every selected
            # test once) then stays short, and the time cap is the module's alone.
            workdir = args.workdir / module.name
            if not (args.keep and workdir.is_dir()):
                if workdir.exists():
                    shutil.rmtree(workdir)
                shutil.copytree(base, workdir, symlinks=True)
            write_config(workdir, [module])
            note = run_module(workdir, module, args.minutes, args.max_children)
            copy_numba_cache(workdir / "mutants", base, skip=module.path)
            record(args.results, workdir, module, note)
            print(f"{module.name}: {note}", flush=True)
            write_report(args.report, args.results, verdicts)
    summary = write_report(args.report, args.results, verdicts)
    for name, c in summary.items():
        rate = "-" if c["kill rate"] is None else f"{100 * c['kill rate']:.1f} %"
        print(f"{name:16s} {c['total']:4d} mutants  killed {c['killed']:4d}  survived {c['survived']:3d}  "
              f"equivalent {c['equivalent']:3d}  not checked {c['not checked']:4d}  kill rate {rate}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
