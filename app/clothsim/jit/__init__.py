"""The just-in-time layer: Numba options shared by every kernel of the package.

This package imports nothing else of clothsim; every layer above may use it. Everything that
touches Numba's private API is in :mod:`clothsim.jit.internals`.

Fast-math lets LLVM contract and reassociate floating point (deterministic for a given build)
but keeps NaN/inf semantics, so blow-up checks and infinite bounds stay meaningful.

``error_model="numpy"`` matters as much: under Numba's default ("python") every float division
carries a zero-divisor check that raises, and that branch stops LLVM from vectorising the loop
(a plain sqrt-and-divide stream ran 4x slower with it). The kernels guard their divisors themselves.
"""

import os

from .internals import install_package_stamp, install_shared_cache

# Before any kernel is decorated: every module that defines one imports this one first.
install_package_stamp()
install_shared_cache()

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
#: ``fastmath=False`` is said explicitly: Numba compiles a callee that does not set it with its
#: caller's fast-math flags, and files that compile in the on-disk cache under the callee's
#: signature alone, so an unset callee was fast or exact depending on which caller compiled it
#: first, in whichever process filled the cache (seen as implicit Euler's and the contact mode's
#: numbers changing between a cold and a warm run).
EXACT = {"cache": True, "error_model": "numpy", "fastmath": False}

#: EXACT for kernels that only read and write the arrays they are given (they make none and
#: return none): compiled without Numba's reference counting (its private ``_nrt`` option). Each
#: time an inlined helper takes a group of arrays, Numba counts a reference to every array of the
#: group up and down again, two calls per array, and in the mesh pass those calls cost more than
#: the tests themselves. A callee that does not set the option inherits it, so every non-inlined
#: callee of such a kernel that takes arrays must be BORROWED too.
BORROWED = {**EXACT, "_nrt": False}

#: Added to a kernel's options when only compiled code calls it (by address, or as a callee):
#: Numba then makes no Python entry point and no C callback for it. For a kernel that takes the
#: contact mode's group (some 40 arrays) the Python entry point, which unpacks every array, was most
#: of its compile: 0.43-0.58 s against 0.08-0.12 s for an eight-line loop over the points. Calling
#: such a kernel from Python crashes the interpreter, so only kernels no Python code calls take it.
INNER = {"no_cpython_wrapper": True, "no_cfunc_wrapper": True}

#: KERNEL split over the cores with ``prange``; such kernels keep every output element a
#: function of its own inputs, so results do not depend on the number of threads.
PARALLEL = {**KERNEL, "parallel": True}

#: Work items a PARALLEL kernel splits a pass into: enough for the cores to share the work evenly,
#: few enough that each item is a long contiguous stream. Items are contiguous point ranges, in
#: the same order in every pass, so a core keeps working on the points it touched last.
CHUNKS = 8


def field_is_none(group: object, name: str) -> bool:
    """At typing time (in an ``overload``): True when field ``name`` of the named-tuple type
    ``group`` is None, i.e. the pass it belongs to is pruned."""
    from numba import types

    return isinstance(group.types[group.fields.index(name)], types.NoneType)  # type: ignore[attr-defined]
