"""The crash-safe result file of a run (:class:`ResultFile`): a working copy, atomic commits, a lock
that dies with its process, free space checked before each write, a file of another scene or format
refused before anything is written.

The run works on a sibling copy ``FILE.work`` and each *commit* (after each study, and every few seconds
of a grid) closes it, copies it to ``FILE.commit``, fsyncs that and renames it over ``FILE``
(``os.replace`` is atomic), so ``FILE`` is always a complete HDF5 file: the previous commit or the
new one. A lock file ``FILE.lock`` (pid and host, a POSIX record lock that dies with its process)
keeps a second run out. The file stores its scene's identity (``scene_hash``, ``scene``) and each
study the identity of its options (``request_hash``, ``request``), so that a different scene is
refused before anything is written.
"""

from __future__ import annotations

import contextlib
import errno
import json
import logging
import os
import shutil
import socket
import time
from pathlib import Path
from typing import Any, Iterator, Mapping

from ._identity import canonical, differing_paths, digest
from ._integrity import check_root, seal_root
from ._store import FORMAT_VERSION, ResultFileError, StorageError, stamp
from ._writes import deferred_interrupts, forget_open, interrupts_handled, register_open

logger = logging.getLogger(__name__)

#: Free space kept beyond what a write or commit needs (HDF5 metadata, other writers on the disk).
SPACE_RESERVE = 1 << 20
#: A grid commits at most this often (s), and spends at most about 5 % of its time committing.
COMMIT_INTERVAL = 2.0
_COMMIT_SHARE = 0.05

def _describe_os_error(error: OSError) -> str:
    return error.strerror or str(error)


