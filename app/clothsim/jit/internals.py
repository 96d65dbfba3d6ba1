"""Every use of Numba's private API, in one place: call-by-address, values handed to a kernel
called by address or to a parallel loop's threads (:func:`stack_address`), the compiled-or-cached test,
the package-wide cache stamp, and the thread team's atomics and clock (LLVM IR through
``numba.core.cgutils``). :func:`missing_private_api` names what a Numba release lacks (the
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

import fcntl
import functools
import hashlib
import os
import platform
import struct
import time
from pathlib import Path
from typing import Any

from llvmlite import ir
from numba import types
from numba.core import caching, cgutils, ir_utils
from numba.core.imputils import impl_ret_borrowed
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


def _locked_save(self: Any, key: Any, data: Any) -> None:
    """Numba's ``IndexDataCacheFile.save``, safe between processes: under an exclusive lock on a
    file beside the index, the index is read afresh, the kernel written, and only then the index
    entry naming it.

    Numba's own save reads the index, picks the first free data-file number, writes the index and
    then the data, with no lock: two processes compiling two signatures of one kernel at once (the
    test suite's workers, a sweep's local workers on a cold cache) both took number 1, and the
    index then named one signature's code with the other's data, which a third process loaded and
    failed to type. Writing the data before the entry also keeps a reader from meeting an entry
    whose file still holds a kernel of an older stamp.
    """
    try:
        fd = os.open(self._index_path + ".lock", os.O_RDWR | os.O_CREAT, 0o644)
    except OSError:  # a folder where no lock file can be made: Numba's own save
        _numba_save(self, key, data)
        return
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        overloads = self._load_index()
        name = overloads.get(key)
        if name is None:
            taken = set(overloads.values())
            number = 1
            while _data_name(self, number) in taken:
                number += 1
            name = _data_name(self, number)
        self._save_data(name, data)
        if overloads.get(key) != name:
            overloads[key] = name
            self._save_index(overloads)
            _drop_other_versions(self)
    finally:
        os.close(fd)  # releases the lock


_numba_save = caching.IndexDataCacheFile.save


def _data_name(cache: Any, number: int) -> str:
    """Data file ``number`` of a kernel: for this package's kernels the name carries the package's
    stamp, so that processes of two versions of the package sharing a cache folder (an upgrade
    under a running sweep; two checkouts' tools) never write each other's files. Numba numbers
    them only, and a process of the other version, finding the index stale, took number 1 again
    and overwrote the code an index of this version named: a later process then ran the other
    version's code (seen: a bit-identity table run beside a run of an edited checkout)."""
    stamp = cache._source_stamp
    if stamp == package_stamp():
        return cache._data_name_pattern.format(number=number).replace(".nbc", f".{stamp[:16]}.nbc")
    return cache._data_name(number)


def _drop_other_versions(cache: Any) -> None:
    """Delete this kernel's data files of other versions of the package (a process of that
    version still running finds its file gone and compiles again: Numba's load treats a missing
    file as a miss)."""
    stamp = cache._source_stamp
    if stamp != package_stamp():
        return
    base = cache._index_name[: -len(".nbi")]
    mine = f".{stamp[:16]}.nbc"
    try:
        names = os.listdir(cache._cache_path)
    except OSError:
        return
    for name in names:
        if name.startswith(base + ".") and name.endswith(".nbc") and not name.endswith(mine):
            rest = name[len(base) + 1 : -len(".nbc")]
            # base.N.nbc (Numba's own naming) or base.N.<stamp>.nbc: not another kernel's base.M...
            if rest.split(".")[0].isdigit() and rest.count(".") <= 1:
                try:
                    os.remove(os.path.join(cache._cache_path, name))
                except OSError:
                    pass


def install_shared_cache() -> None:
    """Make Numba's on-disk cache safe for processes that compile at the same time (once)."""
    if getattr(caching.IndexDataCacheFile, "_clothsim_locked", False):
        return
    caching.IndexDataCacheFile.save = _locked_save
    caching.IndexDataCacheFile._clothsim_locked = True


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


@intrinsic
def stack_address(typingctx, value):  # noqa: ANN001, ANN201
    """The address of a copy of ``value`` on the calling function's stack, valid until that
    function returns, for :func:`load_value` in a kernel it calls by address (the arrays in it are
    the caller's, borrowed: see :func:`_unowned`).

    A kernel called by address with the address of its arguments has one signature for every
    type of argument: the thread team's launcher is compiled once, not once per plan.
    """
    sig = types.int64(value)

    def codegen(context, builder, sig, args):  # noqa: ANN001, ANN202
        slot = cgutils.alloca_once(builder, context.get_value_type(sig.args[0]))
        builder.store(_unowned(context, builder, sig.args[0], args[0]), slot)
        return builder.ptrtoint(slot, ir.IntType(64))

    return sig, codegen


def _unowned(context, builder, ty: types.Type, value: Any) -> Any:  # noqa: ANN001
    """``value`` with every array in it detached from its owner (no meminfo, no parent object), as
    a parallel loop hands arrays to its threads: Numba then counts no references to them. Counted
    references cost an atomic add on a counter the threads share at every array the callee passes
    on, which made the team's frames several times slower (docs/performance-team.md, "One
    launch for every plan")."""
    if isinstance(ty, types.BaseTuple):
        for i, t in enumerate(ty.types):
            value = builder.insert_value(value, _unowned(context, builder, t, builder.extract_value(value, i)), i)
        return value
    if isinstance(ty, types.Array):
        ary = context.make_array(ty)(context, builder, value=value)
        ary.meminfo = cgutils.get_null_value(ary.meminfo.type)
        ary.parent = cgutils.get_null_value(ary.parent.type)
        return ary._getvalue()
    return value


@intrinsic
def load_value(typingctx, address, proto):  # noqa: ANN001, ANN201
    """The value of type ``proto`` (a :func:`type_ref`) that :func:`stack_address` gave ``address``
    of; its arrays stay the caller's."""
    ty = proto.instance_type
    sig = ty(address, proto)

    def codegen(context, builder, sig, args):  # noqa: ANN001, ANN202
        slot = builder.inttoptr(args[0], context.get_value_type(ty).as_pointer())
        return impl_ret_borrowed(context, builder, ty, builder.load(slot))

    return sig, codegen


def packed_value(value: Any, ty: types.Type) -> Any:
    """``value`` (of Numba type ``ty``: tuples, named tuples, arrays and scalars) laid out as
    :func:`stack_address` lays it out, arrays detached as there, in a buffer of this process: for
    :func:`load_value` in a kernel called by address, without a kernel compiled for ``ty`` to copy
    it (the team's plans: about 0.9 s of compiling a plan, docs/history/team.md). The address is
    ``ctypes.addressof`` of the result, valid while the result and ``value``'s arrays live."""
    import ctypes

    layout = _LAYOUTS.get(ty)
    if layout is None:
        layout = _LAYOUTS[ty] = _layout(ty)
    packer, size = layout
    buffer = (ctypes.c_uint8 * max(1, size))()
    try:
        packer.pack_into(buffer, 0, *_native_fields(value, ty))
    except struct.error as why:
        raise TypeError(f"packed_value: {ty} does not lay out as expected: {why}") from None
    return buffer


#: the layout of each type packed so far: a struct.Struct over the value model's scalars (with
#: the padding between them) and the size
_LAYOUTS: dict[types.Type, tuple[struct.Struct, int]] = {}
#: size and alignment of each scalar or pointer LLVM type met, as llvmlite reports them
_LEAVES: dict[str, tuple[int, int]] = {}


def _layout(ty: types.Type) -> tuple[struct.Struct, int]:
    """The packer of ``ty``'s value model: its scalars in order at their offsets."""
    from numba.core.registry import cpu_target

    context = cpu_target.target_context
    llty = context.get_value_type(ty)
    leaves: list[tuple[int, str]] = []
    _place(llty, 0, leaves, context.target_data)
    size = _abi(llty, context.target_data)[0]
    fmt = "="
    at = 0
    for offset, code in leaves:
        fmt += "x" * (offset - at) + code
        at = offset + struct.calcsize("=" + code)
    fmt += "x" * (size - at)
    return struct.Struct(fmt), size


def _place(llty: ir.Type, base: int, leaves: list[tuple[int, str]], data: Any) -> None:
    """Append the (offset, struct code) of every scalar of ``llty`` placed at ``base``."""
    if isinstance(llty, ir.LiteralStructType):
        if llty.packed:
            raise TypeError("packed_value: packed structs are not laid out")
        offset = 0
        for element in llty.elements:
            size, align = _abi(element, data)
            offset = -(-offset // align) * align
            _place(element, base + offset, leaves, data)
            offset += size
    elif isinstance(llty, ir.ArrayType):
        size = _abi(llty.element, data)[0]
        for i in range(llty.count):
            _place(llty.element, base + i * size, leaves, data)
    elif isinstance(llty, ir.IntType) and llty.width in (1, 8, 16, 32, 64):
        leaves.append((base, {1: "B", 8: "b", 16: "h", 32: "i", 64: "q"}[llty.width]))
    elif isinstance(llty, ir.DoubleType):
        leaves.append((base, "d"))
    elif isinstance(llty, ir.FloatType):
        leaves.append((base, "f"))
    elif isinstance(llty, ir.PointerType):
        leaves.append((base, "Q"))
    else:
        raise TypeError(f"packed_value: cannot lay out LLVM type {llty}")


def _abi(llty: ir.Type, data: Any) -> tuple[int, int]:
    """(size, alignment) of ``llty`` on this target. Asking llvmlite parses IR each time (about
    0.1 ms: 45-60 ms for a plan), so it is asked once per scalar or pointer type; structs and
    arrays follow LLVM's layout of them (each member at its alignment, the struct as aligned as
    its most aligned member and its size a multiple of that; an array's elements back to back)."""
    if isinstance(llty, ir.LiteralStructType):
        offset, align = 0, 1
        for element in llty.elements:
            size, a = _abi(element, data)
            offset = -(-offset // a) * a + size
            align = max(align, a)
        return -(-offset // align) * align, align
    if isinstance(llty, ir.ArrayType):
        size, align = _abi(llty.element, data)
        return size * llty.count, align
    key = str(llty)
    known = _LEAVES.get(key)
    if known is None:
        known = _LEAVES[key] = (llty.get_abi_size(data), llty.get_abi_alignment(data))
    return known


def _native_fields(value: Any, ty: types.Type) -> list:
    """``value``'s scalars in the order of Numba's value model (:func:`_place`'s order)."""
    if isinstance(ty, types.BaseTuple):
        return [x for v, t in zip(value, ty.types, strict=True) for x in _native_fields(v, t)]
    if isinstance(ty, types.Array):
        # the array model: meminfo, parent (none: detached), nitems, itemsize, data, shape, strides
        return [0, 0, value.size, value.itemsize, value.ctypes.data, *value.shape, *value.strides]
    if isinstance(ty, types.Boolean):
        return [1 if value else 0]
    if isinstance(ty, types.Integer):
        return [int(value)]
    if isinstance(ty, types.Float):
        return [float(value)]
    if isinstance(ty, types.NoneType):
        return [0]  # (an opaque pointer: a pass the plan does not use)
    raise TypeError(f"packed_value: cannot lay out a {ty}")


@intrinsic
def type_ref(typingctx, value):  # noqa: ANN001, ANN201
    """The type of ``value`` as a value (no data), for :func:`load_value`."""
    sig = types.TypeRef(value)(value)

    def codegen(context, builder, sig, args):  # noqa: ANN001, ANN202
        return context.get_dummy_value()

    return sig, codegen


def _holds_the_callers_arrays(lhs: str, args: list, alias_map: dict, arg_aliases: set | dict) -> None:
    # a set in the dead-code analysis; when a parallel loop is lowered Numba passes an empty dict
    # that nothing may be added to (its own _add_alias would then fail on it)
    if isinstance(arg_aliases, set):
        arg_aliases.add(lhs)


# What load_value returns holds the caller's arrays: without saying so, Numba's dead-code pass may
# take a write through it, inside a parallel loop, for a write to a fresh array nobody reads, and
# drop it (seen with the tuples handed to the threads before load_value).
ir_utils.alias_func_extensions[("load_value", __name__)] = _holds_the_callers_arrays


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


def cache_folder(dispatcher: Any) -> str | None:
    """The folder where ``dispatcher``'s compiled code is cached (created if need be), or None
    (no cache, or a folder that cannot be made)."""
    cache = getattr(dispatcher, "_cache", None)
    folder = getattr(cache, "_cache_path", None)
    if not folder:
        return None
    try:
        os.makedirs(folder, exist_ok=True)
    except OSError:
        return None
    return folder


def missing_private_api() -> list[str]:
    """The private Numba names this module needs that the installed Numba lacks (empty when all
    are there)."""
    from numba.core.callconv import CPUCallConv
    from numba.core.cpu import CPUTargetOptions

    missing = []
    if not hasattr(CPUTargetOptions, "_nrt"):
        missing.append("numba.core.cpu.CPUTargetOptions._nrt (the jit option BORROWED)")
    if getattr(caching, "CacheImpl", None) is None and getattr(caching, "_CacheImpl", None) is None:
        missing.append("numba.core.caching.CacheImpl (or _CacheImpl)")
    impl = getattr(caching, "CacheImpl", None) or getattr(caching, "_CacheImpl", None)
    if impl is not None and not hasattr(impl, "_locator_classes"):
        missing.append("numba.core.caching.CacheImpl._locator_classes")
    if getattr(caching, "_SourceFileBackedLocatorMixin", None) is None:
        missing.append("numba.core.caching._SourceFileBackedLocatorMixin")
    try:
        sample = caching.IndexDataCacheFile("/nonexistent", "kernel", "stamp")  # sets names only, reads nothing
    except Exception:  # noqa: BLE001 - a changed constructor is a missing API too
        sample = None
        missing.append("numba.core.caching.IndexDataCacheFile(cache_path, filename_base, source_stamp)")
    for name in ("_load_index", "_save_index", "_save_data", "_data_name", "_data_name_pattern", "_index_name",
                 "_cache_path", "_source_stamp"):
        if not hasattr(caching.IndexDataCacheFile, name) and not hasattr(sample, name):
            missing.append(f"numba.core.caching.IndexDataCacheFile.{name}")
    for name in ("alloca_once", "alloca_once_value", "unpack_tuple", "get_null_value", "get_item_pointer",
                 "get_or_insert_function", "gep_inbounds"):
        if not hasattr(cgutils, name):
            missing.append(f"numba.core.cgutils.{name}")
    if not hasattr(ir_utils, "alias_func_extensions"):
        missing.append("numba.core.ir_utils.alias_func_extensions")
    for name in ("_get_arg_packer", "_get_return_status", "get_function_type", "get_return_type"):
        if not hasattr(CPUCallConv, name):
            missing.append(f"numba.core.callconv.CPUCallConv.{name}")
    return missing


# ----------------------------------------------------------------------------------------------
# The thread team's primitives (clothsim.sim.team): atomics on an int64 array, the monotonic
# clock, the spin-wait hint and sched_yield, written in LLVM IR through numba.core.cgutils.


def _element_pointer(context, builder, arr_type, arr, idx):  # noqa: ANN001, ANN202
    ary = context.make_array(arr_type)(context, builder, arr)
    return cgutils.get_item_pointer(context, builder, arr_type, ary, [idx])


@intrinsic
def atomic_add(typingctx, arr, idx, val):  # noqa: ANN001, ANN201
    """arr[idx] += val atomically (sequentially consistent); returns the old value."""
    sig = types.int64(arr, idx, val)

    def codegen(context, builder, sig, args):  # noqa: ANN001, ANN202
        ptr = _element_pointer(context, builder, sig.args[0], args[0], args[1])
        return builder.atomic_rmw("add", ptr, args[2], "seq_cst")

    return sig, codegen


@intrinsic
def atomic_load(typingctx, arr, idx):  # noqa: ANN001, ANN201
    """arr[idx] read with acquire ordering (sees every write made before the matching release)."""
    sig = types.int64(arr, idx)

    def codegen(context, builder, sig, args):  # noqa: ANN001, ANN202
        ptr = _element_pointer(context, builder, sig.args[0], args[0], args[1])
        return builder.load_atomic(ptr, "acquire", 8)

    return sig, codegen


@intrinsic
def atomic_cas(typingctx, arr, idx, expected, new):  # noqa: ANN001, ANN201
    """Set arr[idx] = new if it equals expected; returns the value found."""
    sig = types.int64(arr, idx, expected, new)

    def codegen(context, builder, sig, args):  # noqa: ANN001, ANN202
        ptr = _element_pointer(context, builder, sig.args[0], args[0], args[1])
        pair = builder.cmpxchg(ptr, args[2], args[3], "seq_cst", "seq_cst")
        return builder.extract_value(pair, 0)

    return sig, codegen


@intrinsic
def yield_core(typingctx):  # noqa: ANN001, ANN201
    """sched_yield(): let another runnable thread have this core."""
    sig = types.int32()

    def codegen(context, builder, sig, args):  # noqa: ANN001, ANN202
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(ir.IntType(32), []), "sched_yield")
        return builder.call(fn, [])

    return sig, codegen


_CLOCK = getattr(time, "CLOCK_MONOTONIC", 1)


@intrinsic
def monotonic_ns(typingctx):  # noqa: ANN001, ANN201
    """clock_gettime(CLOCK_MONOTONIC) in nanoseconds (a vDSO call: no system call, ~20 ns)."""
    sig = types.int64()

    def codegen(context, builder, sig, args):  # noqa: ANN001, ANN202
        i64 = ir.IntType(64)
        timespec = ir.LiteralStructType([i64, i64])
        fn = cgutils.get_or_insert_function(
            builder.module, ir.FunctionType(ir.IntType(32), [ir.IntType(32), timespec.as_pointer()]),
            "clock_gettime")
        ts = cgutils.alloca_once(builder, timespec)
        builder.call(fn, [ir.Constant(ir.IntType(32), _CLOCK), ts])
        sec = builder.load(cgutils.gep_inbounds(builder, ts, 0, 0))
        nsec = builder.load(cgutils.gep_inbounds(builder, ts, 0, 1))
        return builder.add(builder.mul(sec, ir.Constant(i64, 1_000_000_000)), nsec)

    return sig, codegen


_X86 = platform.machine().lower() in ("x86_64", "amd64", "i686", "i386")


@intrinsic
def spin_pause(typingctx):  # noqa: ANN001, ANN201
    """The CPU's spin-wait hint (x86 ``pause``): a waiting member leaves the core's execution
    units, and a sibling hardware thread, to the members still working."""
    sig = types.void()

    def codegen(context, builder, sig, args):  # noqa: ANN001, ANN202
        if _X86:
            fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(ir.VoidType(), []),
                                                "llvm.x86.sse2.pause")
            builder.call(fn, [])
        return context.get_dummy_value()

    return sig, codegen
