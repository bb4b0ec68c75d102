"""A software prefetch for numba loops: ask for a row of a 2-D array before it is read.

The vector environment reads each copy's library row at a random place in a table of megabytes, every
step the row after the last. That row's cache line was last read by whichever copy passed it many
steps ago, so it comes from main memory, and a step's 4096 reads waited for it longer than the rest of
the step computed. :func:`prefetch_row` issues LLVM's ``llvm.prefetch`` for a row a step before it is
read (spread over the step, one copy at a time, so that the loads overlap the step's arithmetic; asked for
in a burst per block, they queued and gained nothing). A prefetch is a hint: it changes no value and
cannot fault, and the callers pass rows inside the array.
"""

from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic


@intrinsic
def prefetch_row(typingctx, array, row):
    """Prefetch the first and the last element of ``array[row]`` (a C-contiguous 2-D array) for reading,
    into every cache level (``llvm.prefetch``, locality 3)."""
    if not (isinstance(array, types.Array) and array.ndim == 2 and array.layout == "C"
            and isinstance(row, types.Integer)):
        return None

    def codegen(context, builder, signature, args):
        array_type, row_type = signature.args
        view = context.make_array(array_type)(context, builder, args[0])
        index = context.cast(builder, args[1], row_type, types.intp)
        columns = cgutils.unpack_tuple(builder, view.shape, 2)[1]
        last = builder.sub(columns, context.get_constant(types.intp, 1))
        pointer_type = ir.PointerType(ir.IntType(8))
        function = cgutils.get_or_insert_function(
            builder.module, ir.FunctionType(ir.VoidType(), [pointer_type] + [ir.IntType(32)] * 3), "llvm.prefetch.p0")
        for column in (context.get_constant(types.intp, 0), last):
            address = cgutils.get_item_pointer2(context, builder, view.data, cgutils.unpack_tuple(builder, view.shape, 2),
                                                cgutils.unpack_tuple(builder, view.strides, 2), array_type.layout,
                                                [index, column])
            builder.call(function, [builder.bitcast(address, pointer_type), ir.Constant(ir.IntType(32), 0),
                                    ir.Constant(ir.IntType(32), 3), ir.Constant(ir.IntType(32), 1)])
        return context.get_dummy_value()

    return types.void(array, row), codegen
