"""Thread control: BLAS threads and the pool of independent registrations.

relnav's per-frame work is small dense linear algebra (descriptor matrix products, 3×3 SVDs,
12×12 filter updates). Multi-threaded BLAS makes such calls *slower* — on a busy 2-core machine a
150×40 float32 matrix product took 23 ms with 2 OpenBLAS threads and 0.05 ms with one — so the
sequential loops (odometry, tracking) run with one BLAS thread, and parallelism comes from
running sequences/seeds side by side (DESIGN §7). The one exception is opt-in: independent
compiled registrations of one frame that release the interpreter (the navigator's extra starts
under attitude jitter, ``solver.threads``) can share a :func:`thread_pool`.
"""

from __future__ import annotations

import contextlib
import os
import threading
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor

__all__ = ["limit_blas_threads", "thread_pool", "usable_cores"]

_POOLS: dict[tuple[int, int], ThreadPoolExecutor] = {}
_POOLS_LOCK = threading.Lock()


@contextlib.contextmanager
def limit_blas_threads(n: int | None = 1) -> Iterator[None]:
    """Context manager limiting BLAS/OpenMP threads to ``n`` (``None``: leave unchanged)."""
    if n is None:
        yield
        return
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=int(n), user_api="blas"):
        yield


def usable_cores() -> int:
    """The cores this process may run on (its CPU affinity where the OS tells it)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def thread_pool(n: int) -> ThreadPoolExecutor | None:
    """A shared pool of ``n`` worker threads (``0``: :func:`usable_cores`), or ``None`` when that
    is one thread (run in the caller's). One pool per size and process: a forked child makes its
    own instead of using its parent's threads, which it does not have."""
    n = usable_cores() if n <= 0 else int(n)
    if n <= 1:
        return None
    key = (os.getpid(), n)
    with _POOLS_LOCK:
        pool = _POOLS.get(key)
        if pool is None:
            pool = _POOLS[key] = ThreadPoolExecutor(n, thread_name_prefix="relnav-register")
    return pool
