"""Cached kernels are valid for one version of the whole package, not of one file.

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

from numba.core import caching

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


def install() -> None:
    """Put the stamped locators in front of Numba's (once; before any kernel is decorated)."""
    impl = getattr(caching, "CacheImpl", None) or caching._CacheImpl  # renamed in Numba 0.6x
    if getattr(impl, "_clothsim_stamped", False):
        return
    mixin = getattr(caching, "_SourceFileBackedLocatorMixin", None)
    bases = [c for c in impl._locator_classes if mixin is not None and issubclass(c, mixin)]
    impl._locator_classes = [_stamped(c) for c in bases] + list(impl._locator_classes)
    impl._clothsim_stamped = True
