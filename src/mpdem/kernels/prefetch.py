"""A hint to the CPU to start loading a row of an array into the cache.

``prefetch_row(a, i)`` in a jitted kernel emits one prefetch instruction
(``prefetcht0`` on x86) for the cache line that holds ``a[i, 0]`` (or
``a[i]``): it changes no value and never faults, only when the line arrives.
The force pass uses it where it knows a block ahead which partner rows the
contact law will read (docs/performance.md). Called from Python (numba's
JIT disabled) it does nothing.
"""
from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic, overload


def prefetch_row(a, i):
    """Ask for the cache line of ``a[i, 0]`` (a C-contiguous array of 1 or 2 dimensions, 0 <= i < len(a)).

    A no-op here; in jitted code one prefetch instruction (``_prefetch``).
    """
    return None


@intrinsic
def _prefetch(typingctx, a, i):
    """``llvm.prefetch`` (read, high locality, data cache) of the address of a[i, 0, ...]."""
    sig = types.void(a, i)

    def codegen(context, builder, signature, args):
        aryty, idxty = signature.args
        ary = context.make_array(aryty)(context, builder, args[0])
        idx = context.cast(builder, args[1], idxty, types.intp)
        zero = context.get_constant(types.intp, 0)
        ptr = cgutils.get_item_pointer2(context, builder, ary.data, cgutils.unpack_tuple(builder, ary.shape),
                                        cgutils.unpack_tuple(builder, ary.strides), aryty.layout,
                                        [idx] + [zero] * (aryty.ndim - 1), wraparound=False, boundscheck=False)
        i8p = ir.IntType(8).as_pointer()
        i32 = ir.IntType(32)
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(ir.VoidType(), [i8p, i32, i32, i32]),
                                            "llvm.prefetch.p0")
        # rw 0 (read), locality 3 (keep in all levels), cache type 1 (data)
        builder.call(fn, [builder.bitcast(ptr, i8p), ir.Constant(i32, 0), ir.Constant(i32, 3), ir.Constant(i32, 1)])
        return context.get_dummy_value()

    return sig, codegen


@overload(prefetch_row, inline="always")
def _prefetch_row_jit(a, i):
    if isinstance(a, types.Array) and isinstance(i, types.Integer):
        def impl(a, i):
            _prefetch(a, i)
        return impl
    return None
