"""Software prefetch from compiled kernels (numba): ``llvm.prefetch`` on an array's row.

A gather whose rows miss the caches waits for memory; a prefetch issued as soon as the
rows are known lets the loads overlap with work that does not need them. The SIMD lanes
(:mod:`.lane_paths`) prefetch the packed records of a packet's hit triangles
(:func:`.integrator.triangle_records`) right after ``rtcIntersect16`` returns and draw
the bounce's random numbers before they gather the records: on the heavy scene (1 M
triangles, 64 MB of records) that took the lanes' work outside Embree from about 250 to
220 ns per path.
"""

from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic
from numba.np.arrayobj import make_array

_I8P = ir.IntType(8).as_pointer()
_I32 = ir.IntType(32)
#: llvm.prefetch(address, rw = 0 (read), locality = 3 (keep in all levels), 1 (data))
_PREFETCH = ir.FunctionType(ir.VoidType(), [_I8P, _I32, _I32, _I32])


@intrinsic
def prefetch_row(typingctx, ary, row):  # pragma: no cover - compiled
    """Prefetch, for reading, the cache line that holds ``ary[row, 0]`` (a 2-D array;
    ``row`` an integer within its rows: no bounds check, and a prefetch never faults)."""
    if not (isinstance(ary, types.Array) and ary.ndim == 2 and isinstance(row, types.Integer)):
        return None

    def codegen(context, builder, signature, args):
        a = make_array(signature.args[0])(context, builder, args[0])
        offset = builder.mul(context.cast(builder, args[1], signature.args[1], types.intp),
                             builder.extract_value(a.strides, 0))
        address = builder.gep(builder.bitcast(a.data, _I8P), [offset])
        fn = cgutils.get_or_insert_function(builder.module, _PREFETCH, "llvm.prefetch.p0")
        builder.call(fn, [address, _I32(0), _I32(3), _I32(1)])
        return context.get_dummy_value()

    return types.void(ary, row), codegen
