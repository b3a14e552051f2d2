"""Vector products without BLAS, so that a plan is the same on every x86-64 CPU.

numpy's ``@``, ``dot`` and ``linalg.norm`` of a whole vector call OpenBLAS, which picks
its kernels by CPU (SkylakeX on this AMD EPYC, Haswell on an AVX2 machine) and sums in
their order; numba's ``@`` of two vectors calls the same library. Under OpenBLAS's Haswell
kernels (``OPENBLAS_CORETYPE=Haswell``) bench perturbation's n20 seed 1 w 0.8 planned
J 395.81 against 399.15, and a last bit anywhere can send the constrained rounds
elsewhere (issue 28). numpy's own loops (elementwise products, ``sum``, ``einsum``) have
one summation order on every CPU.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ['rows_dot', 'vector_length']


def vector_length(v: ArrayLike) -> float:
    """Euclidean length of a vector [its unit] (``math.hypot``: no BLAS)."""
    return math.hypot(*np.asarray(v, float).ravel())


def rows_dot(m: NDArray, v: NDArray) -> NDArray:
    """``m @ v`` for a matrix (..., k) and a vector (k,) or a matrix (k, j), without BLAS."""
    return np.einsum('...k,k->...', m, v) if np.ndim(v) == 1 else np.einsum('ik,kj->ij', m, v)
