"""One writer at a time for every output that is built over time.

A sweep's dataset folder, a frames folder, an OBJ-sequence folder and a USD stage are each
written by one process at a time. The writer holds an exclusive ``fcntl.flock`` on a lock file
for as long as it writes:

* ``.clothsim.lock`` inside an output folder that exists (the folder checks of
  :mod:`clothsim.atomic` and of a sweep's dataset count it as clothsim's own file);
* ``.NAME.clothsim.lock`` beside a file output (a stage), or beside a folder output that does
  not exist yet (it is built under a temporary name and renamed into place at the end).

A second writer does not wait: it stops with one line naming the holder (process id, host and
start time, which the holder writes into the lock file) and writes nothing. The holder removes
the lock file when it is done. The kernel drops a ``flock`` when its process ends, however it
ends, so the lock of a process killed with ``kill -9`` (or of a machine that rebooted) does not
block the next run: that run finds the lock file, takes the lock and removes the file at its end.
A lock file that was removed while another process was about to lock it is noticed (its inode is
no longer the one at the path) and taken again from the path.

On NFS, Linux (2.6.12 and later) emulates ``flock`` with a POSIX byte-range lock over the whole
file, so writers on different clients exclude each other through the server's lock service (NLM,
``lockd``/``statd``, for NFSv3; built into the protocol for NFSv4). Caveats: a client mounted
with ``nolock`` or ``local_lock=flock``/``all`` sees only its own locks, so two machines can then
write the same output at once; a lock held by a client that crashed is released only when the
server notices (the NFSv4 lease time, about 90 s; for NFSv3 when ``statd`` reports the client's
reboot, which never happens for a client that does not come back); and a server with no lock
service answers ``ENOLCK``, which is reported as a warning and the output is then written
unlocked. Because POSIX locks belong to a process, not to an open file, closing any descriptor
of a lock file releases the process's lock on it over NFS: this module therefore never opens a
lock file that the process already holds (it keeps a table of its own locks).
"""

from __future__ import annotations

import contextlib
import datetime
import errno
import fcntl
import hashlib
import json
import os
import socket
import threading
import time
import warnings
from collections.abc import Iterator
from pathlib import Path

from .errors import ClothsimError

__all__ = ["LOCK_NAME", "OutputLock", "covered", "is_lock_name", "lock_beside", "lock_inside", "probe"]

#: The lock file inside a locked folder.
LOCK_NAME = ".clothsim.lock"
_SUFFIX = ".clothsim.lock"
_NAME_MAX = 255
_NAME_TRIES, _NAME_WAIT_S = 20, 0.05

_held: dict[Path, OutputLock] = {}  # this process's locks, by lock file
_held_guard = threading.Lock()


def is_lock_name(name: str) -> bool:
    """True for the name of a lock file clothsim makes (inside a folder or beside an output)."""
    return name == LOCK_NAME or (name.startswith(".") and name.endswith(_SUFFIX))


def beside_name(name: str) -> str:
    """The lock file's name beside an output called ``name`` (shortened to fit NAME_MAX)."""
    full = f".{name}{_SUFFIX}"
    if len(os.fsencode(full)) <= _NAME_MAX:
        return full
    digest = hashlib.sha1(os.fsencode(name)).hexdigest()[:16]
    return f".{name[:120]}.{digest}{_SUFFIX}"


class OutputLock:
    """A held lock on the output ``target``; :meth:`release` removes the lock file and unlocks."""

    def __init__(self, target: Path, path: Path, fd: int | None) -> None:
        self.target = target
        self.path = path
        self._fd = fd

    def release(self) -> None:
        """Remove the lock file (while still holding it, so nobody locks a file about to go) and unlock."""
        with _held_guard:
            if _held.get(self.path) is self:
                del _held[self.path]
        fd, self._fd = self._fd, None
        if fd is None:
            return
        with contextlib.suppress(OSError):
            if _same_file(fd, self.path):
                os.unlink(self.path)
        os.close(fd)  # releases the flock


def covered(path: Path) -> bool:
    """True if this process holds a lock on ``path`` or on a folder above it."""
    path = _absolute(path)
    with _held_guard:
        return any(path == lock.target or lock.target in path.parents for lock in _held.values())


def lock_inside(folder: Path, label: str) -> OutputLock:
    """Lock the existing folder output ``folder`` (its ``.clothsim.lock``)."""
    return _acquire(_absolute(folder), _absolute(folder) / LOCK_NAME, label)


