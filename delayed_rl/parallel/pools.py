"""Worker pools: picklable tasks run on joblib's ``loky`` pool, on Ray or on Dask.

:func:`iter_tasks` yields each result as its task finishes; :func:`run_tasks` returns them all
in the tasks' order. Every task carries its own seed, so results do not depend on the number of
workers.
"""

from __future__ import annotations

import contextlib
import socket
from collections.abc import Callable, Iterator
from typing import Any

from delayed_rl._validation import Limit, check_choice, check_int, check_limit

#: The joblib backends :func:`run_tasks` can hand the runs to.
BACKENDS = ("loky", "ray", "dask")


MAX_SEED_COUNT = Limit(10_000, "MAX_SEED_COUNT", __name__)
"""The most seeds (runs per condition) an experiment or a sweep runs."""


MAX_WORKERS = Limit(1024, "MAX_WORKERS", __name__, "1024")
"""The most parallel workers asked for (a process or a cluster task each)."""


def check_workers(name: str, workers: Any) -> int:
    """Return ``workers``, an integer in ``[1, MAX_WORKERS]``, after checking it.

    Raises:
        TypeError: it is not an integer.
        ValueError: it is below 1 or above :data:`MAX_WORKERS`.
    """
    return check_limit(name, check_int(name, workers, 1), MAX_WORKERS)


def process_pool(processes: int) -> Any:
    """A pool of ``processes`` local processes for calls made one by one (``submit``).

    loky's ``ProcessPoolExecutor``, which carries closures to its processes (cloudpickle);
    ``shutdown(wait=..., kill_workers=...)`` ends it. The experiments write their files with it
    while the runs go on.
    """
    from joblib.externals.loky import ProcessPoolExecutor

    return ProcessPoolExecutor(max_workers=check_workers("processes", processes))


def run_tasks(
    run_task: Callable[[dict], dict],
    tasks: list[dict],
    workers: int | None,
    backend: str,
    address: str | None = None,
) -> list[dict]:
    """Run ``tasks`` with ``workers`` processes on ``backend``; return the results in their order.

    See :func:`iter_tasks` for the arguments and errors.
    """
    results: list[Any] = [None] * len(tasks)
    for index, result in iter_tasks(run_task, tasks, workers, backend, address):
        results[index] = result
    return results


def iter_tasks(
    run_task: Callable[[dict], dict],
    tasks: list[dict],
    workers: int | None,
    backend: str,
    address: str | None = None,
) -> Iterator[tuple[int, dict]]:
    """Run ``tasks`` in parallel: an iterator of ``(index, result)``, one as each task finishes.

    Results come in the order the tasks finish, so a caller can keep each as soon as it is
    done. ``loky`` and ``dask`` run through joblib; ``ray`` through Ray's own tasks (one CPU
    each), as its joblib backend returns nothing before every task is done. The arguments are
    checked at once; the backend starts (a local Ray or Dask cluster, the connection to one at
    ``address``) when the first result is asked for.

    Args:
        run_task: a picklable function of one task (a module's top-level function).
        tasks: the tasks.
        workers: how many tasks run at once; ``None``: as many as the backend has cores. With
            ``backend="loky"`` and 1 worker the tasks run in this process, one after another.
        backend: ``"loky"`` (joblib's process pool on this machine), ``"ray"`` or ``"dask"``.
        address: a running cluster of ``backend`` to send the tasks to. Ray:
            ``ray.init(address=address)`` (e.g. ``"auto"``, ``"ray://host:10001"``), unless Ray
            is initialized already in this process, which is then used as it is; without an
            address, ``ray.init()`` starts a local Ray (or the one initialized is used).
            Dask: a ``Client(address)`` of the scheduler (e.g. ``"tcp://host:8786"``), closed
            afterwards (not the cluster); without one, a local cluster of ``workers``
            processes that lives as long as the tasks.

    Raises:
        TypeError: ``workers`` is not an integer (or ``None``), ``backend`` or ``address`` not a
            string.
        ValueError: ``workers`` < 1, ``backend`` is not one of :data:`BACKENDS`, or an
            ``address`` is given for ``loky``.
        RuntimeError: the backend's package (Ray, Dask) is not installed, or the backend
            could not start (or reach the cluster at ``address``): the message names the
            backend and the error it raised. Raised when the first result is asked for.
    """
    check_choice("backend", backend, BACKENDS)
    if workers is not None:
        check_workers("workers", workers)
    if address is not None:
        if not isinstance(address, str):
            raise TypeError(f"address must be a string, got {address!r} ({type(address).__name__})")
        if backend == "loky":
            raise ValueError(f"address is for the ray and dask backends, not {backend!r}")
    if workers == 1 and backend == "loky":
        return _in_process_results(run_task, tasks)
    if backend == "ray":
        return _ray_results(run_task, tasks, workers, address)
    return _joblib_results(run_task, tasks, workers, backend, address)