class ResultFile:
    """The result file ``path`` of one run, written so that any kill leaves it readable.

    ``handle`` is the open h5py File of the working copy ``PATH.work``; :meth:`commit` (or
    :meth:`maybe_commit`, time-batched) makes its state the content of ``path`` atomically;
    :meth:`writing` wraps a write (interrupts wait for its end, free space checked first). Use as a
    context manager: on leaving, the work is committed (also after Ctrl-C or SIGTERM), the working
    copy removed and the lock released; a write that failed half-way (an ``OSError``, a full disk)
    is not committed. ``scene``: the identity of the scene (JSON-like dict); an existing file of
    another scene is refused, naming the differing keys, unless ``overwrite`` (start afresh).
    """

    def __init__(self, path: str | Path, *, scene: Mapping[str, Any] | None = None,
                 overwrite: bool = False, commit_interval: float = COMMIT_INTERVAL) -> None:
        self.path = Path(path)
        self.work = self.path.with_name(self.path.name + ".work")
        self.staging = self.path.with_name(self.path.name + ".commit")
        self.lock_path = self.path.with_name(self.path.name + ".lock")
        self.scene = None if scene is None else json.loads(canonical(scene))
        self.overwrite = overwrite
        self.commit_interval = commit_interval
        self._handle: Any = None
        self._lock_fd: int | None = None
        self._last_commit = time.monotonic()
        self._interval = commit_interval
        self._broken = False
        self._root_damage = ""   # the file's own attributes fail their checksum (found on opening)
        self._dirty = False  # written since the last commit (a run that wrote nothing commits nothing)
        self._before_commit: list[Any] = []   # writes waiting in memory (a grid's points), done first
        self._signals = contextlib.ExitStack()
        #: attributes a study group gets when it is created (``studies.cli._run``: what was asked of it)
        self.study_attrs: dict[str, dict[str, Any]] = {}

    # -- opening -------------------------------------------------------------------------------
    def __enter__(self) -> "ResultFile":
        self._signals.enter_context(interrupts_handled())
        try:
            with deferred_interrupts():
                self._open()
        except BaseException:
            self._release()
            self._signals.close()
            raise
        return self

    def _open(self) -> None:
        import h5py

        self._check_path()
        self._lock()
        existed = self.path.exists()
        if existed:
            existed = self._check_existing()
        self._check_space(2 * (self.path.stat().st_size if existed else 0), at_start=True)
        for stale in (self.work, self.staging):
            stale.unlink(missing_ok=True)  # left by a killed run: scratch, the lock is ours
        try:
            if existed and not self.overwrite:
                shutil.copyfile(self.path, self.work)
            # PATH.lock guards the run; HDF5's own lock (flock) would be inherited by forked pool
            # workers and block the reopening after each commit
            self._handle = h5py.File(self.work, "a", locking=False)
        except OSError as error:
            raise ResultFileError(f"result file {str(self.path)!r}: cannot write its working copy "
                                  f"{str(self.work)!r} ({_describe_os_error(error)})") from None
        register_open(self.work, self)
        if "flexvib_version" not in self._handle.attrs:
            stamp(self._handle)
        if self.scene is not None:
            self._handle.attrs["scene_hash"] = digest(self.scene)
            self._handle.attrs["scene"] = canonical(self.scene)

    def refusal(self, cause: str, fix: str = "") -> ResultFileError:
        """The error refusing this file: ``result file 'PATH': cause; fix``."""
        return ResultFileError(f"result file {str(self.path)!r}: {cause}" + (f"; {fix}" if fix else ""))

    def _check_path(self) -> None:
        if self.path.is_dir():
            raise self.refusal("is a folder",
                               f"expected the path of a file, e.g. {str(self.path / 'run.h5')!r}")
        ancestor = self.path.parent
        while not ancestor.exists() and ancestor != ancestor.parent:
            ancestor = ancestor.parent
        if not ancestor.is_dir():
            raise self.refusal(f"{str(ancestor)!r} is a file, not a folder", "choose another --out")
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)  # as a user expects of --out a/b.h5
        except OSError as error:
            raise self.refusal(f"cannot create its folder ({_describe_os_error(error)})") from None
        if self.path.exists() and not self.path.is_file():
            raise self.refusal("is not a regular file", "choose another --out")
        if self.path.exists() and not os.access(self.path, os.R_OK | os.W_OK):
            raise self.refusal("is read-only (no permission to replace it)", "choose another --out")
        if not os.access(self.path.parent, os.W_OK | os.X_OK):
            raise self.refusal(f"no permission to write in the folder {str(self.path.parent)!r}",
                             "choose another --out")

    def _lock(self) -> None:
        """Take ``PATH.lock`` (a POSIX record lock: released by the kernel when its process dies,
        and not inherited by worker processes); report a lock a dead run left behind."""
        import fcntl

        while True:
            try:
                fd = os.open(self.lock_path, os.O_RDWR | os.O_CREAT, 0o644)
            except OSError as error:
                raise self.refusal(f"cannot create the lock file {str(self.lock_path)!r} "
                                 f"({_describe_os_error(error)})", "choose another --out") from None
            try:
                fcntl.lockf(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                holder = os.pread(fd, 200, 0).decode(errors="replace").strip() or "unknown process"
                os.close(fd)
                raise self.refusal(f"is being written by another flexvib run ({holder})",
                                 "wait for it to end, or write to another file with --out") from None
            try:
                same = os.stat(self.lock_path).st_ino == os.fstat(fd).st_ino
            except FileNotFoundError:
                same = False
            if same:
                break
            os.close(fd)  # the file was removed by a run that just ended: lock the new one
        left = os.pread(fd, 200, 0).decode(errors="replace").strip()
        if left:
            logger.warning("%s: released the lock left by a run that ended without finishing (%s)",
                           self.path, left)
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"pid {os.getpid()} on {socket.gethostname()}".encode(), 0)
        self._lock_fd = fd

    def _check_existing(self) -> bool:
        """Refuse a file that is not flexvib's or holds another scene (before writing anything).
        A file that cannot be read as a flexvib result (not HDF5, or its own metadata damaged) is
        refused, or with ``overwrite`` moved aside to ``PATH.damaged-N`` (nothing is destroyed);
        returns whether the file is still there."""
        import h5py

        unreadable = self._unreadable()
        if unreadable and not _looks_like_flexvib(self.path):   # someone else's file: never touched
            raise self.refusal("exists and is not an HDF5 file" if not h5py.is_hdf5(self.path)
                               else f"{unreadable.removeprefix('is damaged: ')}",
                               "remove it or choose another --out")
        if unreadable:
            if not self.overwrite:
                raise self.refusal(f"{unreadable}, so it cannot be resumed",
                                   "run with --overwrite to move it aside (to PATH.damaged-N) and start "
                                   "afresh, or choose another --out")
            self._move_aside(unreadable)
            return False
        with h5py.File(self.path, "r", locking=False) as handle:
            attrs, names = dict(handle.attrs), list(handle)
        if "flexvib_version" not in attrs:
            raise self.refusal("is an HDF5 file not written by flexvib; refusing to change it",
                             "choose another --out")
        if self.overwrite and self._root_damage:   # its own metadata damaged: kept aside, not replaced
            self._move_aside(f"is damaged: {self._root_damage}")
            return False
        if self.overwrite:
            return True
        written = int(attrs.get("format_version", 1))
        if written != FORMAT_VERSION and names:
            raise self.refusal(
                f"was written by flexvib {attrs.get('flexvib_version', '?')} in result format {written}; "
                f"this flexvib writes format {FORMAT_VERSION} and "
                + ("cannot read it" if written > FORMAT_VERSION else "does not add to an older file"),
                "run with --overwrite to start it afresh, or choose another --out"
                + (" (studies.load still reads it)" if written < FORMAT_VERSION else ""))
        if self.scene is not None:
            self._check_scene(attrs, names)
        if self._root_damage:   # after the checks above, which name what they find in words
            raise self.refusal(f"is damaged: {self._root_damage}, so it cannot be resumed",
                               "run with --overwrite to start it afresh, or choose another --out")
        return True

    def _check_scene(self, attrs: Mapping[str, Any], names: list) -> None:
        """Refuse a file of another scene, or one that did not record its scene's identity."""
        if "scene_hash" not in attrs:
            if names:
                raise self.refusal(
                    f"was written by flexvib {attrs.get('flexvib_version', '?')}, which did not record "
                    f"its scene's identity, so resuming could mix two scenes",
                    "run with --overwrite to start it afresh, or choose another --out")
            return
        if attrs["scene_hash"] != digest(self.scene):
            try:
                paths = differing_paths(json.loads(attrs.get("scene", "{}")), self.scene)
            except json.JSONDecodeError:
                paths = ["(unknown)"]
            raise self.refusal(f"holds the results of another scene (differing: {', '.join(paths)})",
                             "write to another file with --out, or run with --overwrite to start it afresh")

    def _unreadable(self) -> str:
        """Why the existing file cannot be read as a result file ("" if it can): not HDF5, HDF5 that
        does not open or list its groups, or (format 3) attributes that fail their checksum."""
        import h5py

        if not h5py.is_hdf5(self.path):
            return "is damaged: it is not readable as HDF5 (its first bytes are damaged)"
        try:
            with h5py.File(self.path, "r", locking=False) as handle:
                attrs = dict(handle.attrs)
                list(handle)
                written = int(attrs.get("format_version", 1)) if "flexvib_version" in attrs else 0
                root = check_root(handle, written) if written >= 3 else None
        except (OSError, RuntimeError, KeyError, ValueError, TypeError) as error:
            cause = _describe_os_error(error) if isinstance(error, OSError) else str(error)
            return f"is damaged: its HDF5 metadata cannot be read ({cause})"
        self._root_damage = root.cause if root is not None and root.damaged else ""
        return ""

    def _move_aside(self, why: str) -> None:
        """Rename the unreadable file to the first free ``PATH.damaged-N`` and say so in one line."""
        number = 1
        while True:
            aside = self.path.with_name(f"{self.path.name}.damaged-{number}")
            if not aside.exists():
                break
            number += 1
        try:
            os.replace(self.path, aside)
        except OSError as error:
            raise self.refusal(f"{why}, and it cannot be moved aside to {str(aside)!r} "
                               f"({_describe_os_error(error)})", "choose another --out") from None
        logger.warning("%s %s; moved it aside to %s and started afresh", self.path, why, aside)

    # -- writing -------------------------------------------------------------------------------
    @property
    def handle(self) -> Any:
        """The open h5py File of the working copy (a new object after each commit)."""
        return self._handle

    def _free(self) -> int:
        stats = os.statvfs(self.path.parent)
        return stats.f_bavail * stats.f_frsize

    def _check_space(self, needed: int, *, at_start: bool = False) -> None:
        free = self._free()
        if free >= needed + SPACE_RESERVE:
            return
        cause = (f"not enough free space on its disk: {free / 2**20:.1f} MiB free, about "
                 f"{(needed + SPACE_RESERVE) / 2**20:.1f} MiB needed")
        if at_start:
            raise self.refusal(cause, "free some space or choose another --out")
        raise StorageError(f"result file {str(self.path)!r}: {cause}; it holds what was saved before "
                           f"(free some space and run the same command to resume)")

    def _work_size(self) -> int:
        try:
            return self.work.stat().st_size
        except FileNotFoundError:
            return 0

    @contextlib.contextmanager
    def writing(self, extra: int = 0) -> Iterator[None]:
        """A write of about ``extra`` bytes into the working copy: free space checked first (for the
        write and the next commit's copy), interrupts wait for its end, a failure marks the copy as
        not to be committed."""
        self._check_space(self._work_size() + 2 * extra)
        with deferred_interrupts():
            self._dirty = True
            try:
                yield
            except BaseException:
                self._broken = True
                raise

    def before_commit(self, flush: Any) -> None:
        """Call ``flush()`` (a write of what waits in memory: ``studies._grid.GridStore.flush``) before
        the next commit, once."""
        if flush not in self._before_commit:
            self._before_commit.append(flush)

    def commit(self) -> None:
        """Make the working copy's state the content of ``path``, atomically (nothing to do when
        nothing was written since the last commit), after the writes waiting in memory."""
        import h5py

        waiting, self._before_commit = self._before_commit, []
        for flush in waiting:
            flush()
        if not self._dirty:
            return
        if self._broken:
            raise StorageError(f"result file {str(self.path)!r}: a write failed half-way; it holds "
                               f"what was saved before")
        start = time.monotonic()
        with deferred_interrupts():
            self._check_space(self._work_size())
            seal_root(self._handle)   # the file's own attributes, checked before the next resume
            self._handle.close()
            try:
                shutil.copyfile(self.work, self.staging)
                with open(self.staging, "rb") as staged:
                    os.fsync(staged.fileno())
                os.replace(self.staging, self.path)
                _fsync_folder(self.path.parent)
            except OSError as error:
                self.staging.unlink(missing_ok=True)
                cause = ("the disk is full" if error.errno in (errno.ENOSPC, errno.EDQUOT)
                         else _describe_os_error(error))
                raise StorageError(f"result file {str(self.path)!r}: cannot save ({cause}); it holds "
                                   f"what was saved before") from None
            finally:
                self._handle = h5py.File(self.work, "a", locking=False)
        self._dirty = False
        spent = time.monotonic() - start
        self._last_commit = time.monotonic()
        self._interval = max(self.commit_interval, spent / _COMMIT_SHARE)

    def rebuild_without(self, damaged: list[str]) -> None:
        """Make the working copy afresh from the last commit: the file's attributes and every study
        but those named in ``damaged``, copied object by object into a new file, so that no damaged
        HDF5 metadata of theirs (an object header, a heap) is carried into the run's writes."""
        import h5py

        fresh = self.work.with_name(self.work.name + ".new")
        forget_open(self.work)
        self._handle.close()
        try:
            with h5py.File(self.path, "r", locking=False) as source, \
                    h5py.File(fresh, "w", locking=False) as target:
                for key, value in source.attrs.items():
                    target.attrs[key] = value
                for name in source:
                    if name not in damaged:
                        _copy_if_intact(source, target, name)
            os.replace(fresh, self.work)
        except (OSError, RuntimeError, KeyError, ValueError) as error:
            fresh.unlink(missing_ok=True)
            raise self.refusal(f"is damaged beyond repair ({type(error).__name__}: {error})",
                               "run with --overwrite to start it afresh, or choose another --out") from None
        finally:
            self._handle = h5py.File(self.work, "a", locking=False)
            register_open(self.work, self)
        self._dirty = True

    def maybe_commit(self) -> None:
        """Commit when the last commit is older than the commit interval (grids batch their points)."""
        if time.monotonic() - self._last_commit >= self._interval:
            self.commit()

    # -- closing -------------------------------------------------------------------------------
    def __exit__(self, kind: type | None, error: BaseException | None, traceback: Any) -> None:
        try:
            with deferred_interrupts():
                if self._handle is not None and not self._broken and (
                        error is None or not isinstance(error, (OSError, StorageError))):
                    try:
                        self.commit()
                    except StorageError as failure:
                        if error is None:
                            raise
                        logger.error("%s", failure)
        finally:
            self._release()
            self._signals.close()

    def _release(self) -> None:
        if self._handle is not None:
            forget_open(self.work)
            try:
                self._handle.close()
            except Exception:  # a handle whose write failed: the copy is scratch anyway
                pass
            self._handle = None
        if self._lock_fd is not None:  # the scratch files are ours only under the lock
            for scratch in (self.work, self.staging):
                scratch.unlink(missing_ok=True)
            self.lock_path.unlink(missing_ok=True)  # while still holding it (see _lock)
            os.close(self._lock_fd)
            self._lock_fd = None