def lock_beside(dest: Path, label: str) -> OutputLock:
    """Lock the output ``dest`` (a file, or a folder that does not exist yet) by a lock file beside it."""
    dest = _absolute(dest)
    return _acquire(dest, dest.parent / beside_name(dest.name), label)


@contextlib.contextmanager
def holding(lock: OutputLock) -> Iterator[OutputLock]:
    """Release ``lock`` when the block ends, however it ends."""
    try:
        yield lock
    finally:
        lock.release()


def probe(lock_file: Path, label: str) -> None:
    """Raise the holder's line if another process holds ``lock_file`` now; create nothing.

    For checks made before a long computation: the writer takes the lock itself later.
    """
    with _held_guard:
        mine = _absolute(lock_file) in _held
    if mine or covered(lock_file.parent if lock_file.name == LOCK_NAME else lock_file):
        return  # never open a lock file this process holds (see the module's note on NFS)
    try:
        fd = os.open(lock_file, os.O_RDONLY | os.O_CLOEXEC | os.O_NOFOLLOW)
    except OSError:
        return  # no lock file: nobody holds it (or it cannot be read, which the writer reports)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            raise _in_use(label, fd) from None
        except OSError:
            return
    finally:
        os.close(fd)


# -- acquiring -----------------------------------------------------------------------------------
def _acquire(target: Path, path: Path, label: str) -> OutputLock:
    with _held_guard:
        if path in _held:  # one process, one writer: a second writer in it is refused too
            raise ClothsimError(f"{label}: is being written by this process already")
    for _ in range(20):
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC | os.O_NOFOLLOW, 0o644)
        except OSError as exc:
            reason = " ".join((exc.strerror or str(exc)).split())
            raise ClothsimError(f"{label}: cannot create the lock file {path}: {reason}") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            error = _in_use(label, fd)
            os.close(fd)
            raise error from None
        except OSError as exc:
            os.close(fd)
            if exc.errno not in (errno.ENOLCK, errno.EOPNOTSUPP, errno.EINVAL, errno.ENOSYS):
                raise ClothsimError(f"{label}: cannot lock {path}: {exc.strerror or exc}") from None
            with contextlib.suppress(OSError):
                os.unlink(path)
            warnings.warn(f"{label}: written without a lock: the file system offers none "
                          f"({exc.strerror or exc}); make sure no other clothsim writes it meanwhile", stacklevel=3)
            lock = OutputLock(target, path, None)
            break
        if not _same_file(fd, path):  # its holder removed it between our open and our lock
            os.close(fd)
            continue
        _write_holder(fd)
        lock = OutputLock(target, path, fd)
        break
    else:  # pragma: no cover - twenty holders in a row removing the file under us
        raise ClothsimError(f"{label}: cannot lock {path}: it keeps being replaced")
    with _held_guard:
        _held[path] = lock
    return lock


def _same_file(fd: int, path: Path) -> bool:
    try:
        a, b = os.fstat(fd), os.stat(path, follow_symlinks=False)
    except OSError:
        return False
    return (a.st_dev, a.st_ino) == (b.st_dev, b.st_ino)


def _write_holder(fd: int) -> None:
    started = datetime.datetime.now().astimezone().isoformat(timespec="seconds")
    text = json.dumps({"pid": os.getpid(), "host": socket.gethostname(), "started": started}) + "\n"
    with contextlib.suppress(OSError):  # who holds it is for messages only; the lock is the flock
        os.ftruncate(fd, 0)
        os.pwrite(fd, text.encode(), 0)
        os.fsync(fd)  # over NFS another client reads it only once it reaches the server


def _in_use(label: str, fd: int) -> ClothsimError:
    who = "another clothsim process (which has only just started)"
    # A holder that has only just taken the lock writes its name a moment later (truncate, write,
    # fsync): wait up to a second for it, so that two commands started together name each other.
    for _ in range(_NAME_TRIES):
        try:
            data = json.loads(os.pread(fd, 4096, 0).decode("utf-8"))
            who = (f"clothsim (pid {int(data['pid'])} on host {' '.join(str(data['host']).split())[:64]}, "
                   f"started {' '.join(str(data['started']).split())[:32]})")
            break
        except (OSError, ValueError, KeyError, TypeError, UnicodeDecodeError):
            time.sleep(_NAME_WAIT_S)
    return ClothsimError(f"{label}: being written by {who}; wait for it to end or choose another output")


def _absolute(path: Path) -> Path:
    return Path(os.path.abspath(path))
