"""
Where batch tasks run: in this process, in a local process pool, or on a Dask cluster.

(Over 400 lines on purpose: the three executors share one interface and one retry loop.)

All three take a picklable, module-level function and a list of tasks and yield
``(task, outcome)`` pairs as tasks finish, where ``outcome`` is the function's return value
or the exception that ended the task (a crashed worker, a lost connection ...), so that the
caller records the failure and goes on. No scheduling of our own: the local pool is
:class:`concurrent.futures.ProcessPoolExecutor`, the cluster is ``dask.distributed``.

An executor may hold a ``shared`` object (a road network): it reaches every worker once
(the pool's initialiser, ``Client.scatter`` on Dask) and each task is called as
``fn(task, shared)``; without one, ``fn(task)``.

Faults: a task whose worker process died (killed, out of memory) is run once more in a fresh
pool (:meth:`ProcessExecutor.run`'s ``retry`` says how: the same task, or smaller ones);
a task lost again runs once more alone, and only a task that kills a pool on its own is
yielded with its :class:`WorkerLostError` error. Workers die with the
process that started them: each watches a pipe from its parent and exits when the parent is
gone, killed or not, so no orphaned worker goes on matching and writing.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import sys
import threading
from concurrent.futures import Future, ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol, TypeVar

from mapmatch.errors import MapMatchError
from mapmatch.machine import available_cores

if TYPE_CHECKING:
    from collections.abc import Callable, Generator, Iterator, Sequence
    from multiprocessing.connection import Connection
    from multiprocessing.context import BaseContext

__all__ = [
    "DaskExecutor",
    "Executor",
    "InlineExecutor",
    "ProcessExecutor",
    "SchedulerError",
    "WorkerLostError",
    "available_cores",
    "make_executor",
    "unshadowed",
]

T = TypeVar("T")
R = TypeVar("R")


class SchedulerError(MapMatchError, OSError):
    """The Dask scheduler cannot be reached, or ``dask.distributed`` is not installed."""


class WorkerLostError(MapMatchError, RuntimeError):
    """The worker process running a task died, and died again when the task ran alone."""


class Executor(Protocol):
    """Runs tasks and yields each with its outcome as it finishes."""

    #: Tasks that can run at once (processes, or Dask worker threads).
    slots: int
    #: Short description for the human summary (``"2 processes"``, ``"dask tcp://..."``).
    description: str

    def run(
        self,
        fn: Callable[..., R],
        tasks: Sequence[T],
        *,
        retry: Callable[[T], Sequence[T]] | None = None,
    ) -> Iterator[tuple[T, R | BaseException]]:
        """Yield ``(task, fn(task) or the exception it raised)`` in order of completion."""
        ...

    def close(self) -> None:
        """Release processes and connections; cancel what has not started."""
        ...


_NO_SHARED = object()


class InlineExecutor:
    """Runs tasks one after the other in this process (``--workers 1``)."""

    slots = 1
    description = "1 process (in-process)"

    def __init__(self, *, shared: object = _NO_SHARED) -> None:
        self._shared = shared

    def run(
        self,
        fn: Callable[..., R],
        tasks: Sequence[T],
        *,
        retry: Callable[[T], Sequence[T]] | None = None,
    ) -> Iterator[tuple[T, R | BaseException]]:
        """Yield ``(task, outcome)`` for each task in order (a crash here ends the caller)."""
        for task in tasks:
            try:
                if self._shared is _NO_SHARED:
                    outcome: R | BaseException = fn(task)
                else:
                    outcome = fn(task, self._shared)
            except Exception as exc:
                outcome = exc
            yield task, outcome

    def close(self) -> None:
        """Nothing to release."""


# --------------------------------------------------------------------------- local pool

_WORKER_SHARED: list[object] = []


def _watch_parent(parent: Connection) -> None:
    """Exit this worker at once when the process that started the pool is gone."""
    with contextlib.suppress(EOFError, OSError):
        parent.recv()  # nothing is ever sent: returns (EOFError) when the parent's end closes
    os._exit(1)


def _die_with_parent() -> None:
    """Ask Linux to kill this process when its parent (the fork server) dies."""
    if not sys.platform.startswith("linux"):
        return
    with contextlib.suppress(OSError, AttributeError):
        import ctypes
        import signal

        libc = ctypes.CDLL(None, use_errno=True)
        pr_set_pdeathsig = 1
        libc.prctl(pr_set_pdeathsig, signal.SIGKILL, 0, 0, 0)


def _init_worker(parent: Connection, shared: object) -> None:
    _die_with_parent()
    threading.Thread(target=_watch_parent, args=(parent,), daemon=True).start()
    _WORKER_SHARED[:] = [shared]


def _call_shared(fn: Callable[[T, object], R], task: T) -> R:
    return fn(task, _WORKER_SHARED[0])


def unshadowed(preload: Sequence[str], cwd: Path | None = None) -> list[str]:
    """
    The modules of ``preload`` a fork server started here would import as this process did.

    A fork server is started as ``python -c`` in this process's working directory and (up to
    Python 3.11) keeps its own ``sys.path``, whose first entry is that directory: a package of
    the same name there (a checkout of another version, a snapshot) would be what it imports,
    and every worker forked from it would run that copy while this process runs its own. Such
    modules are left to the workers, which import them with this process's ``sys.path``.

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     (Path(tmp) / "mapmatch").mkdir()
    ...     _ = (Path(tmp) / "mapmatch" / "__init__.py").write_text("")
    ...     unshadowed(["mapmatch.batch", "json"], cwd=Path(tmp))
    ['json']
    """
    here = (cwd if cwd is not None else Path.cwd()).resolve()
    kept = []
    for name in preload:
        top = name.partition(".")[0]
        local = [p for p in (here / top / "__init__.py", here / f"{top}.py") if p.exists()]
        origin = getattr(sys.modules.get(top), "__file__", None)
        if local and (origin is None or Path(origin).resolve() not in local):
            continue
        kept.append(name)
    return kept


class ProcessExecutor:
    """
    A local pool of worker processes (:class:`~concurrent.futures.ProcessPoolExecutor`).

    Workers are started by a fork server that has imported ``preload`` once, so each starts
    fast without inheriting the parent's threads; where there is no fork server (Windows,
    macOS defaults) they are spawned. Each worker exits as soon as this process is gone.

    Parameters
    ----------
    workers
        Number of worker processes.
    preload
        Modules the fork server imports before forking workers.
    shared
        An object every task receives as its second argument, sent to each worker once.
    """

    def __init__(
        self, workers: int, *, preload: Sequence[str] = (), shared: object = _NO_SHARED
    ) -> None:
        ctx: BaseContext
        if "forkserver" in multiprocessing.get_all_start_methods():
            server = multiprocessing.get_context("forkserver")
            server.set_forkserver_preload(unshadowed(preload))
            ctx = server
        else:
            ctx = multiprocessing.get_context("spawn")
        self._ctx = ctx
        self._shared = shared
        self.slots = workers
        self.description = f"{workers} processes"
        # the worker ends of a pipe whose parent end only this process holds: when this
        # process dies, however, the workers read end-of-file and exit
        self._from_parent, self._parent_end = ctx.Pipe(duplex=False)
        self._pool = self._new_pool()

    def _new_pool(self) -> ProcessPoolExecutor:
        shared = None if self._shared is _NO_SHARED else self._shared
        return ProcessPoolExecutor(
            max_workers=self.slots,
            mp_context=self._ctx,
            initializer=_init_worker,
            initargs=(self._from_parent, shared),
        )

    def _submit(self, fn: Callable[..., R], task: T) -> Future[R]:
        if self._shared is _NO_SHARED:
            return self._pool.submit(fn, task)
        return self._pool.submit(_call_shared, fn, task)

    def run(
        self,
        fn: Callable[..., R],
        tasks: Sequence[T],
        *,
        retry: Callable[[T], Sequence[T]] | None = None,
    ) -> Iterator[tuple[T, R | BaseException]]:
        """
        Submit every task; yield each with its outcome as it completes.

        Tasks lost with a dead worker are run once more in a fresh pool, after the others
        (and those lost again, each alone in its own fresh pool): ``retry(task)`` gives
        what to run instead (default: the task itself; an empty list
        when nothing of it is left to do).
        """
        yield from _retried(
            partial(self._round, fn),
            tasks,
            retry,
            died=BrokenProcessPool,
            fresh=self._renew,
            what="the worker process died each time it ran this task, the last time alone",
        )

    def _renew(self) -> None:
        """Replace a broken pool by a fresh one."""
        self._pool.shutdown(wait=True, cancel_futures=True)
        self._pool = self._new_pool()

    def _round(
        self, fn: Callable[..., R], tasks: Sequence[T]
    ) -> Iterator[tuple[T, R | BaseException]]:
        futures: dict[Future[R], T] = {}
        for task in tasks:
            try:
                futures[self._submit(fn, task)] = task
            except BrokenProcessPool as exc:  # the pool broke while submitting
                yield task, exc
        for future in as_completed(futures):
            outcome: R | BaseException = _outcome(future)
            yield futures[future], outcome

    def close(self) -> None:
        """Cancel pending tasks and stop the workers."""
        self._pool.shutdown(wait=True, cancel_futures=True)
        self._parent_end.close()
        self._from_parent.close()


def _retried(
    round_: Callable[[Sequence[T]], Iterator[tuple[T, R | BaseException]]],
    tasks: Sequence[T],
    retry: Callable[[T], Sequence[T]] | None,
    *,
    died: type[BaseException],
    fresh: Callable[[], None] | None,
    what: str,
) -> Iterator[tuple[T, R | BaseException]]:
    """
    Run ``tasks`` in a round; the ones lost with their worker (``died``) once more.

    ``fresh`` makes a new pool first; ``retry(task)`` says what to run instead of a lost
    task. The lost tasks run again together; when that round breaks too, each task it lost
    runs alone in a fresh pool, so an innocent task that only shared the pool with a
    killer is not blamed. A task that kills a pool on its own is yielded with a
    :class:`WorkerLostError` (``what`` says why).
    """
    again = yield from _lost_in(round_(tasks), died)
    if not again:
        return
    again = yield from _lost_in(_fresh_round(round_, again, retry, fresh), died)
    for task in again:
        for alone, outcome in _fresh_round(round_, [task], retry, fresh):
            if isinstance(outcome, died):
                outcome = WorkerLostError(f"{what} ({outcome})")
            yield alone, outcome


def _fresh_round(
    round_: Callable[[Sequence[T]], Iterator[tuple[T, R | BaseException]]],
    lost: Sequence[T],
    retry: Callable[[T], Sequence[T]] | None,
    fresh: Callable[[], None] | None,
) -> Iterator[tuple[T, R | BaseException]]:
    """A round of what is left to do of ``lost`` (``retry``), in a fresh pool."""
    if fresh is not None:
        fresh()
    yield from round_([t for task in lost for t in (retry(task) if retry else [task])])


def _lost_in(
    outcomes: Iterator[tuple[T, R | BaseException]], died: type[BaseException]
) -> Generator[tuple[T, R | BaseException], None, list[T]]:
    """Yield the outcomes of a round; return the tasks lost with their worker."""
    lost: list[T] = []
    for task, outcome in outcomes:
        if isinstance(outcome, died):
            lost.append(task)
        else:
            yield task, outcome
    return lost


def _outcome(future: Future[R]) -> R | BaseException:
    try:
        result: R = future.result()
    except Exception as exc:
        return exc
    return result


# --------------------------------------------------------------------------- Dask


class DaskExecutor:
    """
    Tasks on a ``dask.distributed`` cluster: an existing scheduler, or a client given.

    Workers must see the same files as this process (inputs, network, output folder) and
    have this package installed.

    Parameters
    ----------
    address
        The scheduler, e.g. ``tcp://10.0.0.5:8786`` (ignored with ``client``).
    client
        A connected ``distributed.Client`` to use (left open at :meth:`close`).
    timeout_s
        How long to wait for the connection.
    shared
        An object every task receives as its second argument (scattered to every worker
        once).

    Raises
    ------
    SchedulerError
        The scheduler cannot be reached or has no workers, or ``dask.distributed`` is missing.
    """

    def __init__(
        self,
        address: str | None = None,
        *,
        client: Any = None,
        timeout_s: float = 30.0,
        shared: object = _NO_SHARED,
    ) -> None:
        try:
            from distributed import Client
        except ImportError as exc:  # pragma: no cover - a dependency of the package
            msg = "Dask needs dask.distributed; pip install 'dask[distributed]'"
            raise SchedulerError(msg) from exc
        self._own = client is None
        if client is None:
            try:
                client = Client(  # type: ignore[no-untyped-call]
                    address, timeout=timeout_s, set_as_default=False
                )
            except (OSError, TimeoutError, ValueError) as exc:
                msg = f"cannot reach the Dask scheduler at {address!r}: {exc}; is it running?"
                raise SchedulerError(msg) from exc
        self._client = client
        address = str(client.scheduler.address)
        workers = client.scheduler_info().get("workers", {})
        threads = sum(int(w.get("nthreads", 1)) for w in workers.values())
        if threads < 1:
            self.close()
            msg = f"the Dask scheduler at {address!r} has no workers; start some first"
            raise SchedulerError(msg)
        self.slots = threads
        self.description = f"dask {address} ({len(workers)} workers, {threads} threads)"
        self._shared: object = _NO_SHARED
        if shared is not _NO_SHARED:
            self._shared = client.scatter(shared, broadcast=True, hash=False)

    def _submit(self, fn: Callable[..., R], task: T) -> Any:
        if self._shared is _NO_SHARED:
            return self._client.submit(fn, task, pure=False)
        return self._client.submit(fn, task, self._shared, pure=False)

    def run(
        self,
        fn: Callable[..., R],
        tasks: Sequence[T],
        *,
        retry: Callable[[T], Sequence[T]] | None = None,
    ) -> Iterator[tuple[T, R | BaseException]]:
        """
        Submit every task to the cluster; yield each with its outcome as it completes.

        A task whose workers kept dying (Dask's ``KilledWorker``) is submitted once more
        (``retry`` as for :meth:`ProcessExecutor.run`).
        """
        from distributed import KilledWorker

        yield from _retried(
            partial(self._round, fn),
            tasks,
            retry,
            died=KilledWorker,
            fresh=None,  # the scheduler replaces dead workers itself
            what="the Dask workers running this task died",
        )

    def _round(
        self, fn: Callable[..., R], tasks: Sequence[T]
    ) -> Iterator[tuple[T, R | BaseException]]:
        from distributed import as_completed as dask_as_completed

        if not tasks:
            return
        futures = {self._submit(fn, task): task for task in tasks}
        for future in dask_as_completed(  # type: ignore[no-untyped-call]
            list(futures), loop=self._client.loop
        ):
            try:
                outcome: R | BaseException = future.result()
            except Exception as exc:
                outcome = exc
            yield futures[future], outcome

    def close(self) -> None:
        """Close the connection we opened (the cluster keeps running; a given client stays)."""
        if self._own:
            self._client.close()


def make_executor(
    workers: int | None,
    scheduler: str | None,
    *,
    client: Any = None,
    preload: Sequence[str] = (),
    timeout_s: float = 30.0,
    shared: object = _NO_SHARED,
) -> InlineExecutor | ProcessExecutor | DaskExecutor:
    """
    The executor for the command line's ``--workers`` / ``--scheduler`` (or a Dask client).

    Parameters
    ----------
    workers
        Local worker processes; ``None`` means one per core; 1 runs in this process.
        Ignored with ``scheduler`` or ``client``.
    scheduler
        Address of a Dask scheduler, or ``None`` for local execution.
    client
        A connected ``distributed.Client`` (instead of ``scheduler``).
    preload
        Modules the local fork server imports once.
    timeout_s
        How long to try to connect to ``scheduler``.
    shared
        An object every task receives as its second argument (``fn(task, shared)``), sent
        to each worker once.
    """
    if client is not None or scheduler:
        return DaskExecutor(scheduler, client=client, timeout_s=timeout_s, shared=shared)
    count = workers if workers is not None else available_cores()
    if count <= 1:
        return InlineExecutor(shared=shared)
    return ProcessExecutor(count, preload=preload, shared=shared)