def _in_process_results(
    run_task: Callable[[dict], dict], tasks: list[dict]
) -> Iterator[tuple[int, dict]]:
    """:func:`iter_tasks` in this process, one task after another."""
    for index, task in enumerate(tasks):
        yield index, run_task(task)


def _indexed(run_task: Callable[[dict], dict], index: int, task: dict) -> tuple[int, dict]:
    """``(index, run_task(task))``: a result that says which task it is."""
    return index, run_task(task)


def _joblib_results(
    run_task: Callable[[dict], dict],
    tasks: list[dict],
    workers: int | None,
    backend: str,
    address: str | None,
) -> Iterator[tuple[int, dict]]:
    """:func:`iter_tasks` on joblib's ``loky`` or ``dask`` backend."""
    import joblib

    with contextlib.ExitStack() as cleanup:
        if backend == "dask":
            cleanup.enter_context(_dask_client(workers, address))  # closed after
        with joblib.parallel_config(backend=backend, n_jobs=-1 if workers is None else workers):
            parallel = joblib.Parallel(return_as="generator_unordered")
            calls = (joblib.delayed(_indexed)(run_task, i, task) for i, task in enumerate(tasks))
            yield from parallel(calls)


def _dask_client(workers: int | None, address: str | None) -> Any:
    """A Dask client of the scheduler at ``address``, else of a local cluster of ``workers``."""
    try:
        from dask.distributed import Client
    except ImportError as error:
        raise RuntimeError("backend 'dask' needs Dask: pip install 'dask[distributed]'") from error
    try:
        if address is not None:
            return Client(address)  # closing it leaves the cluster, which is not ours, running
        return Client(processes=True, n_workers=workers)
    except Exception as error:  # Dask raises OSError, TimeoutError, ValueError...
        raise RuntimeError(_not_started("dask", address, error)) from error


#: How long a cluster's address may take to answer before the backend is said not to start.
CONNECT_TIMEOUT = 10.0


def _check_reachable(backend: str, address: str | None) -> None:
    """Refuse at once a ``host:port`` (or ``ray://host:port``) address that nobody answers.

    (Ray's own connection waits for minutes for an address that does not answer.) Other
    addresses (``"auto"``, ``None``) are left to the backend.

    Raises:
        RuntimeError: nothing accepted a TCP connection at the address within
            :data:`CONNECT_TIMEOUT` seconds.
    """
    if address is None:
        return
    host, _, port = address.removeprefix(f"{backend}://").rpartition(":")
    if not host or not port.isdigit():
        return
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=CONNECT_TIMEOUT).close()
    except (OSError, ValueError, OverflowError) as error:
        raise RuntimeError(_not_started(backend, address, error)) from None


def _not_started(backend: str, address: str | None, error: BaseException) -> str:
    """The message for a backend that could not start (or reach the cluster at ``address``)."""
    where = f"the cluster at {address!r}" if address is not None else "a local cluster"
    reason = " ".join(str(error).split()) or type(error).__name__
    return f"backend {backend!r} could not start on {where}: {type(error).__name__}: {reason}"


def _ray_results(
    run_task: Callable[[dict], dict], tasks: list[dict], workers: int | None, address: str | None
) -> Iterator[tuple[int, dict]]:
    """:func:`iter_tasks` on Ray: at most ``workers`` tasks in flight (``None``: all of them)."""
    try:
        import ray
    except ImportError as error:
        raise RuntimeError("backend 'ray' needs Ray: pip install 'ray[default]'") from error
    if not ray.is_initialized():
        _check_reachable("ray", address)
        try:
            ray.init(address=address)
        except Exception as error:  # Ray raises ConnectionError, RuntimeError, plain Exception...
            raise RuntimeError(_not_started("ray", address, error)) from error
    remote = ray.remote(num_cpus=1)(_indexed)
    waiting = list(enumerate(tasks))[::-1]
    running: list[Any] = []
    try:
        while waiting or running:
            while waiting and (workers is None or len(running) < workers):
                running.append(remote.remote(run_task, *waiting.pop()))
            done, running = ray.wait(running, num_returns=1)
            try:
                yield ray.get(done[0])
            except ray.exceptions.RayTaskError as error:
                raise error.cause from None  # the task's own exception, not Ray's wrapper
    finally:
        for ref in running:
            ray.cancel(ref)
