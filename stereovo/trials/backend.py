"""Trial backends: where the independent trials of a grid run.

A trial is a pure function of its payload (config and seed); a backend only decides where it
runs, so the rows never depend on the backend, the worker count or the completion order.

- :class:`LocalBackend`: this process (``workers == 1``) or a process pool of ``workers``.
- :class:`RayBackend`: Ray tasks. Without an address it starts a local Ray instance with
  ``workers`` CPUs (and shuts it down at the end); ``address="auto"`` or ``"HOST:PORT"`` joins
  an existing cluster. A task whose worker process dies, or whose node is lost, is retried
  (``max_retries``); a trial that *raises* is not retried (it would raise again).

Both take a ``warmup`` callable, run once in every worker process before its first trial, so
one-off costs (numba compiling or loading its cache) never land in a trial's timing.

Ray is imported only by :class:`RayBackend`: the local backend has no Ray start-up cost.
"""

from __future__ import annotations

import hashlib
import os
import pickle
import signal
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass
from typing import Any, Callable, Iterator, Sequence

from stereovo.options import Integer

__all__ = ["BACKENDS", "Task", "Backend", "LocalBackend", "RayBackend", "make_backend", "chunked", "WorkerDied"]

BACKENDS = ("local", "ray")
RAY_WORKER_NICENESS = "RAY_worker_niceness"  # the environment variable the raylet reads at start


@dataclass(frozen=True)
class Task:
    """One trial: its key (unique integer within a run), its payload and its progress weight."""

    key: int
    payload: Any
    weight: float = 1


class WorkerDied(RuntimeError):
    """A local worker process died (killed, out of memory); finished trials are kept."""


def chunked(tasks: Sequence[Task], size: int) -> list[list[Task]]:
    """Consecutive groups of ``size`` tasks (one backend call each: less overhead per trial)."""
    size = Integer(low=1).check("chunk size", size, prefix="")
    return [list(tasks[i:i + size]) for i in range(0, len(tasks), size)]


def _run_chunk(fn: Callable[[Any], Any], chunk: Sequence[Task]) -> list[tuple[int, Any]]:
    return [(task.key, fn(task.payload)) for task in chunk]


# Warm-ups done in this process, by token: a Ray worker process runs many tasks.
_WARMED: set[str] = set()


def _ensure_warm(warmup: Callable[[], None] | None, token: str) -> None:
    if warmup is not None and token not in _WARMED:
        warmup()
        _WARMED.add(token)


def _token(warmup: Callable[[], None] | None) -> str:
    if warmup is None:
        return ""
    try:
        return hashlib.sha1(pickle.dumps(warmup)).hexdigest()
    except Exception:  # noqa: BLE001 - unpicklable warm-ups (in-process only) are keyed by identity
        return f"id-{id(warmup)}"


def _pool_worker_start() -> None:
    # Ctrl-C is the driver's business: it cancels the run and terminates the workers itself;
    # workers that also caught SIGINT would each print a traceback.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    os.environ.setdefault("OMP_NUM_THREADS", "1")


def _warm_chunk(fn, warmup, token, chunk):
    """A chunk in a worker process, after that process's one warm-up."""
    _ensure_warm(warmup, token)
    return _run_chunk(fn, chunk)


class Backend:
    """Runs chunks of tasks and yields ``(key, result)`` as each chunk finishes (any order)."""

    name = "backend"
    workers = 1

    def run(self, fn: Callable[[Any], Any], chunks: Sequence[Sequence[Task]],
            warmup: Callable[[], None] | None = None) -> Iterator[list[tuple[int, Any]]]:
        raise NotImplementedError

    def close(self) -> None:
        """Release the workers (idempotent)."""

    def describe(self) -> str:
        return f"{self.name}, {self.workers} worker(s)"

    def __enter__(self) -> "Backend":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


