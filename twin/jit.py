"""numba's compilation for the batch engines, kept on disk where numba can write it.

numba caches a compiled function in the first writable place of: ``NUMBA_CACHE_DIR``, the source's own
``__pycache__`` (an editable or user install), the user's cache folder (``~/.cache/numba``: an install the
user cannot write). Where none is writable (a read-only install and home, no ``NUMBA_CACHE_DIR``) numba
refuses ``cache=True`` outright; the function is then compiled in each process instead, with one warning
that says how to keep it. A single run never gets here: only the batch engines compile (``twin.rigs.warm``)."""

from __future__ import annotations

import warnings
from collections.abc import Callable
from typing import Any

__all__ = ["njit_cached"]


def njit_cached(function: Callable[..., Any]) -> Any:
    """``numba.njit(cache=True)(function)``, or ``numba.njit(function)`` where no cache folder is writable."""
    import numba

    try:
        return numba.njit(cache=True)(function)
    except RuntimeError as exc:  # numba's "cannot cache function …: no locator available for file …"
        warnings.warn(
            f"{exc}: {function.__module__}.{function.__name__} is compiled in every process; set "
            "NUMBA_CACHE_DIR to a writable folder to keep it",
            RuntimeWarning,
            stacklevel=2,
        )
        return numba.njit(function)
