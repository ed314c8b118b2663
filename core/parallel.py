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
off), else the number of CPUs this process may use, at most 4. A chunk that itself calls
:func:`pmap` runs its inner chunks serially (no nested pools, no deadlock).
"""

from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor
from typing import Callable, Iterable, Sequence, TypeVar

__all__ = ["thread_count", "pmap", "row_blocks"]

T = TypeVar("T")
R = TypeVar("R")

MAX_THREADS = 4

_pool: ThreadPoolExecutor | None = None
_pool_size = 0
_pool_lock = threading.Lock()
_inside = threading.local()


def thread_count() -> int:
    """Threads to use: ``TCB_THREADS`` if set (at least 1), else the usable CPUs (at most 4)."""
    env = os.environ.get("TCB_THREADS", "").strip()
    if env:
        try:
            return max(1, int(env))
        except ValueError:
            raise ValueError(f"TCB_THREADS must be a whole number, got {env!r}") from None
    try:
        cpus = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        cpus = os.cpu_count() or 1
    return max(1, min(MAX_THREADS, cpus))


def _executor(n: int) -> ThreadPoolExecutor:
    global _pool, _pool_size
    with _pool_lock:
        if _pool is None or _pool_size != n:
            if _pool is not None:
                _pool.shutdown(wait=False)
            _pool = ThreadPoolExecutor(n, thread_name_prefix="tcb")
            _pool_size = n
        return _pool


def _run_marked(fn: Callable[[T], R], item: T) -> R:
    _inside.active = True
    try:
        return fn(item)
    finally:
        _inside.active = False


def pmap(fn: Callable[[T], R], items: Iterable[T]) -> list[R]:
    """``[fn(x) for x in items]``, the items spread over :func:`thread_count` threads.

    Serial when there is one item, one thread, or when called from inside a chunk. The first
    exception raised by a chunk is re-raised here.
    """
    items = list(items)
    n = thread_count()
    if n <= 1 or len(items) <= 1 or getattr(_inside, "active", False):
        return [fn(x) for x in items]
    pool = _executor(n)
    return list(pool.map(lambda x: _run_marked(fn, x), items))


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