class LocalBackend(Backend):
    """This process (``workers == 1``) or a pool of ``workers`` processes on this machine.

    The pool lives until :meth:`close`, so its workers stay warm across runs. At most
    ``2 * workers`` chunks are queued at once, so an interrupt has little to cancel (the pool is
    then terminated). A worker that dies raises :class:`WorkerDied` (finished trials are kept).
    """

    name = "local"

    def __init__(self, workers: int = 1) -> None:
        self.workers = Integer(low=1).check("workers", workers, prefix="")
        self._pool: ProcessPoolExecutor | None = None

    def run(self, fn, chunks, warmup=None):
        chunks = list(chunks)
        token = _token(warmup)
        if self.workers == 1:
            for chunk in chunks:
                _ensure_warm(warmup, token)
                yield _run_chunk(fn, chunk)
            return
        from concurrent.futures.process import BrokenProcessPool

        if self._pool is None:
            self._pool = ProcessPoolExecutor(max_workers=self.workers, initializer=_pool_worker_start)
        pool = self._pool
        queue = iter(chunks)
        pending: set = set()
        finished = False
        try:
            for chunk in queue:
                pending.add(pool.submit(_warm_chunk, fn, warmup, token, chunk))
                if len(pending) >= 2 * self.workers:
                    break
            while pending:
                done, pending = wait(pending, return_when=FIRST_COMPLETED)
                for future in done:
                    try:
                        result = future.result()
                    except BrokenProcessPool:
                        raise WorkerDied("a worker process died (killed or out of memory)") from None
                    yield result
                    nxt = next(queue, None)
                    if nxt is not None:
                        pending.add(pool.submit(_warm_chunk, fn, warmup, token, nxt))
            finished = True
        finally:
            if not finished:  # interrupted or failed: stop the trials in flight now
                self.close()

    def close(self) -> None:
        pool, self._pool = self._pool, None
        if pool is None:
            return
        pool.shutdown(wait=False, cancel_futures=True)
        # Trials in flight are lost anyway (they are not in the journal): stop them now rather
        # than wait for them. ProcessPoolExecutor has no public way before Python 3.14.
        terminate = getattr(pool, "terminate_workers", None)
        if terminate is not None:
            terminate()
        else:
            for process in list((getattr(pool, "_processes", None) or {}).values()):
                if process.is_alive():
                    process.terminate()
        pool.shutdown(wait=True)


def connect_ray(workers: int | None, address: str | None, log_to_driver: bool = True) -> bool:
    """Start a local Ray instance with ``workers`` CPUs (``address`` None) or join ``address``
    (``"auto"`` or ``"HOST:PORT"``), unless Ray is already initialised.

    Returns True if this call started or joined Ray (the caller then shuts it down).

    Raises:
        ValueError: naming ``--address`` when the cluster cannot be joined.
    """
    import ray

    if ray.is_initialized():
        return False
    from stereovo.compilation import QUIET_ENV

    # The driver prints the compile notice once for the run (stereovo.trials.runner); a Ray worker,
    # started by Ray's daemons rather than by this process, would print it again without this.
    kwargs: dict[str, Any] = dict(include_dashboard=False, logging_level="ERROR", log_to_driver=log_to_driver,
                                  configure_logging=True, runtime_env={"env_vars": {QUIET_ENV: "1"}})
    if address is None:
        kwargs["num_cpus"] = int(workers or os.cpu_count() or 1)
        # Ray starts its workers at niceness 15 (to keep its own daemons responsive): on a machine
        # doing anything else they then get a sliver of a core, and the same trials run several times
        # slower than in the local pool, whose workers run at the caller's niceness. The trials are
        # the work; give them the caller's priority. (A cluster keeps its own setting.)
        os.environ.setdefault(RAY_WORKER_NICENESS, "0")
    else:
        kwargs["address"] = address
    # ray.init takes SIGTERM over: a Python handler that exits for the start-up, then the core
    # worker's C++ failure handler, which dumps "*** SIGTERM received ***" and aborts. A caller that
    # installed its own handler (vo-gym's sigterm_as_interrupt: a stop that keeps the journal and
    # says how to resume) gets it back, so SIGTERM means the same on every backend.
    keep = _callers_sigterm_handler()
    try:
        ray.init(**kwargs)
    except ConnectionError as err:
        raise ValueError(f"--address {address!r}: cannot join a Ray cluster ({err})") from None
    except (KeyboardInterrupt, SystemExit) as stop:
        # Stopped during the start-up (Ray's handler turns SIGTERM into sys.exit(SIGTERM)): stop
        # what was started, then hand a SIGTERM to the caller's handler, as the signal would have.
        _shutdown_quietly(ray)
        if keep is not None and isinstance(stop, SystemExit) and stop.code == signal.SIGTERM:
            signal.signal(signal.SIGTERM, keep)
            keep(signal.SIGTERM, None)
        raise
    finally:
        if keep is not None:
            signal.signal(signal.SIGTERM, keep)
    return True


