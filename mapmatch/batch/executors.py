"""
Where batch tasks run: in this process, in a local process pool, or on a Dask cluster.

All three take a picklable, module-level function and a list of tasks and yield
``(task, outcome)`` pairs as tasks finish, where ``outcome`` is the function's return value
or the exception that ended the task (a crashed worker, a lost connection ...), so that the
caller records the failure and goes on. No scheduling of our own: the local pool is
:class:`concurrent.futures.ProcessPoolExecutor`, the cluster is ``dask.distributed``.
"""

from __future__ import annotations

import multiprocessing
import os
from concurrent.futures import Future, ProcessPoolExecutor, as_completed
from typing import TYPE_CHECKING, Protocol, TypeVar

from mapmatch.errors import MapMatchError

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator, Sequence
    from multiprocessing.context import BaseContext

__all__ = [
    "DaskExecutor",
    "Executor",
    "InlineExecutor",
    "ProcessExecutor",
    "SchedulerError",
    "make_executor",
]

T = TypeVar("T")
R = TypeVar("R")


class SchedulerError(MapMatchError, OSError):
    """The Dask scheduler cannot be reached, or ``dask.distributed`` is not installed."""


class Executor(Protocol):
    """Runs tasks and yields each with its outcome as it finishes."""

    #: Tasks that can run at once (processes, or Dask worker threads).
    slots: int
    #: Short description for the human summary (``"2 processes"``, ``"dask tcp://..."``).
    description: str

    def run(
        self, fn: Callable[[T], R], tasks: Sequence[T]
    ) -> Iterator[tuple[T, R | BaseException]]:
        """Yield ``(task, fn(task) or the exception it raised)`` in order of completion."""
        ...

    def close(self) -> None:
        """Release processes and connections; cancel what has not started."""
        ...


class InlineExecutor:
    """Runs tasks one after the other in this process (``--workers 1``)."""

    slots = 1
    description = "1 process (in-process)"

    def run(
        self, fn: Callable[[T], R], tasks: Sequence[T]
    ) -> Iterator[tuple[T, R | BaseException]]:
        """Yield ``(task, outcome)`` for each task in order."""
        for task in tasks:
            try:
                outcome: R | BaseException = fn(task)
            except Exception as exc:
                outcome = exc
            yield task, outcome

    def close(self) -> None:
        """Nothing to release."""


class ProcessExecutor:
    """
    A local pool of worker processes (:class:`~concurrent.futures.ProcessPoolExecutor`).

    Workers are started by a fork server that has imported ``preload`` once, so each starts
    fast without inheriting the parent's threads; where there is no fork server (Windows,
    macOS defaults) they are spawned.

    Parameters
    ----------
    workers
        Number of worker processes.
    preload
        Modules the fork server imports before forking workers.
    """

    def __init__(self, workers: int, *, preload: Sequence[str] = ()) -> None:
        ctx: BaseContext
        if "forkserver" in multiprocessing.get_all_start_methods():
            server = multiprocessing.get_context("forkserver")
            server.set_forkserver_preload(list(preload))
            ctx = server
        else:
            ctx = multiprocessing.get_context("spawn")
        self.slots = workers
        self.description = f"{workers} processes"
        self._pool = ProcessPoolExecutor(max_workers=workers, mp_context=ctx)

    def run(
        self, fn: Callable[[T], R], tasks: Sequence[T]
    ) -> Iterator[tuple[T, R | BaseException]]:
        """Submit every task; yield each with its outcome as it completes."""
        futures: dict[Future[R], T] = {self._pool.submit(fn, task): task for task in tasks}
        for future in as_completed(futures):
            outcome: R | BaseException = _outcome(future)
            yield futures[future], outcome

    def close(self) -> None:
        """Cancel pending tasks and stop the workers."""
        self._pool.shutdown(wait=True, cancel_futures=True)


def _outcome(future: Future[R]) -> R | BaseException:
    try:
        result: R = future.result()
    except Exception as exc:
        return exc
    return result


class DaskExecutor:
    """
    Tasks on an existing ``dask.distributed`` cluster.

    Workers must see the same files as this process (inputs, network, output folder) and
    have this package installed.

    Parameters
    ----------
    address
        The scheduler, e.g. ``tcp://10.0.0.5:8786``.
    timeout_s
        How long to wait for the connection.

    Raises
    ------
    SchedulerError
        The scheduler cannot be reached or has no workers, or ``dask.distributed`` is missing.
    """

    def __init__(self, address: str, *, timeout_s: float = 30.0) -> None:
        try:
            from distributed import Client
        except ImportError as exc:  # pragma: no cover - a dependency of the package
            msg = "--scheduler needs dask.distributed; pip install 'dask[distributed]'"
            raise SchedulerError(msg) from exc
        try:
            self._client = Client(  # type: ignore[no-untyped-call]
                address, timeout=timeout_s, set_as_default=False
            )
        except (OSError, TimeoutError, ValueError) as exc:
            msg = f"cannot reach the Dask scheduler at {address!r}: {exc}; is it running?"
            raise SchedulerError(msg) from exc
        workers = self._client.scheduler_info().get("workers", {})
        threads = sum(int(w.get("nthreads", 1)) for w in workers.values())
        if threads < 1:
            self._client.close()  # type: ignore[no-untyped-call]
            msg = f"the Dask scheduler at {address!r} has no workers; start some first"
            raise SchedulerError(msg)
        self.slots = threads
        self.description = f"dask {address} ({len(workers)} workers, {threads} threads)"

    def run(
        self, fn: Callable[[T], R], tasks: Sequence[T]
    ) -> Iterator[tuple[T, R | BaseException]]:
        """Submit every task to the cluster; yield each with its outcome as it completes."""
        from distributed import as_completed as dask_as_completed

        futures = {self._client.submit(fn, task, pure=False): task for task in tasks}
        for future in dask_as_completed(  # type: ignore[no-untyped-call]
            list(futures), loop=self._client.loop
        ):
            try:
                outcome: R | BaseException = future.result()
            except Exception as exc:
                outcome = exc
            yield futures[future], outcome

    def close(self) -> None:
        """Close the connection (the cluster keeps running)."""
        self._client.close()  # type: ignore[no-untyped-call]


def make_executor(
    workers: int | None,
    scheduler: str | None,
    *,
    preload: Sequence[str] = (),
    timeout_s: float = 30.0,
) -> InlineExecutor | ProcessExecutor | DaskExecutor:
    """
    The executor for the command line's ``--workers`` / ``--scheduler``.

    Parameters
    ----------
    workers
        Local worker processes; ``None`` means one per core; 1 runs in this process.
        Ignored with ``scheduler``.
    scheduler
        Address of a Dask scheduler, or ``None`` for local execution.
    preload
        Modules the local fork server imports once.
    timeout_s
        How long to try to connect to ``scheduler``.
    """
    if scheduler:
        return DaskExecutor(scheduler, timeout_s=timeout_s)
    count = workers if workers is not None else (os.cpu_count() or 1)
    if count <= 1:
        return InlineExecutor()
    return ProcessExecutor(count, preload=preload)
