"""Run independent tasks serially, on local worker processes or on Ray tasks.

:func:`map_tasks` applies a picklable top-level function to a list of task specs (plain
dataclasses or dicts holding seeds and settings) and returns the results in task order:

- ``workers=1`` (and no Ray address): in this process, one task after the other;
- ``workers=N``: on N local worker processes (``concurrent.futures.ProcessPoolExecutor``
  with the ``forkserver`` start method: a worker is forked from a clean server process, not
  from this one, so it inherits no MuJoCo/EGL context, torch thread pool or open file);
- ``ray_address`` given: as plain Ray tasks (``ray.remote``; the ``distributed`` extra), at
  most ``workers`` in flight: ``"local"`` starts a Ray instance on this machine with
  ``workers`` CPUs, ``"auto"`` joins the cluster ``ray start --head`` started here, and
  ``"ray://host:port"`` (Ray Client) or ``"host:port"`` a remote one.

Every task builds what it needs (an env from a seed) itself, so the results are the same
for any number of workers. Each task runs on one BLAS/OpenMP/torch thread, in a worker (N
workers on N cores, not N x N threads) and serially alike: torch's convolutions sum in
another order on two threads than on one, which moved a closed-loop episode's belief by
0.2 mm, so a serial run on torch's default threads did not equal a parallel one.
"""

from __future__ import annotations

import atexit
import concurrent.futures as cf
import multiprocessing
import os
import socket
import sys
from collections.abc import Callable, Hashable, Iterator, Sequence
from contextlib import contextmanager
from typing import Any, TypeVar
from urllib.parse import urlsplit

from tqdm.auto import tqdm

__all__ = ["DISTRIBUTED_EXTRA", "RAY_ADDRESS_HELP", "WORKERS_HELP", "check_ray_address",
           "check_workers", "close_worker_env", "import_ray", "limit_threads", "map_tasks",
           "worker_env"]

T = TypeVar("T")
R = TypeVar("R")

#: how to install Ray, quoted by the errors
DISTRIBUTED_EXTRA = "pip install 'appearance-nav[distributed]' (or: pip install 'ray>=2.9')"
#: seconds to wait for a Ray head's port before calling the address unreachable
CONNECT_TIMEOUT = 5.0
#: Ray's own connection budgets (Ray Client: 3 tries of 3 s; a GCS address: 5 tries of ~1 s;
#: Ray's defaults wait ~30 s and ~20 s); a value already in the environment wins
RAY_CLIENT_TIMEOUTS = {"RAY_CLIENT_INITIAL_CONNECTION_TIMEOUT_S": "3",
                       "RAY_CLIENT_MAX_CONNECTION_TIMEOUT_S": "3"}
RAY_GCS_TIMEOUT = {"RAY_gcs_server_port_wait_time_s": "5"}
#: the environment variables that size the BLAS / OpenMP thread pools of a worker
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                    "NUMEXPR_NUM_THREADS", "VECLIB_MAXIMUM_THREADS")

_limited = False  # this process already runs on one thread (a worker)

#: the help of the ``--workers`` options
WORKERS_HELP = ("worker processes (1: this process); with --ray-address, Ray tasks in flight; "
                "the results do not depend on it")
#: the help of the ``--ray-address`` options
RAY_ADDRESS_HELP = ("run on Ray (the distributed extra): 'local' (a Ray instance here), 'auto' "
                    "(the cluster of `ray start --head`) or 'ray://host:port'; empty: no Ray")


def check_workers(workers: object, name: str = "workers") -> int:
    """``workers`` as a positive int; ``TypeError`` / ``ValueError`` naming ``name``."""
    if isinstance(workers, bool) or not isinstance(workers, int):
        raise TypeError(f"{name} must be a positive integer, got {workers!r} "
                        f"({type(workers).__name__})")
    if workers < 1:
        raise ValueError(f"{name} must be a positive integer (1: no parallelism), got {workers}")
    return workers


def check_ray_address(address: object, name: str = "ray_address") -> str:
    """``address`` as a stripped string: "" (no Ray), "local", "auto", "ray://host:port" or
    "host:port"; ``TypeError`` / ``ValueError`` naming ``name`` otherwise."""
    if address is None:
        return ""
    if not isinstance(address, str):
        raise TypeError(f"{name} must be a string, got {type(address).__name__}")
    address = address.strip()
    if address in ("", "local", "auto"):
        return address
    if _host_port(address) is None:
        raise ValueError(f"{name} must be 'local', 'auto', 'ray://host:port' or 'host:port', "
                         f"got {address!r}")
    return address


