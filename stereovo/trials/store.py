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

import codecs
import contextlib
import csv
import io
import json
import math
import os
import tempfile
from pathlib import Path
from typing import Any, Callable, Collection, Iterator, Mapping, Sequence

__all__ = [
    "JOURNAL",
    "MANIFEST",
    "TrialJournal",
    "RunFolderError",
    "JournalError",
    "read_journal",
    "read_manifest",
    "csv_records",
    "header_mismatch",
    "parsed_row",
    "prepare_run_folder",
    "atomic_path",
    "atomic_write_text",
    "csv_value",
]

JOURNAL = "journal.csv"
MANIFEST = "manifest.json"
_KEY_COLUMNS = ("task", "task_rows")
NEWLINE = b"\n"


class RunFolderError(ValueError):
    """A run folder that cannot be used as asked (not empty, other settings); the message says why."""


class JournalError(RunFolderError):
    """A journal (or manifest) file that is not one this run wrote; ``detail`` says what is wrong where."""

    def __init__(self, name: str, detail: str) -> None:
        super().__init__(f"{name} is not a {'manifest' if name == MANIFEST else 'journal'} of this run ({detail})")
        self.name, self.detail = name, detail


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
    shown = str(out)
    # Lexically, as a shell would: X/missing/../Y is X/Y (Path keeps the "..", and is_dir() through a
    # missing folder is False, so a full folder would pass as empty and then be written into).
    out = Path(os.path.normpath(out))
    if resume and overwrite:
        raise RunFolderError("--resume and --overwrite exclude each other")
    entries = [p for p in out.iterdir() if not p.name.startswith(".write-check-")] if out.is_dir() else []
    if entries and not (resume or overwrite):
        raise RunFolderError(
            f"{option} {shown!r} is not empty ({len(entries)} entries); pass --resume to complete the run"
            " there or --overwrite to replace it"
        )
    if overwrite:
        for name in (JOURNAL, MANIFEST):
            if (out / name).is_dir() and not (out / name).is_symlink():
                raise RunFolderError(f"{option} {shown!r}: {name} is a directory; remove it to start again")
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
        parse: ``parse(column, text) -> value``: restores a cell's type when reading back (raises
            ValueError on a text that is no value of its column).
        option: the flag that named the folder, for messages.
    """

    def __init__(self, folder: str | os.PathLike, columns: Sequence[str],
                 parse: Callable[[str, str], Any], option: str = "--out") -> None:
        self.folder = Path(folder)
        self.option = option
        self.columns = tuple(columns)
        clash = set(self.columns) & set(_KEY_COLUMNS)
        if clash:
            raise ValueError(f"trial columns must not use the journal's own names {sorted(clash)}")
        self.parse = parse
        self.path = self.folder / JOURNAL
        self._fh: io.TextIOWrapper | None = None

    # ------------------------------------------------------------------ opening

    def open(self, manifest: Mapping[str, Any], resume: bool,
             keys: Collection[int] | None = None) -> dict[int, list[dict[str, Any]]]:
        """Start the journal (or continue it with ``resume``); returns the finished trials' rows by key.

        ``keys``: the run's task keys; a stored trial with another key is refused (it was not written
        by this run, and re-running the task it stands for while calling it resumed would be wrong).

        Raises:
            RunFolderError: ``resume`` into a folder whose manifest differs from ``manifest``, or
                whose manifest or journal is not one a run wrote (naming the file and what is wrong).
        """
        manifest_path = self.folder / MANIFEST
        done: dict[int, list[dict[str, Any]]] = {}
        where = f"{self.option} {str(self.folder)!r}"
        for name in (MANIFEST, JOURNAL):
            if (self.folder / name).is_dir():
                raise RunFolderError(f"{where}: {name} is a directory, not a file of a run; remove it to start again")
        if resume and not manifest_path.is_file() and self.path.is_file() and self.path.stat().st_size > 0:
            # without its manifest a journal cannot be told to be this run's: refused, not discarded
            raise RunFolderError(f"{where}: {JOURNAL} has no {MANIFEST} beside it, so it cannot be resumed as this "
                                 "run's; pass --overwrite to start again")
        if resume and manifest_path.is_file():
            try:
                stored = read_manifest(manifest_path)
            except JournalError as err:
                raise RunFolderError(f"{where}: {err}; pass --overwrite to start again") from None
            if _comparable(stored) != _comparable(manifest):
                raise RunFolderError(
                    f"--resume: {str(self.folder)!r} holds a run with other settings"
                    f" ({_describe_difference(stored, _comparable(manifest))} differ); use another --out,"
                    " or --overwrite to replace it"
                )
            try:
                done = read_journal(self.path, self.parse, self.columns, keys)
            except JournalError as err:
                raise RunFolderError(f"{where}: {err}; pass --overwrite to start again") from None
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
        return read_journal(self.path, self.parse, self.columns)


def read_manifest(path: str | os.PathLike) -> dict[str, Any]:
    """A run's ``manifest.json``; raises :class:`JournalError` when it is no JSON object."""
    path = Path(path)
    try:
        data = json.loads(path.read_bytes().decode("utf-8"))
    except UnicodeDecodeError as err:
        raise JournalError(MANIFEST, f"not UTF-8 text at byte {err.start}") from None
    except json.JSONDecodeError as err:
        raise JournalError(MANIFEST, f"not JSON: {err.msg} at line {err.lineno} column {err.colno}") from None
    except RecursionError:
        raise JournalError(MANIFEST, "not JSON of a manifest: nested too deeply") from None
    except OSError as err:
        raise JournalError(MANIFEST, f"cannot be read: {err.strerror or err}") from None
    if not isinstance(data, dict):
        raise JournalError(MANIFEST, f"a JSON {type(data).__name__ if data is not None else 'null'}, not an object")
    return data


