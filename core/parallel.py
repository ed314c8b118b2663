"""Run independent chunks of array work on a few threads.

numpy's ufunc loops, fancy indexing, sorting and ``bincount`` (and scipy's KD-tree queries)
release the GIL, so the per-chunk work of the engine (basis evaluation over (point,
configuration) pairs, link-triangulation costs, local PCA of neighbourhoods) runs in parallel on
threads without copying data between processes. Measured on the 2-core CI machine: evaluating a
4258-function quadratic space at 1e5 points took 0.86 s on one thread and 0.46 s on two
(``benchmarks/bench_fit.py`` gives the effect on whole fits).

Results never depend on the number of threads: chunks are computed independently and returned
in order, and callers combine them in that order (the same floating-point operations as a serial
run, so the same bits).

The number of threads is ``TCB_THREADS`` from the environment if set (``1`` switches threading
off; a value that is not a whole number is ignored with a warning), else the number of CPUs
this process may use, at most 4. A chunk that itself calls :func:`pmap` runs its inner chunks
serially (no nested waits, no deadlock). The workers are daemon threads, so quitting the
interpreter (or Blender) in the middle of a fit does not wait for queued chunks, and a process
forked after a pool was made builds its own.
"""

from __future__ import annotations

import os
import queue
import threading
import warnings
from concurrent.futures import Future
from typing import Callable, Iterable, Sequence, TypeVar

__all__ = ["thread_count", "pmap", "row_blocks", "background"]

T = TypeVar("T")
R = TypeVar("R")

MAX_THREADS = 4

_pools: dict = {}  # thread count -> task queue served by that many daemon threads
_pools_lock = threading.Lock()
_inside = threading.local()
_warned: set = set()  # the values of TCB_THREADS warned of


def thread_count() -> int:
    """Threads to use: ``TCB_THREADS`` if set (at least 1), else the usable CPUs (at most 4)."""
    env = os.environ.get("TCB_THREADS", "").strip()
    if env:
        try:
            return max(1, int(env))
        except ValueError:
            if env not in _warned:  # once per value (a fit asked three times: user test)
                _warned.add(env)
                warnings.warn(f"TCB_THREADS must be a whole number, got {env!r}; ignoring it",
                              RuntimeWarning, stacklevel=2)
    try:
        cpus = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        cpus = os.cpu_count() or 1
    return max(1, min(MAX_THREADS, cpus))


def _serve(tasks: queue.SimpleQueue) -> None:
    _inside.active = True  # a pmap inside a chunk runs serially
    while True:
        fn, item, fut = tasks.get()
        if not fut.set_running_or_notify_cancel():
            continue
        try:
            fut.set_result(fn(item))
        except BaseException as exc:  # handed to the caller
            fut.set_exception(exc)


def _queue(n: int) -> queue.SimpleQueue:
    """The task queue of the pool of ``n`` daemon threads (made on first use; pools of other
    sizes stay, idle, so a caller that still holds one is never cut off)."""
    with _pools_lock:
        tasks = _pools.get(n)
        if tasks is None:
            tasks = queue.SimpleQueue()
            for i in range(n):
                threading.Thread(target=_serve, args=(tasks,), name=f"tcb-{n}-{i}",
                                 daemon=True).start()
            _pools[n] = tasks
        return tasks


def _forget_pools() -> None:  # in a forked child the parent's threads do not exist
    global _pools_lock
    _pools.clear()
    _pools_lock = threading.Lock()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_pools)


def pmap(fn: Callable[[T], R], items: Iterable[T]) -> list[R]:
    """``[fn(x) for x in items]``, the items spread over :func:`thread_count` threads.

    Serial when there is one item, one thread, or when called from inside a chunk. If chunks
    raise, the exception of the first failing one in item order is re-raised here (once every
    chunk has finished).
    """
    items = list(items)
    n = thread_count()
    if n <= 1 or len(items) <= 1 or getattr(_inside, "active", False):
        return [fn(x) for x in items]
    tasks = _queue(n)
    futures = []
    for x in items:
        fut: Future = Future()
        tasks.put((fn, x, fut))
        futures.append(fut)
    errors = [f.exception() for f in futures]  # waits for all
    for err in errors:
        if err is not None:
            raise err
    return [f.result() for f in futures]


def background(fn: Callable[[], R]) -> Callable[[], R]:
    """``fn()`` started on a daemon thread of its own, for work that releases the GIL (qhull,
    KD-trees) and whose result is needed later: returns ``get()``, which waits for the result
    (and re-raises what ``fn`` raised). Not in the :func:`pmap` pool, whose chunks would queue
    behind it. With one thread (``TCB_THREADS=1``) or from inside a chunk, ``fn`` runs on the
    first ``get()``, on the thread that calls it."""
    if thread_count() <= 1 or getattr(_inside, "active", False):
        lock, done = threading.Lock(), []

        def get() -> R:
            with lock:
                if not done:
                    done.append(fn())
            return done[0]

        return get
    fut: Future = Future()

    def run() -> None:
        fut.set_running_or_notify_cancel()
        try:
            fut.set_result(fn())
        except BaseException as exc:  # handed to whoever asks for the result
            fut.set_exception(exc)

    threading.Thread(target=run, name="tcb-background", daemon=True).start()
    return fut.result


def row_blocks(n: int, min_rows: int = 4096, per_thread: int = 2) -> Sequence[tuple[int, int]]:
    """Split ``range(n)`` into contiguous ``(start, stop)`` blocks for :func:`pmap`: about
    ``per_thread`` blocks per thread (balances uneven chunks), none smaller than ``min_rows``
    (thread hand-off costs ~0.1 ms), one block when threading is off."""
    threads = thread_count()
    if n <= 0:
        return []
    count = max(1, min(threads * per_thread if threads > 1 else 1, n // max(min_rows, 1)))
    bounds = [round(i * n / count) for i in range(count + 1)]
    return [(bounds[i], bounds[i + 1]) for i in range(count) if bounds[i + 1] > bounds[i]]