def _copy_if_intact(source: Any, target: Any, name: str) -> None:
    """Copy the study ``name`` from ``source`` into ``target`` unless it (or its copy) does not read
    back: damaged metadata surfaces when an object is opened or copied; it is then computed again."""
    from ._integrity import check_group
    from ._store import format_of

    try:
        source.copy(source[name], target, name=name)
        check = check_group(target[name], format_of(target[name]))
        broken = check.damaged and check.points is None
    except (KeyError, OSError, RuntimeError, ValueError):
        broken = True
    if broken:
        logger.warning("%s: damaged (it does not read back); recomputing it", name)
        if name in target:
            del target[name]


#: Bytes every flexvib result file holds in its root group's attribute names (read to tell a
#: damaged result file from someone else's file), and how much of a file is searched for them.
_FLEXVIB_MARK = b"flexvib_version"
_MARK_SEARCH = 64 << 20


def _looks_like_flexvib(path: Path) -> bool:
    """Whether the bytes of ``path`` hold flexvib's mark (a damaged result file rather than another
    program's file, which ``--overwrite`` must leave alone)."""
    try:
        with open(path, "rb") as stream:
            tail, read = b"", 0
            while read < _MARK_SEARCH:
                block = stream.read(1 << 20)
                if not block:
                    return False
                if _FLEXVIB_MARK in tail + block:
                    return True
                tail, read = block[-len(_FLEXVIB_MARK):], read + len(block)
    except OSError:
        return False
    return False


def _fsync_folder(folder: Path) -> None:
    """Make a rename in ``folder`` durable (a no-op where folders cannot be opened)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)
