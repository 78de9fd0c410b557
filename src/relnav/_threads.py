"""BLAS thread control.

relnav's per-frame work is small dense linear algebra (descriptor matrix products, 3×3 SVDs,
12×12 filter updates). Multi-threaded BLAS makes such calls *slower* — on a busy 2-core machine a
150×40 float32 matrix product took 23 ms with 2 OpenBLAS threads and 0.05 ms with one — so the
sequential loops (odometry, tracking) run with one BLAS thread, and parallelism comes from
running sequences/seeds side by side (DESIGN §7).
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

__all__ = ["limit_blas_threads"]


@contextlib.contextmanager
def limit_blas_threads(n: int | None = 1) -> Iterator[None]:
    """Context manager limiting BLAS/OpenMP threads to ``n`` (``None``: leave unchanged)."""
    if n is None:
        yield
        return
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=int(n), user_api="blas"):
        yield
