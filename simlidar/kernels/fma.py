"""A fused multiply-add, ``fma(a, b, c) = a * b + c`` rounded once, for compiled code (LLVM's ``llvm.fma.f64``).

numpy's small matrix products go through BLAS, whose kernels fuse the multiply and
the add; a compiled loop that is to round as they do (``simlidar.kernels.sweep``)
needs the same operation, exact whether or not the processor has the instruction.
"""

from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic


@intrinsic
def fma(typingctx, a, b, c):
    """``a * b + c`` with one rounding (float64), callable from ``numba.njit`` code."""
    sig = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        fnty = ir.FunctionType(ir.DoubleType(), [ir.DoubleType()] * 3)
        fn = cgutils.get_or_insert_function(builder.module, fnty, "llvm.fma.f64")
        return builder.call(fn, args)

    return sig, codegen


__all__ = ["fma"]
