"""Watching Numba compile: a record of each kernel compiled and for how long
(:class:`CompileRecorder`), and the first-run notice (:class:`CompileNotice`).

Kept apart from :mod:`clothsim.cli.compile` because it needs Numba at import, and the command line
loads that module to build its parser: a command that runs no kernel never imports Numba.
"""

from __future__ import annotations

import sys
import threading
import time
from dataclasses import dataclass
from typing import Any, TextIO

from numba.core import event

#: Cold compile of the frame kernel as a user first meets it (``clothsim simulate pinned2``, every
#: cache empty, measured with ``clothsim bench compile`` on a 2-core machine).
FIRST_RUN_SECONDS = 10
#: The same for a scene in the contact self-collision mode, whose kernels take most of it
#: (``clothsim bench compile --commands contact``), and for one that also has a triangle mesh
#: (the bundled ``skirt`` and ``drum`` scenes' cold starts, docs/performance-compile.md).
CONTACT_FIRST_RUN_SECONDS = 30
CONTACT_MESH_FIRST_RUN_SECONDS = 45
#: The same for a scene with a triangle mesh, as a collider or as the cloth, whose passes and
#: plans are their own (the bundled ``mesh`` and ``cape`` scenes' cold starts, docs/performance-compile.md).
MESH_FIRST_RUN_SECONDS = 30


@dataclass(frozen=True)
class Compiled:
    """One compile: the kernel, the groups or types it was compiled for, and its seconds
    (``own``: not counting the kernels it called that were compiled inside it)."""

    kernel: str
    variant: str
    seconds: float
    own: float
    depth: int


def _group_name(arg: Any) -> str | None:
    """A frame kernel's state group by name: "-" for a pass the scene does not use, the names
    joined by "+" for a tuple of groups (the forces), None for any other argument."""
    cls = getattr(arg, "instance_class", None)
    if cls is not None:
        return cls.__name__
    if str(arg) == "none":
        return "-"
    items = getattr(arg, "types", None)
    if isinstance(items, tuple) and all(getattr(t, "instance_class", None) is not None for t in items):
        return "+".join(t.instance_class.__name__ for t in items) or "-"
    return None


def _kernel_name(data: dict[str, Any]) -> tuple[str, str]:
    disp = data.get("dispatcher")
    func = getattr(disp, "py_func", None)
    name = f"{func.__module__}.{func.__qualname__}" if func is not None else str(disp)
    args = data.get("args") or ()
    groups = [_group_name(a) for a in args]
    variant = ", ".join(g for g in groups if g) if any(g and g != "-" for g in groups) else ""
    return name, variant


class CompileRecorder(event.Listener):
    """Collects every Numba compile of this process as :class:`Compiled` records."""

    def __init__(self) -> None:
        self.records: list[Compiled] = []
        self._stack: list[list[float]] = []

    def on_start(self, ev: event.Event) -> None:
        self._stack.append([time.perf_counter(), 0.0])

    def on_end(self, ev: event.Event) -> None:
        began, inner = self._stack.pop()
        seconds = time.perf_counter() - began
        if self._stack:
            self._stack[-1][1] += seconds
        name, variant = _kernel_name(ev.data)
        self.records.append(Compiled(name, variant, seconds, seconds - inner, len(self._stack)))

    def total(self) -> float:
        """Seconds spent compiling (outermost compiles only)."""
        return sum(r.seconds for r in self.records if r.depth == 0)


class CompileNotice(event.Listener):
    """Says on ``stream`` that kernels are being compiled, once, when the first compile starts;
    on a terminal it also shows which kernel and the seconds so far while a compile runs."""

    def __init__(self, stream: TextIO | None = None, estimate: float = FIRST_RUN_SECONDS) -> None:
        self._stream = stream
        self.estimate = estimate
        self.announced = False
        self.depth = 0
        self.kernel = ""
        self._bar: Any = None
        self._began = 0.0
        self._lock = threading.Lock()

    @property
    def stream(self) -> TextIO:
        """The stream given, or the process's stderr as it is now (not as it was at install: a
        caller may have replaced it since, and closed the one it replaced)."""
        return self._stream if self._stream is not None else sys.stderr

    def on_start(self, ev: event.Event) -> None:
        with self._lock:
            self.depth += 1
            if self.depth > 1:
                return
            self.kernel = _kernel_name(ev.data)[0].rsplit(".", 1)[-1].lstrip("_")
            if not self.announced:
                self.announced = True
                self._began = time.perf_counter()
                try:
                    print(f"clothsim: compiling kernels for this CPU (first run only, about {self.estimate:.0f} s)...",
                          file=self.stream, flush=True)
                except (OSError, ValueError):  # a closed or broken stream: the compile goes on unannounced
                    return
                if self.stream.isatty():
                    threading.Thread(target=self._tick, name="clothsim-compile-progress", daemon=True).start()
            if self.stream.isatty() and self._bar is None:
                # made here, not in the thread: tqdm's first lock taken in a second thread while
                # this one is compiling (and importing) can hang that thread
                from tqdm import tqdm

                self._bar = tqdm(total=round(self.estimate), desc=f"compiling {self.kernel}", unit="s",
                                 file=self.stream, leave=False, bar_format="{desc}: {bar} {n:.0f}/{total:.0f} s")

    def on_end(self, ev: event.Event) -> None:
        with self._lock:
            self.depth -= 1
            if self.depth == 0 and self._bar is not None:
                # cleared before the command prints anything of its own
                self._bar.close()
                self._bar = None

    def _tick(self) -> None:
        while True:
            time.sleep(0.25)
            with self._lock:
                if self._bar is not None:
                    self._bar.n = min(time.perf_counter() - self._began, self._bar.total)
                    self._bar.set_description_str(f"compiling {self.kernel}", refresh=False)
                    self._bar.refresh()


_installed: CompileNotice | None = None


def expect(seconds: float) -> None:
    """Raise the installed notice's estimate to ``seconds`` (a run about to compile more than a
    plain scene); nothing if no notice is installed or it has already been shown."""
    if _installed is not None and not _installed.announced:
        _installed.estimate = max(_installed.estimate, seconds)


def install_notice() -> CompileNotice:
    """Register the process's one :class:`CompileNotice` (on stderr) for the rest of this process;
    calling it again (``main()`` run twice in one process) returns the same notice."""
    global _installed
    if _installed is None:
        _installed = CompileNotice()
        event.register("numba:compile", _installed)
    return _installed
