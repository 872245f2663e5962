"""Runs that outgrow one process: trial backends (local pool, Ray), a journal that survives
interrupts and resumes, and the task runner with progress.

- :mod:`stereovo.trials.backend`: :class:`~stereovo.trials.backend.LocalBackend`,
  :class:`~stereovo.trials.backend.RayBackend`, :func:`~stereovo.trials.backend.make_backend`.
- :mod:`stereovo.trials.store`: the run folder (manifest, append-only journal, atomic final files).
- :mod:`stereovo.trials.runner`: :func:`~stereovo.trials.runner.run_tasks`.

Importing this package imports neither Ray nor torch.
"""

from stereovo.trials.backend import BACKENDS, Backend, LocalBackend, RayBackend, Task, make_backend
from stereovo.trials.runner import RunInterrupted, RunResult, run_tasks
from stereovo.trials.store import RunFolderError, TrialJournal, atomic_path, atomic_write_text, prepare_run_folder

__all__ = [
    "BACKENDS", "Backend", "LocalBackend", "RayBackend", "Task", "make_backend",
    "RunInterrupted", "RunResult", "run_tasks",
    "RunFolderError", "TrialJournal", "atomic_path", "atomic_write_text", "prepare_run_folder",
]
