"""
Read-only arrays for the compiled kernels: one compiled variant per kernel, whatever the input.

numba compiles a kernel once per set of argument types, and whether an array is writable is
part of its type. A trace's columns are read-only (:class:`~mapmatch.trace.Trace`), while
what stands in for a missing column, or a column the model computes instead (a speed from
positions, times of a trace whose own are implausible), is a fresh, writable array. Mixed
freely, every set of columns a user may send would need a variant of its own: 2 to the
number of optional columns, more than a warm-up compiles, so a request of a kind it missed
waited half a minute for the compiler. The model hands its kernels the per-fix arrays
read-only always (:func:`read_only`, :data:`EMPTY_FLOAT`, :data:`EMPTY_INT`), so that the
warm-up's variant serves every input.
"""

from __future__ import annotations

from typing import Any, TypeVar, cast

import numpy as np
import numpy.typing as npt

__all__ = ["EMPTY_FLOAT", "EMPTY_INT", "kernel_array", "kernel_column", "read_only"]

_A = TypeVar("_A", bound=npt.NDArray[Any])


def read_only(array: _A) -> _A:
    """
    ``array`` if it is read-only, else a read-only view of it (the caller's stays writable).

    Examples
    --------
    >>> a = np.zeros(3)
    >>> read_only(a).flags.writeable, a.flags.writeable
    (False, True)
    >>> b = read_only(a)
    >>> read_only(b) is b
    True
    """
    if not array.flags.writeable:
        return array
    view = array.view()
    view.flags.writeable = False
    return view


def kernel_array(values: npt.ArrayLike, dtype: npt.DTypeLike = np.float64) -> npt.NDArray[Any]:
    """
    ``values`` as a kernel takes an array: contiguous, of ``dtype``, read-only.

    No copy where ``values`` already is one (a trace's column); a read-only view of a
    writable one (the caller's stays writable).

    Examples
    --------
    >>> a = kernel_array([1, 2])
    >>> a, a.flags.writeable
    (array([1., 2.]), False)
    >>> kernel_array(a) is a
    True
    """
    return read_only(np.ascontiguousarray(values, dtype))


def kernel_column(values: npt.ArrayLike | None, missing: _A) -> _A:
    """
    ``values`` as a kernel takes a column: contiguous, of ``missing``'s dtype, read-only.

    ``missing`` (:data:`EMPTY_FLOAT`, :data:`EMPTY_INT`) stands in where ``values`` is None.

    Examples
    --------
    >>> kernel_column([1, 2], EMPTY_FLOAT)
    array([1., 2.])
    >>> kernel_column(None, EMPTY_INT) is EMPTY_INT
    True
    """
    if values is None:
        return missing
    return cast("_A", kernel_array(values, missing.dtype))


#: What stands in for a missing float column: empty and read-only.
EMPTY_FLOAT = read_only(np.empty(0, dtype=np.float64))

#: What stands in for a missing integer column: empty and read-only.
EMPTY_INT = read_only(np.empty(0, dtype=np.int64))
