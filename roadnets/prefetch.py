"""
A hint to the processor, from compiled code, to start loading an array's item into its caches.

A kernel that reads scattered items of a large array (a route table's records, one per pair
of candidates) waits on each load in turn when each address comes out of the load before it.
Asking for the loads of many items first (:func:`prefetch`), then reading them, lets the
memory answer them together: on the matcher's pairs, read right after another trace's match
(the table no longer in the caches), 13-21 % less time.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, cast

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

__all__ = ["prefetch"]

_I8P = ir.IntType(8).as_pointer()
_I32 = ir.IntType(32)
# LLVM names its intrinsic after the pointer type: ``ptr`` (opaque, LLVM >= 15) or ``i8*``
_NAME = "llvm.prefetch.p0" if str(_I8P) == "ptr" else "llvm.prefetch.p0i8"
_READ, _KEEP_IN_ALL_CACHES, _DATA = 0, 3, 1


@intrinsic
def _prefetch(typingctx: Any, array: Any, index: Any) -> Any:  # pragma: no cover - compiled
    """
    Start loading ``array[index]`` into the caches; nothing is read, nothing can fail.

    For a one-dimensional array and an integer index, in compiled code only. An index outside
    the array is harmless (a prefetch never faults) but wasted.
    """
    if not (
        isinstance(array, types.Array) and array.ndim == 1 and isinstance(index, types.Integer)
    ):
        return None
    sig = types.void(array, index)

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        kind = signature.args[0]
        data = context.make_array(kind)(context, builder, args[0])
        address = cgutils.get_item_pointer(context, builder, kind, data, [args[1]])  # type: ignore[no-untyped-call]
        hint = ir.FunctionType(ir.VoidType(), [_I8P, _I32, _I32, _I32])
        function = cgutils.get_or_insert_function(builder.module, hint, _NAME)  # type: ignore[no-untyped-call]
        builder.call(
            function,
            [builder.bitcast(address, _I8P), _I32(_READ), _I32(_KEEP_IN_ALL_CACHES), _I32(_DATA)],
        )
        return context.get_dummy_value()

    return sig, codegen


if TYPE_CHECKING:
    from collections.abc import Callable

#: :func:`_prefetch` as compiled code calls it (numba passes its typing context itself).
prefetch = cast("Callable[[Any, Any], None]", _prefetch)
