"""Run many independent experiments serially, on local processes or on a Dask cluster, with a
checkpoint that survives interruption.

Each experiment is seeded by its own child of ``numpy.random.SeedSequence(seed).spawn(n)``, so a
result depends only on its index. A :class:`Job` names two module-level functions by
``"module:function"`` (so loky and Dask pickle a reference, not code):

- ``setup(context) -> state``: built once per process and cached (e.g. the model and keyboard);
- ``run(state, task) -> dict[str, ndarray]``: one experiment.

:func:`execute` yields ``(index, result)`` as experiments finish: serially, on ``jobs=N`` local
processes (joblib/loky) or on ``scheduler="tcp://HOST:PORT"`` (``dask.distributed``). Workers only
compute; the caller alone writes files. BLAS/OpenMP pools are limited to one thread in every
backend, so results are bit-identical across backends. :class:`kbcli.io.checkpoint.Checkpoint`
keeps the finished experiments, so a killed run resumes.
"""

from __future__ import annotations

import contextlib
import importlib
import os
import uuid
import warnings
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from typing import Any

from kbcli.errors import ConfigError, KbcliError
from kbcli.io.processes import cap_jobs, children_deaf_to_ctrl_c, watch_parent

CONNECT_TIMEOUT_S = 5.0
WORKER_WAIT_S = 30.0


@dataclass(frozen=True)
class Job:
    """What to run.

    Attributes
    ----------
    setup, run : str
        ``"module:function"`` of the per-process setup and of one experiment.
    context : object
        Picklable input of ``setup`` (shared by every experiment).
    context_key : str
        Identifies ``context`` (e.g. a sha256) for the per-process cache.
    tasks : tuple
        Picklable input of ``run``; ``tasks[i]`` is experiment ``i``.
    """

    setup: str
    run: str
    context: Any
    context_key: str
    tasks: tuple


# -- the worker side ---------------------------------------------------------------------------
_STATE: dict[str, Any] = {}


def resolve(name: str) -> Any:
    """The object named ``"package.module:attribute"``."""
    module, _, attr = name.partition(":")
    if not module or not attr:
        raise ConfigError(f"function name {name!r} must look like 'package.module:function'")
    return getattr(importlib.import_module(module), attr)


def _tune_malloc() -> None:
    """Undo a small ``MALLOC_TRIM_THRESHOLD_`` in this process (Dask's nanny sets 64 kB in its
    workers), which makes glibc mmap and unmap every numpy temporary above 128 kB: restores large
    thresholds with ``mallopt`` (glibc only; elsewhere, or without the variable, nothing
    happens)."""
    if not os.environ.get("MALLOC_TRIM_THRESHOLD_"):
        return
    import ctypes
    import ctypes.util

    with contextlib.suppress(OSError, AttributeError, TypeError):
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        m_trim_threshold, m_mmap_threshold = -1, -3
        libc.mallopt(m_mmap_threshold, 32 << 20)
        libc.mallopt(m_trim_threshold, 64 << 20)


def _state_for(setup: str, context: Any, key: str) -> Any:
    token = f"{setup}|{key}"
    if token not in _STATE:
        _tune_malloc()
        _STATE.clear()  # one context at a time per process
        _STATE[token] = resolve(setup)(context)
    return _STATE[token]


def no_leak_restarts() -> None:
    """Tell loky (in this worker) not to take the per-process caches for a leak: it restarts a
    worker whose memory grew by 300 MB, and the model rasters and blurred maps a worker keeps on
    purpose weigh about 0.5 GB a model. Raised to 16 GB, the check still catches a runaway."""
    with contextlib.suppress(ImportError, AttributeError):
        from joblib.externals.loky import process_executor

        process_executor._MAX_MEMORY_LEAK_SIZE = max(process_executor._MAX_MEMORY_LEAK_SIZE,
                                                     16 << 30)


def run_tasks(
    setup: str, run: str, context: Any, key: str, items: list[tuple[int, Any]]
) -> list[tuple[int, dict]]:
    """Run ``items`` (index, task) in this process and return ``[(index, result), ...]``.

    This is what every backend calls (it is module-level, so it pickles by reference).
    """
    from threadpoolctl import threadpool_limits

    no_leak_restarts()
    with threadpool_limits(limits=1):
        state = _state_for(setup, context, key)
        fn = resolve(run)
        return [(i, fn(state, task)) for i, task in items]


def run_local_tasks(parent: int, setup: str, run: str, context: Any, key: str,
                    items: list[tuple[int, Any]]) -> list[tuple[int, dict]]:
    """:func:`run_tasks` in a local worker process of ``parent``, which it never outlives."""
    watch_parent(parent)
    return run_tasks(setup, run, context, key, items)


# -- backends ------------------------------------------------------------------------------------
def check_scheduler_address(address: str) -> str:
    """Validate ``tcp://HOST:PORT`` (or ``tls://``); raises ConfigError otherwise."""
    scheme, sep, rest = address.partition("://")
    host, _, port = rest.rpartition(":")
    if not sep or scheme not in ("tcp", "tls") or not host or not port.isdigit():
        raise ConfigError(f"--scheduler must look like tcp://HOST:PORT, got {address!r}")
    return address