def _host_port(address: str) -> tuple[str, int] | None:
    """``(host, port)`` of "ray://host:port" or "host:port", or None if malformed."""
    parts = urlsplit(address if "://" in address else "ray://" + address)
    try:
        port = parts.port
    except ValueError:
        return None
    if parts.scheme != "ray" or not parts.hostname or port is None or parts.path not in ("", "/"):
        return None
    return parts.hostname, port


def import_ray(name: str = "ray_address") -> Any:
    """The ``ray`` module, or an ``ImportError`` naming ``name`` and the extra to install."""
    for var, value in RAY_CLIENT_TIMEOUTS.items():  # read when Ray Client is imported
        os.environ.setdefault(var, value)
    try:
        import ray
    except ImportError as err:
        raise ImportError(f"{name} needs Ray, which is not installed: {DISTRIBUTED_EXTRA}"
                          ) from err
    return ray


def limit_threads() -> None:
    """Make this process use one BLAS / OpenMP / torch thread (idempotent; run in workers)."""
    global _limited
    if _limited:
        return
    for var in THREAD_VARIABLES:
        os.environ[var] = "1"  # libraries loaded from now on
    from threadpoolctl import threadpool_limits
    threadpool_limits(1)  # the ones already loaded (numpy's BLAS)
    if "torch" in sys.modules:
        sys.modules["torch"].set_num_threads(1)
    _limited = True


@contextmanager
def one_thread() -> Iterator[None]:
    """Run the block on one BLAS / OpenMP / torch thread, as a worker does (restored after;
    torch is imported here, since a task may import it later)."""
    import torch
    from threadpoolctl import threadpool_limits

    old = torch.get_num_threads()
    with threadpool_limits(1):
        torch.set_num_threads(1)
        try:
            yield
        finally:
            torch.set_num_threads(old)


def _call(fn: Callable[[T], R], task: T) -> R:
    """``fn(task)`` on one thread: what a worker (process or Ray task) runs."""
    limit_threads()
    return fn(task)


def map_tasks(fn: Callable[[T], R], tasks: Sequence[T], workers: int = 1,
              ray_address: str | None = None, progress: bool = True, desc: str = "tasks",
              ) -> list[R]:
    """``[fn(task) for task in tasks]``, serially, on local processes or on Ray.

    Parameters
    ----------
    fn : a picklable top-level function of one task spec.
    tasks : the task specs (picklable: dataclasses or dicts of seeds and settings).
    workers : int >= 1 — worker processes (1 and no ``ray_address``: this process); with
        ``ray_address``, the Ray tasks in flight at once.
    ray_address : None or "" (no Ray), "local", "auto", "ray://host:port" or "host:port"
        (see the module docstring).
    progress : bool — a tqdm bar over the completed tasks.
    desc : str — the bar's label.

    Returns
    -------
    list — ``fn(task)`` for each task, in task order.

    Raises
    ------
    TypeError, ValueError
        If ``workers`` is not a positive integer or ``ray_address`` is malformed.
    ImportError
        If ``ray_address`` is given and Ray is not installed (names the extra).
    ConnectionError
        If no Ray cluster answers at ``ray_address`` (within a few seconds).
    """
    workers = check_workers(workers)
    address = check_ray_address(ray_address)
    tasks = list(tasks)
    if not callable(fn):
        raise TypeError(f"fn must be callable, got {type(fn).__name__}")
    bar = tqdm(total=len(tasks), desc=desc, disable=not progress, leave=False)
    try:
        if address:
            return _map_ray(fn, tasks, workers, address, bar)
        if workers == 1 or len(tasks) <= 1:
            with one_thread():  # as in a worker: the same sums, the same results
                return [_step(bar, fn(task)) for task in tasks]
        return _map_processes(fn, tasks, workers, bar)
    finally:
        bar.close()


def _step(bar: tqdm, result: R) -> R:
    bar.update()
    return result


