"""A run folder whose results survive interrupts: an append-only journal of finished trials.

Layout of a run folder (``--out``):

- ``manifest.json``: what the run computes (grid, methods, seed, ...), written when the run
  starts. ``--resume`` refuses a folder whose manifest differs from the new run's.
- ``journal.csv``: one block of rows per finished trial, appended, flushed and ``fsync``-ed the
  moment the trial's result reaches the driver. Columns ``task`` (the trial key, an integer) and
  ``task_rows`` (how many rows the trial has) come first, then the trial's own columns. A block
  cut short by a crash (fewer than ``task_rows`` rows, or a torn last line) is dropped on resume,
  so only trials that were in flight are lost.
- the final files (``trials.csv``, summaries, plots), written once every trial is in, each
  through a temporary file and an atomic rename, so a reader never sees half a file.

Floats are written with ``repr`` (shortest round-trip form), so rows read back from the journal
are bit-identical to the rows computed: a resumed run's final files equal an uninterrupted run's.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import math
import os
import tempfile
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping, Sequence

__all__ = [
    "JOURNAL",
    "MANIFEST",
    "TrialJournal",
    "RunFolderError",
    "prepare_run_folder",
    "atomic_path",
    "atomic_write_text",
    "csv_value",
]

JOURNAL = "journal.csv"
MANIFEST = "manifest.json"
_KEY_COLUMNS = ("task", "task_rows")


class RunFolderError(ValueError):
    """A run folder that cannot be used as asked (not empty, other settings); the message says why."""


def csv_value(value: Any) -> str:
    """A cell's text: floats at full precision (``repr``), numpy scalars unwrapped, bools as True/False."""
    if hasattr(value, "item") and not isinstance(value, (str, bytes)):
        value = value.item()
    if isinstance(value, float):
        return repr(value)
    return str(value)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success it replaces ``path`` in one rename."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    try:
        yield Path(tmp)
        # mkstemp makes the file 0600; a result file gets the mode any new file gets under the umask
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def _umask() -> int:
    """The process's umask: from ``/proc/self/status`` where there is one (Linux), else by setting it
    and straight back (another thread creating a file in between would get the interim mask)."""
    try:
        with open("/proc/self/status") as status:
            for line in status:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def atomic_write_text(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` to ``path`` through a temporary file and an atomic rename."""
    with atomic_path(path) as tmp:
        with open(tmp, "w", newline="") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
    return Path(path)


def prepare_run_folder(out: str | os.PathLike, resume: bool, overwrite: bool, option: str = "--out") -> Path:
    """Refuse a non-empty folder unless resuming or overwriting; with ``overwrite`` forget its journal.

    Only the folder's own run files (journal, manifest) are removed by ``overwrite``; the final
    files are replaced when the new run ends.

    Raises:
        RunFolderError: ``out`` is not empty and neither ``resume`` nor ``overwrite`` is set,
            or both are set.
    """
    out = Path(out)
    if resume and overwrite:
        raise RunFolderError("--resume and --overwrite exclude each other")
    entries = [p for p in out.iterdir() if not p.name.startswith(".write-check-")] if out.is_dir() else []
    if entries and not (resume or overwrite):
        raise RunFolderError(
            f"{option} {str(out)!r} is not empty ({len(entries)} entries); pass --resume to complete the run"
            " there or --overwrite to replace it"
        )
    if overwrite:
        for name in (JOURNAL, MANIFEST):
            with contextlib.suppress(FileNotFoundError):
                (out / name).unlink()
    return out


def _comparable(manifest: Mapping[str, Any]) -> Any:
    # JSON round trip: tuples become lists, so a manifest compares equal to its stored copy.
    return json.loads(json.dumps(manifest, sort_keys=True, default=str))


def _describe_difference(old: Mapping[str, Any], new: Mapping[str, Any]) -> str:
    keys = sorted(k for k in set(old) | set(new) if old.get(k) != new.get(k))
    return ", ".join(keys) or "?"


class TrialJournal:
    """The append-only journal of one run folder (see the module doc).

    Args:
        folder: the run folder (must exist and be writable).
        columns: the trial rows' columns, in order.
        parse: ``parse(column, text) -> value``: restores a cell's type when reading back.
    """

    def __init__(self, folder: str | os.PathLike, columns: Sequence[str],
                 parse: Callable[[str, str], Any]) -> None:
        self.folder = Path(folder)
        self.columns = tuple(columns)
        clash = set(self.columns) & set(_KEY_COLUMNS)
        if clash:
            raise ValueError(f"trial columns must not use the journal's own names {sorted(clash)}")
        self.parse = parse
        self.path = self.folder / JOURNAL
        self._fh: io.TextIOWrapper | None = None

    # ------------------------------------------------------------------ opening

    def open(self, manifest: Mapping[str, Any], resume: bool) -> dict[int, list[dict[str, Any]]]:
        """Start the journal (or continue it with ``resume``); returns the finished trials' rows by key.

        Raises:
            RunFolderError: ``resume`` into a folder whose manifest differs from ``manifest``.
        """
        manifest_path = self.folder / MANIFEST
        done: dict[int, list[dict[str, Any]]] = {}
        if resume and manifest_path.is_file():
            stored = json.loads(manifest_path.read_text())
            if _comparable(stored) != _comparable(manifest):
                raise RunFolderError(
                    f"--resume: {str(self.folder)!r} holds a run with other settings"
                    f" ({_describe_difference(stored, _comparable(manifest))} differ); use another --out,"
                    " or --overwrite to replace it"
                )
            done = self.read()
        atomic_write_text(manifest_path, json.dumps(_comparable(manifest), indent=2) + "\n")
        # Rewrite the journal with the complete trials only, so torn blocks never mix with new ones.
        with atomic_path(self.path) as tmp:
            with open(tmp, "w", newline="") as fh:
                fh.write(self._encode_header())
                for key in sorted(done):
                    fh.write(self._encode(key, done[key]))
                fh.flush()
                os.fsync(fh.fileno())
        self._fh = open(self.path, "a", newline="")
        return done

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None

    def __enter__(self) -> "TrialJournal":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    # ------------------------------------------------------------------ writing

    def _encode_header(self) -> str:
        buf = io.StringIO()
        csv.writer(buf, lineterminator="\n").writerow([*_KEY_COLUMNS, *self.columns])
        return buf.getvalue()

    def _encode(self, key: int, rows: Sequence[Mapping[str, Any]]) -> str:
        buf = io.StringIO()
        writer = csv.writer(buf, lineterminator="\n")
        for row in rows:
            writer.writerow([int(key), len(rows), *(csv_value(row[c]) for c in self.columns)])
        return buf.getvalue()

    def append(self, key: int, rows: Sequence[Mapping[str, Any]]) -> None:
        """Append one finished trial's rows in a single write, then flush and ``fsync``."""
        if self._fh is None:
            raise RuntimeError("the journal is not open; call open() first")
        if not rows:
            raise ValueError(f"trial {key}: no rows to append (every trial has at least one row)")
        self._fh.write(self._encode(key, rows))
        self._fh.flush()
        os.fsync(self._fh.fileno())

    # ------------------------------------------------------------------ reading

    def read(self) -> dict[int, list[dict[str, Any]]]:
        """The complete trials of the journal on disk, by key (torn or partial blocks dropped)."""
        return read_journal(self.path, self.parse)


def read_journal(path: str | os.PathLike, parse: Callable[[str, str], Any]) -> dict[int, list[dict[str, Any]]]:
    """Complete trials of a journal file by key; a torn last line or a short block is dropped."""
    path = Path(path)
    if not path.is_file():
        return {}
    with path.open(newline="") as fh:
        text = fh.read()
    if not text.endswith("\n"):
        text = text[: text.rfind("\n") + 1]  # a line cut by a crash
    blocks: dict[int, list[dict[str, Any]]] = {}
    expected: dict[int, int] = {}
    for raw in csv.DictReader(io.StringIO(text, newline="")):
        if any(v is None for v in raw.values()) or None in raw:
            continue  # a malformed line
        try:
            key, n = int(raw.pop("task")), int(raw.pop("task_rows"))
        except (TypeError, ValueError):
            continue
        if key in expected and expected[key] != n:
            continue
        expected[key] = n
        blocks.setdefault(key, []).append({k: parse(k, v) for k, v in raw.items()})
    out: dict[int, list[dict[str, Any]]] = {}
    for key, rows in blocks.items():
        n = expected[key]
        if len(rows) >= n:
            out[key] = rows[:n] if len(rows) == n else rows[-n:]  # a trial re-run after a torn block
    return out


def parse_number(text: str) -> Any:
    """An integer if the text is one, else a float if it parses, else the text."""
    try:
        return int(text)
    except ValueError:
        pass
    try:
        value = float(text)
    except ValueError:
        return text
    return value if math.isfinite(value) or text.lower() in ("nan", "inf", "-inf") else text
