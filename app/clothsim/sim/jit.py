"""Numba options shared by the kernels.

Fast-math lets LLVM contract and reassociate floating point (deterministic for a given build)
but keeps NaN/inf semantics, so blow-up checks and infinite bounds stay meaningful.

``error_model="numpy"`` matters as much: under Numba's default ("python") every float division
carries a zero-divisor check that raises, and that branch stops LLVM from vectorising the loop
(a plain sqrt-and-divide stream ran 4x slower with it). The kernels guard their divisors themselves.
"""

import os

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

from .kernel_cache import install as _install_package_stamp

# Before any kernel is decorated: every module that defines one imports this one first.
_install_package_stamp()

# Numba runs PARALLEL kernels on libgomp, whose idle workers spin 300,000 pause instructions
# (about 10 ms on this machine's CPUs) before sleeping. A frame's parallel regions follow each
# other microseconds apart, so a short spin keeps the same speed, while the default stole both
# cores from whatever ran after a frame: llvmpipe rendered Blinn-Phong at 50 instead of 62 frames/s.
# libgomp reads the variable when it loads (at the first parallel call); a user's value wins.
os.environ.setdefault("GOMP_SPINCOUNT", "10000")

FASTMATH = {"nsz", "arcp", "contract", "afn", "reassoc"}

#: Options for kernels whose floating point may be reassociated.
KERNEL = {"cache": True, "fastmath": FASTMATH, "error_model": "numpy"}

#: Options for kernels that keep IEEE evaluation order (bit-exact closed forms, drivers).
EXACT = {"cache": True, "error_model": "numpy"}

#: KERNEL split over the cores with ``prange``; such kernels keep every output element a
#: function of its own inputs, so results do not depend on the number of threads.
PARALLEL = {**KERNEL, "parallel": True}

#: Work items a PARALLEL kernel splits a pass into: enough for the cores to share the work evenly,
#: few enough that each item is a long contiguous stream. Items are contiguous point ranges, in
#: the same order in every pass, so a core keeps working on the points it touched last.
CHUNKS = 8


@intrinsic
def call_native(typingctx, address, args):  # noqa: ANN001, ANN201
    """Call the compiled kernel at ``address`` (see :func:`native_address`) with the tuple ``args``;
    returns 1 if it failed (it could not allocate), else 0. The kernel must have been compiled
    for exactly the types of ``args`` and return nothing.

    A call by address keeps the callee's code out of the caller's module: Numba links every callee
    into its caller and optimises the whole again, so each level of direct calls re-optimises all
    the code below it, and the callee cannot be compiled in another process meanwhile.
    """
    argtys = tuple(args)
    sig = types.int64(address, args)

    def codegen(context, builder, sig, llargs):  # noqa: ANN001, ANN202
        conv = context.call_conv
        fnty = conv.get_function_type(types.void, argtys)
        fn = builder.inttoptr(llargs[0], fnty.as_pointer())
        retty = conv.get_return_type(types.void).pointee
        ret = cgutils.alloca_once(builder, retty)
        builder.store(cgutils.get_null_value(retty), ret)
        excinfo = cgutils.alloca_once(builder, fnty.args[1].pointee)
        values = cgutils.unpack_tuple(builder, llargs[1], len(argtys))
        packed = list(conv._get_arg_packer(argtys).as_arguments(builder, values))
        code = builder.call(fn, [ret, excinfo, *packed])
        status = conv._get_return_status(builder, code, builder.load(excinfo))
        return builder.zext(status.is_error, ir.IntType(64))

    return sig, codegen


def native_address(kernel, argtypes: tuple) -> int:  # noqa: ANN001
    """Address of ``kernel`` compiled (or loaded from the cache) for ``argtypes``, for
    :func:`call_native`."""
    kernel.compile(argtypes)
    cres = kernel.overloads[argtypes]
    return cres.library.get_pointer_to_function(cres.fndesc.llvm_func_name)
