"""Every use of Numba's private API, in one place: call-by-address, the compiled-or-cached test and
the package-wide cache stamp. :func:`missing_private_api` names what a Numba release lacks (the
test suite checks it, so an upgrade that removes any of it fails there with that name, not with a
crash in a kernel).

Cached kernels are valid for one version of the whole package, not of one file.

Numba keys a function's on-disk cache on its own source file only. A kernel's compiled code,
though, holds every kernel it calls, from other modules too: after an upgrade (or an edit) that
changes ``constraints.py`` but not ``explicit.py``, Numba would load ``run_symplectic`` compiled
against the old Provot code, which ran the old code at best and crashed the process at worst
(seen: a segmentation fault after the Provot helpers were merged into one function). pip leaves
the old ``*.nbi``/``*.nbc`` files in ``__pycache__`` when it replaces a package, and a
read-only install caches in the user's folder, which outlives every upgrade.

So every kernel of this package is stamped with one digest of all the package's modules that use
Numba: a change to any of them makes every cached kernel stale, and Numba recompiles and
overwrites it. Where the cache lives is Numba's own choice (``NUMBA_CACHE_DIR``, next to the
module, or the user-wide cache), unchanged. The digest reads about 20 files once per process
(about a millisecond).
"""

from __future__ import annotations

import functools
import hashlib
from pathlib import Path
from typing import Any

from llvmlite import ir
from numba import types
from numba.core import caching, cgutils
from numba.extending import intrinsic

_PACKAGE = Path(__file__).resolve().parent.parent


@functools.lru_cache(maxsize=1)
def package_stamp() -> str:
    """SHA-256 over the path and text of every module of the package that mentions Numba, in any
    case: a plain-Python function a kernel compiles (``motion.position_at``) says so in its text."""
    digest = hashlib.sha256()
    for path in sorted(_PACKAGE.rglob("*.py")):
        text = path.read_bytes()
        if b"numba" in text.lower():
            digest.update(path.relative_to(_PACKAGE).as_posix().encode() + b"\0" + text + b"\0")
    return digest.hexdigest()


def _in_package(py_file: str) -> bool:
    try:
        Path(py_file).resolve().relative_to(_PACKAGE)
    except (ValueError, OSError):
        return False
    return True


def _stamped(base: type) -> type:
    """``base`` (one of Numba's file-backed locators) with the package's stamp, for this package's
    functions only."""

    class PackageLocator(base):  # type: ignore[misc, valid-type]
        def get_source_stamp(self) -> Any:
            return package_stamp()

        @classmethod
        def from_function(cls, py_func: Any, py_file: str) -> Any:
            if not _in_package(py_file):
                return None
            return super().from_function(py_func, py_file)

    PackageLocator.__name__ = PackageLocator.__qualname__ = f"Package{base.__name__}"
    return PackageLocator


def install_package_stamp() -> None:
    """Put the stamped locators in front of Numba's (once; before any kernel is decorated)."""
    impl = getattr(caching, "CacheImpl", None) or caching._CacheImpl  # renamed in Numba 0.6x
    if getattr(impl, "_clothsim_stamped", False):
        return
    mixin = getattr(caching, "_SourceFileBackedLocatorMixin", None)
    bases = [c for c in impl._locator_classes if mixin is not None and issubclass(c, mixin)]
    impl._locator_classes = [_stamped(c) for c in bases] + list(impl._locator_classes)
    impl._clothsim_stamped = True


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


def native_address(kernel: Any, argtypes: tuple) -> int:
    """Address of ``kernel`` compiled (or loaded from the cache) for ``argtypes``, for
    :func:`call_native`."""
    kernel.compile(argtypes)
    cres = kernel.overloads[argtypes]
    return cres.library.get_pointer_to_function(cres.fndesc.llvm_func_name)


def is_cached(dispatcher: Any, argtypes: tuple) -> bool:
    """True when ``dispatcher`` is compiled for ``argtypes`` in this process or in its disk cache."""
    if argtypes in dispatcher.overloads:
        return True
    cache = getattr(dispatcher, "_cache", None)
    try:
        return cache is not None and cache.load_overload(argtypes, dispatcher.targetctx) is not None
    except Exception:  # noqa: BLE001 - an unreadable cache entry is a miss
        return False


def missing_private_api() -> list[str]:
    """The private Numba names this module needs that the installed Numba lacks (empty when all
    are there)."""
    from numba.core.callconv import CPUCallConv

    missing = []
    if getattr(caching, "CacheImpl", None) is None and getattr(caching, "_CacheImpl", None) is None:
        missing.append("numba.core.caching.CacheImpl (or _CacheImpl)")
    impl = getattr(caching, "CacheImpl", None) or getattr(caching, "_CacheImpl", None)
    if impl is not None and not hasattr(impl, "_locator_classes"):
        missing.append("numba.core.caching.CacheImpl._locator_classes")
    if getattr(caching, "_SourceFileBackedLocatorMixin", None) is None:
        missing.append("numba.core.caching._SourceFileBackedLocatorMixin")
    for name in ("_get_arg_packer", "_get_return_status", "get_function_type", "get_return_type"):
        if not hasattr(CPUCallConv, name):
            missing.append(f"numba.core.callconv.CPUCallConv.{name}")
    return missing