def connect(address: str, timeout: float | None = None):
    """A ``dask.distributed.Client`` on ``address``, or KbcliError within ``timeout`` seconds
    (default :data:`CONNECT_TIMEOUT_S`)."""
    check_scheduler_address(address)
    timeout = CONNECT_TIMEOUT_S if timeout is None else timeout
    from dask.distributed import Client

    try:
        return Client(address, timeout=timeout, set_as_default=False)
    except (OSError, TimeoutError) as exc:
        raise KbcliError(
            f"cannot reach the Dask scheduler at {address} within {timeout:g} s "
            f"({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})"
        ) from None


def chunks(todo: list[int], workers: int, most: int = 16) -> list[list[int]]:
    """Split ``todo`` into runs of consecutive experiments, about 8 per worker and at most ``most``
    long: fewer round trips for short experiments, still enough pieces to balance the load."""
    size = max(1, min(most, len(todo) // (8 * max(1, workers))))
    return [todo[i:i + size] for i in range(0, len(todo), size)]


def _serial(job: Job, todo: list[int]) -> Iterator[tuple[int, dict]]:
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1):  # entered once: it costs about a millisecond
        state = _state_for(job.setup, job.context, job.context_key)
        fn = resolve(job.run)
        for i in todo:
            yield i, fn(state, job.tasks[i])


def quiet_joblib_cancel() -> None:
    """Silence joblib's warning of several lines about the tasks it cancels when stopped early
    (Ctrl-C, SIGTERM, an error): the one line the CLI prints already says what was kept."""
    warnings.filterwarnings("ignore", message=r"(?s).*adjusting the input task iterator",
                            category=UserWarning)


def _local(job: Job, todo: list[int], n_jobs: int) -> Iterator[tuple[int, dict]]:
    from joblib import Parallel, delayed

    quiet_joblib_cancel()

    par = Parallel(n_jobs=n_jobs, backend="loky", return_as="generator_unordered",
                   batch_size=1, pre_dispatch="2 * n_jobs")
    calls = (
        delayed(run_local_tasks)(os.getpid(), job.setup, job.run, job.context, job.context_key,
                                 [(i, job.tasks[i]) for i in piece])
        for piece in chunks(todo, n_jobs)
    )
    with children_deaf_to_ctrl_c():  # (the workers start in this call)
        batches = par(calls)
    for batch in batches:
        yield from batch


def _dask(job: Job, todo: list[int], address: str) -> Iterator[tuple[int, dict]]:
    from dask.distributed import as_completed

    client = connect(address)
    futures: list = []
    try:
        try:
            client.wait_for_workers(1, timeout=WORKER_WAIT_S)
        except (OSError, TimeoutError):
            raise KbcliError(
                f"the Dask scheduler at {address} has no workers (waited {WORKER_WAIT_S:g} s); "
                "start some with: dask worker " + address
            ) from None
        ctx = client.scatter(job.context, broadcast=True, hash=False)
        info = client.scheduler_info().get("workers", {})
        workers = max(1, sum(int(w.get("nthreads", 1)) for w in info.values()))
        pieces = chunks(todo, workers)
        n = len(pieces)
        futures = client.map(
            run_tasks,
            [job.setup] * n,
            [job.run] * n,
            [ctx] * n,
            [job.context_key] * n,
            [[(i, job.tasks[i]) for i in piece] for piece in pieces],
            key=[f"kbcli-{job.context_key[:12]}-{piece[0]}-{uuid.uuid4().hex[:8]}"
                 for piece in pieces],
            pure=False,
        )
        for fut in as_completed(futures, loop=client.loop):
            try:
                batch = fut.result()
            except ModuleNotFoundError as exc:
                raise KbcliError(
                    f"a Dask worker could not import {exc.name!r}: install kbcli in the workers' "
                    "environment"
                ) from None
            fut.release()
            yield from batch
    finally:
        with contextlib.suppress(Exception):
            client.cancel(futures)
        with contextlib.suppress(Exception):
            client.close(timeout=5)


def execute(
    job: Job, todo: Iterable[int], *, jobs: int = 1, scheduler: str | None = None
) -> Iterator[tuple[int, dict]]:
    """Run experiments ``todo`` (indices into ``job.tasks``), yielding ``(index, result)`` as they
    finish (in any order).

    Parameters
    ----------
    jobs : int
        1: in this process; N > 1: N local processes (joblib/loky), at most the usable cores
        (:func:`cap_jobs`).
    scheduler : str, optional
        ``tcp://HOST:PORT`` of a running Dask scheduler (overrides ``jobs``).

    Raises
    ------
    ConfigError
        ``jobs < 1`` or a malformed scheduler address.
    KbcliError
        An unreachable scheduler (within :data:`CONNECT_TIMEOUT_S`), or one without workers.
    """
    todo = list(todo)
    if not isinstance(jobs, int) or jobs < 1:
        raise ConfigError(f"--jobs must be a whole number >= 1, got {jobs!r}")
    if scheduler is not None:
        check_scheduler_address(scheduler)
        if not todo:
            return iter(())
        return _dask(job, todo, scheduler)
    if not todo:
        return iter(())
    jobs, _ = cap_jobs(jobs)  # (the CLI says so; results do not depend on the worker count)
    if jobs == 1:
        return _serial(job, todo)
    return _local(job, todo, jobs)
