"""stereovo.trials.store: the journal round-trips rows, survives a torn block, and guards its folder."""

from __future__ import annotations

import os
import stat

import pytest

from stereovo.trials import RunFolderError, prepare_run_folder
from stereovo.trials.store import JOURNAL
from tests.support.benchmark import same_rows
from tests.support.trials import open_journal


def test_journal_round_trips_rows_bit_for_bit(tmp_path, reference):
    journal = open_journal(tmp_path)
    assert journal.open({"run": 1}, resume=False) == {}
    by_trial = {}
    for row in reference:
        by_trial.setdefault(row["trial"], []).append(row)
    for key, rows in by_trial.items():
        journal.append(key, rows)
    journal.close()
    back = journal.read()
    assert sorted(back) == sorted(by_trial)
    same_rows([r for k in sorted(back) for r in back[k]], reference)  # floats via repr: exact


def test_a_torn_block_is_dropped_and_the_rest_kept(tmp_path, reference):
    journal = open_journal(tmp_path)
    journal.open({"run": 1}, resume=False)
    journal.append(0, reference[0:2])
    journal.append(1, reference[2:4])
    journal.close()
    text = (tmp_path / JOURNAL).read_text()
    lines = text.splitlines(keepends=True)
    # A crash in the middle of trial 1's block: its second row is missing and the first is torn.
    (tmp_path / JOURNAL).write_text("".join(lines[:-2]) + lines[-2][: len(lines[-2]) // 2])
    assert sorted(journal.read()) == [0]
    done = open_journal(tmp_path).open({"run": 1}, resume=True)
    assert sorted(done) == [0]
    assert (tmp_path / JOURNAL).read_text() == "".join(lines[:-2])  # rewritten with whole blocks only


def test_resume_refuses_a_folder_with_other_settings(tmp_path):
    open_journal(tmp_path).open({"seed": 1, "methods": ["ransac"]}, resume=False)
    with pytest.raises(RunFolderError, match="other settings.*seed"):
        open_journal(tmp_path).open({"seed": 2, "methods": ["ransac"]}, resume=True)


def test_a_non_empty_folder_is_refused_unless_resume_or_overwrite(tmp_path):
    (tmp_path / "old.txt").write_text("x")
    with pytest.raises(RunFolderError, match="not empty.*--resume.*--overwrite"):
        prepare_run_folder(tmp_path, resume=False, overwrite=False)
    prepare_run_folder(tmp_path, resume=True, overwrite=False)
    (tmp_path / JOURNAL).write_text("task\n")
    prepare_run_folder(tmp_path, resume=False, overwrite=True)
    assert not (tmp_path / JOURNAL).exists()
    with pytest.raises(RunFolderError, match="exclude"):
        prepare_run_folder(tmp_path, resume=True, overwrite=True)


def test_a_result_file_gets_the_mode_the_umask_gives_a_new_file(tmp_path):
    from stereovo.trials.store import atomic_write_text

    previous = os.umask(0o022)
    try:
        path = atomic_write_text(tmp_path / "summary.md", "x\n")
        assert stat.S_IMODE(path.stat().st_mode) == 0o644  # mkstemp's 0600 made results unreadable to others
        os.umask(0o077)
        assert stat.S_IMODE(atomic_write_text(tmp_path / "other.md", "y\n").stat().st_mode) == 0o600
    finally:
        os.umask(previous)
