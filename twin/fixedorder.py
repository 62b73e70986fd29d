"""Products of the tick in a fixed order: the same bits under any BLAS kernel, alone and over a batch.

numpy's ``@``, ``dot``, ``matmul`` and ``einsum`` hand even 2–21-element products to BLAS, whose kernel (chosen
by the CPU or ``OPENBLAS_CORETYPE``) decides the summation order and whether a multiply-add is fused: the
same run gave different last bits under OpenBLAS's Haswell and SkylakeX kernels. Here every sum of products
is taken left to right, each product rounded, then each sum (IEEE +, ×: no fused multiply-add), in two
forms with the same bits:

* scalar, on Python floats (``dot``, ``matvec``, ``total``): the single run;
* elementwise numpy over a leading batch axis (``dots``, ``matvecs``): column k of every row is added in
  the k-th ufunc call, so each row gets the scalar form's bits (numpy's ``add.reduce`` is pairwise, not
  left to right, and is not used).

Design-time linear algebra (pole placement, ``expm``, ``eig``, LQR) is not per tick and stays numpy's.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["dot", "dots", "matvec", "matvecs", "total"]


def dot(a: Sequence[float], b: Sequence[float]) -> float:
    """a₀·b₀ + a₁·b₁ + … added left to right (Python floats; ``len(a) == len(b) ≥ 1``)."""
    acc = a[0] * b[0]
    for i in range(1, len(a)):
        acc += a[i] * b[i]
    return acc


def total(values: Sequence[float]) -> float:
    """v₀ + v₁ + … left to right (Python's ``sum`` of floats is compensated from 3.12 on: not this)."""
    acc = values[0]
    for i in range(1, len(values)):
        acc += values[i]
    return acc


def matvec(matrix: Sequence[Sequence[float]], v: Sequence[float]) -> list[float]:
    """``dot`` of each row of ``matrix`` with ``v``."""
    return [dot(row, v) for row in matrix]


def dots(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``dot`` along the last axis, elementwise over the leading ones: a (..., k), b (k,) or (..., k)."""
    k = a.shape[-1]
    if b.shape[-1] != k or k < 1:
        raise ValueError(f"dots: last axes {a.shape} and {b.shape} must match and be non-empty")
    acc = a[..., 0] * b[..., 0]
    for i in range(1, k):
        acc = acc + a[..., i] * b[..., i]
    return acc


def matvecs(matrix: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``matvec`` for each row of ``v`` (n, c): ``matrix`` (r, c) for all runs or (n, r, c) per run; (n, r)."""
    return dots(matrix[None, :, :] if matrix.ndim == 2 else matrix, v[:, None, :])