def _short(text: str, limit: int = 40) -> str:
    return repr(text if len(text) <= limit else text[:limit] + "...")


def csv_records(text: str) -> Iterator[tuple[int, list[str]]]:
    """``(line number, fields)`` of the CSV ``text``; ValueError ``"line N: ..."`` where it is no CSV."""
    reader = csv.reader(io.StringIO(text, newline=""))
    try:
        for fields in reader:
            yield reader.line_num, fields
    except csv.Error as err:
        raise ValueError(f"line {reader.line_num}: {err}") from None


def header_mismatch(header: Sequence[str], columns: Sequence[str], optional: Collection[str] = ()) -> str | None:
    """What keeps a CSV ``header`` from naming ``columns`` (any order; those in ``optional`` may be
    missing): missing or unknown columns, or one named twice; None when nothing does."""
    missing = [c for c in columns if c not in header and c not in optional]
    unknown = [c for c in header if c not in columns]
    if missing or unknown:
        return "; ".join(part for part in (f"missing column(s) {', '.join(missing)}" if missing else "",
                                           f"unknown column(s) {', '.join(map(_short, unknown[:3]))}"
                                           if unknown else "") if part)
    return "a column is named twice" if len(set(header)) != len(header) else None


def parsed_row(columns: Sequence[str], fields: Sequence[str], parse: Callable[[str, str], Any],
               line: int) -> dict[str, Any]:
    """One CSV record's cells by column, each through ``parse(column, text)``; ValueError
    ``"line N: COLUMN 'TEXT' is no value of that column"`` for a cell ``parse`` refuses."""
    if len(fields) != len(columns):
        raise ValueError(f"line {line}: {len(fields)} fields, the header has {len(columns)}")
    row = {}
    for column, value in zip(columns, fields):
        try:
            row[column] = parse(column, value)
        except (ValueError, TypeError, OverflowError):
            raise ValueError(f"line {line}: {column} {_short(value)} is no value of that column") from None
    return row