def _callers_sigterm_handler() -> Callable[[int, Any], Any] | None:
    """The Python SIGTERM handler in place, if the caller installed one and can reinstall it here."""
    import threading

    if threading.current_thread() is not threading.main_thread():
        return None  # signal.signal would refuse; and Ray sets no handler outside the main thread
    handler = signal.getsignal(signal.SIGTERM)
    return handler if callable(handler) else None  # SIG_DFL / SIG_IGN / set outside Python: Ray's stays


def _shutdown_quietly(ray: Any) -> None:
    try:
        ray.shutdown()
    except Exception:  # noqa: BLE001 - a start-up cut short may leave nothing to shut down
        pass


class RayBackend(Backend):
    """Ray tasks, one per chunk (see the module doc).

    Args:
        workers: CPUs of the local instance started without ``address``; with an address, the
            cluster's CPUs are used and ``workers`` only sizes the in-flight window if given.
        address: None (start a local instance), ``"auto"`` or ``"HOST:PORT"``.
        max_retries: re-runs of a task whose worker died or whose node was lost.
    """

    name = "ray"

    def __init__(self, workers: int | None = None, address: str | None = None, max_retries: int = 3) -> None:
        Integer(low=1, allow_none=True).check("workers", workers, prefix="")
        Integer(low=0).check("max_retries", max_retries, prefix="")
        import ray

        self._ray = ray
        self.address = address
        self.max_retries = int(max_retries)
        self._started = False
        self._pending: list = []
        self._started = connect_ray(workers, address, log_to_driver=True)
        try:
            cpus = int(ray.cluster_resources().get("CPU", 1))
            self.workers = int(workers) if (workers is not None and address is None) else cpus
            self._remote = ray.remote(num_cpus=1, max_retries=self.max_retries, retry_exceptions=False)(_warm_chunk)
        except BaseException:  # an interrupt here: nobody holds this backend to close it
            self.close()
            raise

    def describe(self) -> str:
        where = "a local instance" if self.address is None else f"cluster {self.address}"
        return f"ray ({where}), {self.workers} CPU(s)"

    def run(self, fn, chunks, warmup=None):
        ray = self._ray
        fn_ref = ray.put(fn)
        warm_ref = ray.put(warmup)
        token = _token(warmup)
        queue = iter(chunks)
        window = 2 * self.workers
        self._pending = []
        interrupted = False
        try:
            for chunk in queue:
                self._pending.append(self._remote.remote(fn_ref, warm_ref, token, chunk))
                if len(self._pending) >= window:
                    break
            while self._pending:
                done, self._pending = ray.wait(self._pending, num_returns=1)
                for ref in done:
                    yield ray.get(ref)
                    nxt = next(queue, None)
                    if nxt is not None:
                        self._pending.append(self._remote.remote(fn_ref, warm_ref, token, nxt))
        except KeyboardInterrupt:
            interrupted = True
            raise
        finally:
            if interrupted and self._started:
                self._pending = []  # the caller closes next; see close
            else:
                self._cancel()

    def _cancel(self) -> None:
        pending, self._pending = self._pending, []
        for ref in pending:
            try:
                self._ray.cancel(ref, force=True)
            except Exception:  # noqa: BLE001 - already finished or gone with its node
                pass

    def close(self) -> None:
        if self._started:
            # Shutting our instance down stops its tasks. Force-cancelling them first races their
            # replies: Ray 2.60 then fails a check in CompletePendingTask and the driver exits 1
            # without a word (seen once in four interrupts of `vo-gym evaluate`).
            self._pending = []
            self._started = False
            self._ray.shutdown()
        else:
            self._cancel()


def make_backend(kind: str = "local", workers: int = 1, address: str | None = None, max_retries: int = 3) -> Backend:
    """A backend by name: ``"local"`` (``address`` must be None) or ``"ray"``.

    Raises:
        ValueError: an unknown kind, or an address with the local backend.
    """
    if kind == "local":
        if address is not None:
            raise ValueError(f"--address {address!r} needs --backend ray")
        return LocalBackend(workers)
    if kind == "ray":
        return RayBackend(workers, address, max_retries)
    raise ValueError(f"unknown backend {kind!r}; expected one of {', '.join(BACKENDS)}")
