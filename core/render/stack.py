"""Arrays in the stack memory of a compiled kernel (numba), for loops that LLVM vectorises.

A numba array made by ``np.empty`` lives on the heap with an owner whose references are
counted; a loop that writes it and reads the scene's arrays is, to LLVM, one whose stores
may alias its loads, and it stays scalar ("unsafe dependent memory operations"). An
array in the kernel's own stack frame (:func:`stack_array`: an ``alloca``, no owner) is
known to alias nothing else, so such loops become vector code: the SIMD lanes'
structure-of-arrays state (:mod:`.lane_paths`), the four wavelengths of a texel's
spectrum (:func:`.textures.texel_reflectance`). A function that makes one must not
return it or keep it past its own return; it compiles without reference counting
(``_nrt=False``) or never passes the array to code that counts references.
"""

from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.extending import intrinsic
from numba.np.arrayobj import make_array, populate_array


@intrinsic(prefer_literal=True)
def stack_array(typingctx, rows, cols, dtype):  # pragma: no cover - compiled
    """A C-contiguous (rows, cols) array of ``dtype`` (rows and cols literals) in fresh
    stack memory of the calling function, aligned to 64 bytes and uninitialised; it has
    no owner to count references to."""
    if not (isinstance(rows, types.IntegerLiteral) and isinstance(cols, types.IntegerLiteral)):
        return None
    shape = (rows.literal_value, cols.literal_value)
    elem = dtype.instance_type if isinstance(dtype, types.NumberClass) else dtype.dtype
    aryty = types.Array(elem, 2, "C")

    def codegen(context, builder, signature, args):
        lty = context.get_data_type(elem)
        with builder.goto_entry_block():
            slot = builder.alloca(ir.ArrayType(lty, shape[0] * shape[1]))
            slot.align = 64
        ary = make_array(aryty)(context, builder)
        size = context.get_abi_sizeof(lty)
        intp = context.get_value_type(types.intp)
        populate_array(ary, data=builder.bitcast(slot, lty.as_pointer()),
                       shape=[intp(n) for n in shape],
                       strides=[intp(shape[1] * size), intp(size)], itemsize=intp(size),
                       meminfo=None)
        return ary._getvalue()

    return aryty(rows, cols, dtype), codegen