def read_journal(path: str | os.PathLike, parse: Callable[[str, str], Any], columns: Sequence[str] | None = None,
                 keys: Collection[int] | None = None) -> dict[int, list[dict[str, Any]]]:
    """Complete trials of a journal file by key; a torn last line or a short last block is dropped.

    Args:
        columns: the trial columns the header must name (in this order); None: any after the keys.
        keys: the task keys a trial may have; None: any integer.

    Raises:
        JournalError: anything else that is not a journal of this run: not UTF-8 text, a line that is
            no CSV row of the header's width, a header with other columns, a key or row count that is
            no integer in range, a cell ``parse`` refuses, a block cut short before the last one.
    """
    path = Path(path)
    if path.is_dir():
        raise JournalError(JOURNAL, "a directory, not a file")
    if not path.is_file():
        return {}
    try:
        data = path.read_bytes()
    except OSError as err:
        raise JournalError(JOURNAL, f"cannot be read: {err.strerror or err}") from None
    cut = data.rfind(b"\n") + 1
    body, torn = data[:cut], data[cut:]
    try:
        text = body.decode("utf-8")
    except UnicodeDecodeError as err:
        raise JournalError(JOURNAL, f"line {body[:err.start].count(NEWLINE) + 1}: not UTF-8 text") from None
    try:
        # a line cut by a crash: dropped, but it must be the start of UTF-8 text (a character may be cut)
        codecs.getincrementaldecoder("utf-8")().decode(torn, final=False)
    except UnicodeDecodeError:
        raise JournalError(JOURNAL, f"line {body.count(NEWLINE) + 1}: not UTF-8 text") from None
    header = None
    blocks: list[tuple[int, int, int, list[dict[str, Any]]]] = []  # (key, n, first line, rows)
    try:
        for number, fields in csv_records(text):
            if header is None:
                header = fields
                if header[:2] != list(_KEY_COLUMNS):
                    raise JournalError(JOURNAL, f"line 1: the header starts {_short(','.join(header[:2]))},"
                                                f" not {','.join(_KEY_COLUMNS)}")
                what = header_mismatch(header[2:], header[2:] if columns is None else columns)
                if what is None and columns is not None and header[2:] != list(columns):
                    what = "columns in another order"
                if what is not None or len(set(header)) != len(header):
                    raise JournalError(JOURNAL, f"line 1: {what or 'a column is named twice'}")
                continue
            if len(fields) != len(header):
                raise JournalError(JOURNAL, f"line {number}: {len(fields)} fields, the header has {len(header)}")
            try:
                key, n = int(fields[0]), int(fields[1])
            except ValueError:
                raise JournalError(JOURNAL, f"line {number}: task {_short(fields[0])} or task_rows"
                                            f" {_short(fields[1])} is no integer") from None
            if n < 1:
                raise JournalError(JOURNAL, f"line {number}: task_rows {n} (a trial has at least one row)")
            if keys is not None and key not in keys:
                raise JournalError(JOURNAL, f"line {number}: task {key} is not a task of this run")
            row = parsed_row(header[2:], fields[2:], parse, number)
            if blocks and blocks[-1][0] == key and blocks[-1][1] == n and len(blocks[-1][3]) < n:
                blocks[-1][3].append(row)
            else:
                blocks.append((key, n, number, [row]))
    except JournalError:
        raise
    except ValueError as err:  # csv_records' and parsed_row's, which name the line
        raise JournalError(JOURNAL, str(err)) from None
    out: dict[int, list[dict[str, Any]]] = {}
    for i, (key, n, first, rows) in enumerate(blocks):
        if len(rows) == n:
            out[key] = rows  # a trial re-run after a torn block: the later block
        elif i != len(blocks) - 1:
            raise JournalError(JOURNAL, f"line {first}: task {key}'s block has {len(rows)} of its {n} rows")
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