def _map_processes(fn: Callable[[T], R], tasks: list[T], workers: int, bar: tqdm) -> list[R]:
    """The tasks on ``min(workers, len(tasks))`` forkserver worker processes (the server,
    started once per process, imports ``fn``'s module so that each worker starts warm)."""
    context = multiprocessing.get_context("forkserver")
    module = getattr(fn, "__module__", None)
    if module and module != "__main__":
        context.set_forkserver_preload([module])  # no effect once the server runs
    with cf.ProcessPoolExecutor(min(workers, len(tasks)), mp_context=context,
                                initializer=limit_threads) as pool:
        futures = [pool.submit(_call, fn, task) for task in tasks]
        try:
            for future in cf.as_completed(futures):
                future.result()  # raise the first failure now
                bar.update()
        except BaseException:
            for future in futures:
                future.cancel()
            raise
        return [future.result() for future in futures]


def _map_ray(fn: Callable[[T], R], tasks: list[T], workers: int, address: str,
             bar: tqdm) -> list[R]:
    """The tasks as Ray tasks (one CPU each), at most ``workers`` in flight."""
    ray = import_ray()
    with _ray_session(ray, address, workers):
        remote = ray.remote(num_cpus=1)(_call)
        fn_ref = ray.put(fn)
        refs: list[Any] = []
        pending: list[Any] = []
        for task in tasks:
            if len(pending) >= workers:
                done, pending = ray.wait(pending, num_returns=1)
                ray.get(done)  # raise the first failure now
                bar.update(len(done))
            ref = remote.remote(fn_ref, task)
            refs.append(ref)
            pending.append(ref)
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            ray.get(done)
            bar.update(len(done))
        return ray.get(refs)


@contextmanager
def _ray_session(ray: Any, address: str, workers: int) -> Iterator[None]:
    """Use the running Ray session, or connect (start one for "local") and disconnect after."""
    if ray.is_initialized():
        yield
        return
    if address == "local":
        ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False)
    else:
        _check_reachable(address)
        try:
            with _environ(RAY_GCS_TIMEOUT):
                ray.init(address=address, log_to_driver=False)
        except (ConnectionError, RuntimeError, TimeoutError) as err:
            raise ConnectionError(f"ray_address {address!r}: cannot connect to a Ray cluster "
                                  f"({err}); start one with `ray start --head`") from err
    try:
        yield
    finally:
        ray.shutdown()


@contextmanager
def _environ(values: dict[str, str]) -> Iterator[None]:
    """Set the environment variables not set yet, for the ``with`` block."""
    added = {k: v for k, v in values.items() if k not in os.environ}
    os.environ.update(added)
    try:
        yield
    finally:
        for k in added:
            os.environ.pop(k, None)


def _check_reachable(address: str) -> None:
    """A TCP connection to a "host:port" address opens within :data:`CONNECT_TIMEOUT`
    (Ray itself retries for a long time), else ``ConnectionError`` naming the address."""
    host_port = _host_port(address)
    if host_port is None:  # "auto": Ray finds the local cluster or fails fast
        return
    try:
        socket.create_connection(host_port, timeout=CONNECT_TIMEOUT).close()
    except OSError as err:
        raise ConnectionError(f"ray_address {address!r}: no Ray cluster answers at "
                              f"{host_port[0]}:{host_port[1]} ({err}); start one with "
                              "`ray start --head` or check the address") from None


_WORKER_ENV: dict[Hashable, Any] = {}


def worker_env(key: Hashable, make: Callable[[], Any]) -> Any:
    """This process's env for ``key``, made by ``make()`` when the key changes.

    A task runner of :func:`map_tasks` calls it for the env its episodes need: consecutive
    tasks with the same ``key`` (settings, city, condition, pose source) share one env, and a
    new key closes the previous env first. One env per process: an env holds a renderer, a
    filter and moving things (~100 MB), and a worker that kept every row's env of the
    robustness benchmark was killed out of memory at 6 GB.
    """
    if key not in _WORKER_ENV:
        close_worker_env()
        _WORKER_ENV[key] = make()
    return _WORKER_ENV[key]


@atexit.register
def close_worker_env() -> None:
    """Close the env :func:`worker_env` keeps (also at exit)."""
    while _WORKER_ENV:
        _WORKER_ENV.popitem()[1].close()
