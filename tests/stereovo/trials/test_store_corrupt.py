"""A corrupt run folder is one RunFolderError naming the file and what is wrong, never a traceback."""

from __future__ import annotations

import pytest

from stereovo.trials import RunFolderError, prepare_run_folder
from stereovo.trials.store import JOURNAL, MANIFEST
from tests.support.trials import open_journal

MANIFEST_DATA = {"run": 1}


def _journal_text(tmp_path, reference):
    journal = open_journal(tmp_path)
    journal.open(MANIFEST_DATA, resume=False)
    journal.append(0, reference[0:2])
    journal.append(1, reference[2:4])
    journal.close()
    return (tmp_path / JOURNAL).read_text()


def _replace_line(text, number, edit):
    lines = text.splitlines(keepends=True)
    lines[number - 1] = edit(lines[number - 1])
    return "".join(lines)


@pytest.mark.parametrize("content, needle", [
    (b"{bad", "manifest.json is not a manifest of this run (not JSON"),
    (b"", "manifest.json is not a manifest of this run (not JSON"),
    (b"[1,2,3]", "manifest.json is not a manifest of this run (a JSON list, not an object)"),
    (b"null", "manifest.json is not a manifest of this run (a JSON null, not an object)"),
    (b"[" * 200_000, "manifest.json is not a manifest of this run (not JSON"),
    (b"\xff{}", "manifest.json is not a manifest of this run (not UTF-8 text at byte 0)"),
])
def test_a_corrupt_manifest_is_one_error_naming_it(tmp_path, reference, content, needle):
    _journal_text(tmp_path, reference)
    (tmp_path / MANIFEST).write_bytes(content)
    with pytest.raises(RunFolderError, match="pass --overwrite") as info:
        open_journal(tmp_path).open(MANIFEST_DATA, resume=True)
    assert needle in str(info.value) and str(tmp_path) in str(info.value)
    assert (tmp_path / MANIFEST).read_bytes() == content  # left as it was


@pytest.mark.parametrize("name", [MANIFEST, JOURNAL])
def test_a_directory_in_place_of_a_run_file_is_one_error(tmp_path, reference, name):
    _journal_text(tmp_path, reference)
    (tmp_path / name).unlink()
    (tmp_path / name).mkdir()
    with pytest.raises(RunFolderError, match=f"{name} is a directory"):
        open_journal(tmp_path).open(MANIFEST_DATA, resume=True)


@pytest.mark.parametrize("corrupt, needle", [
    (lambda t: "\x00\x01garbage\n" * 3, "line 1: the header starts '\\x00\\x01garbage', not task,task_rows"),
    (lambda t: t.encode() + b"\xff\xfe\x80", "not UTF-8 text"),
    (lambda t: t.replace("\n", "\n\xff", 1).encode("latin-1"), "line 2: not UTF-8 text"),
    (lambda t: _replace_line(t, 3, lambda l: l.rstrip("\n") + "," + "x" * 300_000 + "\n"), "line 3: field larger"),
    (lambda t: _replace_line(t, 1, lambda l: l.replace("method", "methodX")), "line 1: missing column(s) method;"
                                                                               " unknown column(s) 'methodX'"),
    (lambda t: _replace_line(t, 1, lambda l: l.replace(",method", "")), "line 1: missing column(s) method)"),
    (lambda t: _replace_line(t, 2, lambda l: "zero" + l[1:]), "line 2: task 'zero'"),
    (lambda t: _replace_line(t, 2, lambda l: l.replace(",True,", ",maybe,").replace(",False,", ",maybe,")),
     "line 2: success 'maybe' is no value of that column"),
    (lambda t: _replace_line(t, 2, lambda l: l.split(",", 2)[0] + ",0," + l.split(",", 2)[2]), "line 2: task_rows 0"),
    (lambda t: _replace_line(t, 3, lambda l: "99" + l[1:]), "task 99 is not a task of this run"),
    (lambda t: _replace_line(t, 3, lambda l: "-1" + l[1:]), "task -1 is not a task of this run"),
])
def test_a_corrupt_journal_is_one_error_naming_the_line(tmp_path, reference, corrupt, needle):
    text = _journal_text(tmp_path, reference)
    content = corrupt(text)
    content = content.encode() if isinstance(content, str) else content
    (tmp_path / JOURNAL).write_bytes(content)
    with pytest.raises(RunFolderError) as info:
        open_journal(tmp_path).open(MANIFEST_DATA, resume=True, keys=range(2))
    message = str(info.value)
    assert "journal.csv is not a journal of this run (" in message and needle in message, message
    assert message.endswith("; pass --overwrite to start again") and "\n" not in message
    assert (tmp_path / JOURNAL).read_bytes() == content  # left as it was


def test_a_path_through_a_missing_folder_is_checked_as_the_folder_it_names(tmp_path):
    full = tmp_path / "full"
    full.mkdir()
    (full / "trials.csv").write_text("x")
    with pytest.raises(RunFolderError, match="is not empty"):
        prepare_run_folder(tmp_path / "missing" / ".." / "full", resume=False, overwrite=False)
    assert not (tmp_path / "missing").exists()


def test_a_journal_without_its_manifest_is_refused_not_discarded(tmp_path):
    journal = open_journal(tmp_path)
    journal.open({"run": 1}, resume=False)
    journal.close()
    (tmp_path / "manifest.json").unlink()
    before = (tmp_path / "journal.csv").read_bytes()
    with pytest.raises(RunFolderError, match="journal.csv has no manifest.json beside it"):
        open_journal(tmp_path).open({"run": 1}, resume=True)
    assert (tmp_path / "journal.csv").read_bytes() == before
