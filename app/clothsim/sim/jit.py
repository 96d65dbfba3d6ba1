"""Numba options shared by the kernels.

Fast-math lets LLVM contract and reassociate floating point (deterministic for a given build)
but keeps NaN/inf semantics, so blow-up checks and infinite bounds stay meaningful.
"""

FASTMATH = {"nsz", "arcp", "contract", "afn", "reassoc"}
