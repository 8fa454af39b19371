"""Where a command writes (docs/reliability.md): nothing is lost, nothing is overwritten by halves.

* ``check_paths`` refuses, before anything starts, an output that is an input of the same
  command, two outputs that are one file, an output that is a directory (or whose folder is
  missing or read-only), and an output that another running Grasp Lab process is writing.
* ``AtomicFile`` writes a file as ``OUT.partial`` beside its target, locked (``flock``) while
  it is written, and renames it to ``OUT`` only when it is finished (``commit``): a kill, a
  full disk or an error leaves the target as it was. A recording's ``.partial`` is a valid
  prefix at every flush, so what a crash leaves is readable (``grasp-lab info``) and is never
  overwritten by the next run.

Plain Python (no bpy): the command line, the recorder and the exports share it.
"""
from __future__ import annotations

import contextlib
import errno
import fcntl
import io
import os
import threading

PARTIAL = ".partial"


_committed: list = []       # outputs renamed into place by this process, in order
_open: list = []            # AtomicFiles neither committed nor discarded


_kept: dict = {}            # files written in place (a sweep's samples.csv): path -> what they hold


def committed() -> list:
    return list(_committed)


def note_kept(path: str, what: str) -> None:
    """A file written in place, not renamed (appended rows a resume reads): a stop says it kept it."""
    _kept[os.path.abspath(path)] = what


def written() -> list:
    """What this process wrote, for a stop's last line: renamed files, then files kept in place."""
    return [p for p in _committed if p not in _kept] + [f"{p} ({what})" for p, what in _kept.items()]


def forget_written() -> None:
    """A new command in this process (Blender) starts with nothing written."""
    _committed.clear()
    _kept.clear()


def close_unfinished() -> list:
    """At the end of a command: outputs still open (an error before they were finished) are
    discarded, except a partial file worth keeping (a recording with ticks), left closed
    beside its untouched target. Returns the partial files left."""
    left = []
    for f in list(_open):
        if f.keep:
            f.leave()
            left.append(f.partial)
        else:
            f.discard()
    return left


class OutputError(ValueError):
    """An output that cannot or must not be written; the message names the file(s) and why."""


def partial_path(path: str) -> str:
    return os.path.abspath(path) + PARTIAL


def same_file(a: str, b: str) -> bool:
    """One file under two names (the same path, a symlink, a hard link)."""
    if os.path.realpath(a) == os.path.realpath(b):
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def _locker(path: str) -> str:
    """``pid N`` of the process holding the flock on ``path`` (from /proc/locks), else ''."""
    try:
        inode = os.stat(path).st_ino
        with open("/proc/locks") as fh:
            for line in fh:
                parts = line.split()
                if len(parts) > 5 and parts[1] == "FLOCK" and parts[5].endswith(f":{inode}"):
                    return f"pid {parts[4]}"
    except OSError:
        pass
    return ""


def writer_of(path: str) -> str:
    """``a Grasp Lab process (pid N)`` when another process holds ``path``'s writer's lock (a
    recording's partial file of a session still running), else ''."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_CLOEXEC)
    except OSError:
        return ""
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        return ""
    except OSError:
        who = _locker(path)
        return f"a Grasp Lab process{f' ({who})' if who else ''}"
    finally:
        os.close(fd)


def _busy(path: str) -> str:
    """Why ``path``'s partial file is busy ('' when it is not): another process holds its lock."""
    partial = partial_path(path)
    holder = writer_of(partial)
    return f"another Grasp Lab process{holder[len('a Grasp Lab process'):]} is writing it ({partial})" if holder else ""


def check_paths(inputs: dict, outputs: dict, folders: tuple = ()) -> None:
    """Refuse (OutputError, naming both) an output that is an input or another output, that is
    a directory, whose folder cannot be written, or that another process is writing.
    ``inputs``/``outputs``: {what (e.g. "--record"): path}; None values are skipped. Outputs
    named in ``folders`` are folders (export --csv): they may exist as directories."""
    ins = {k: v for k, v in inputs.items() if v}
    outs = {k: v for k, v in outputs.items() if v}
    for what, out in outs.items():
        for src, path in ins.items():
            if same_file(out, path):
                raise OutputError(f"{what} {out} is {src} {path}: refusing to write over an input "
                                  f"of this command (name another file)")
        for other, path in outs.items():
            if other < what and same_file(out, path):
                raise OutputError(f"{what} {out} and {other} {path} are one file: name two files")
        target = os.path.abspath(out)
        if what in folders:
            if os.path.exists(target) and not os.path.isdir(target):
                raise OutputError(f"{what} {out}: exists and is not a folder")
            folder = target if os.path.isdir(target) else os.path.dirname(target)
        else:
            if os.path.isdir(target):
                raise OutputError(f"{what} {out}: is a folder (name a file)")
            folder = os.path.dirname(target)
        existing = folder
        while existing and not os.path.isdir(existing):
            if os.path.exists(existing):
                raise OutputError(f"{what} {out}: {existing} is not a folder")
            existing = os.path.dirname(existing)
        if not os.access(existing, os.W_OK | os.X_OK):
            raise OutputError(f"{what} {out}: cannot write in {existing} (read-only or no permission)")
        if what not in folders:
            busy = _busy(target)
            if busy:
                raise OutputError(f"{what} {out}: {busy}")


class AtomicFile:
    """A file written as ``PATH.partial`` (locked) and renamed to ``PATH`` by ``commit``.

    ``keep_partial``: says whether a partial file left by a process that died holds
    something worth keeping (a recording with ticks): then it is refused, not overwritten."""

    def __init__(self, path: str, keep_partial=None):
        # Made whole or not at all: a stop signal arriving while the partial file is opened,
        # locked and wrapped (os.fdopen) waits until this object tracks it.
        with uninterrupted():
            self._create(path, keep_partial)

    def _create(self, path: str, keep_partial) -> None:
        self.path = os.path.abspath(path)
        self.partial = self.path + PARTIAL
        if os.path.isdir(self.path):
            raise OutputError(f"{path}: is a folder (name a file)")
        os.makedirs(os.path.dirname(self.path), exist_ok=True)
        existed = os.path.exists(self.partial)
        fd = os.open(self.partial, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
        locked = False
        try:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                locked = True
            except OSError as ex:
                if ex.errno not in (errno.EWOULDBLOCK, errno.EAGAIN):
                    raise
                who = _locker(self.partial)
                raise OutputError(f"{path}: another Grasp Lab process{f' ({who})' if who else ''} is "
                                  f"writing it ({self.partial})") from None
            if keep_partial is not None and os.fstat(fd).st_size > 0 and keep_partial(self.partial):
                raise OutputError(f"{path}: {self.partial} is left by a session that did not finish "
                                  f"(`grasp-lab info` reads what it holds): move or delete it first")
            os.ftruncate(fd, 0)
            self.done = False
            self.keep = False       # the partial file holds something worth keeping (close_unfinished)
            self.file = os.fdopen(fd, "w+b")
            _open.append(self)
        except BaseException:
            # Refused or failed before this object was tracked: a partial file made here for
            # nothing goes; one that was there, or that another process holds, stays.
            if self in _open:
                _open.remove(self)
            if getattr(self, "file", None) is not None:
                self.file.close()
            else:
                os.close(fd)
            if locked and not existed:
                try:
                    os.unlink(self.partial)
                except OSError:
                    pass
            raise

    def commit(self, verify=None, source: str | None = None) -> str:
        """Flush, sync, verify and rename into place; returns the final path.

        ``verify(path)``: checks what was written (``blend_is_whole``, ``csv_rows``), raising
        OutputError when it is not whole. ``source``: a file another writer made beside the
        target (Blender's save) that goes into place instead of this object's partial file,
        which stays the lock until then. A write, sync or check that fails leaves the target
        as it was, removes what was written and raises OutputError naming the target."""
        if self.done:
            return self.path
        written = source or self.partial
        try:
            self.file.flush()
            if source is None:
                os.fsync(self.file.fileno())
            else:
                _fsync_path(source)
            if verify is not None:
                verify(written)
            os.replace(written, self.path)
            _fsync_path(os.path.dirname(self.path))      # the rename itself survives a power cut
        except (OSError, OutputError) as ex:
            if source is not None:
                _unlink(source)
            if not self.keep:           # a recording's readable prefix is its writer's to cut back
                self.discard()
            why = ex.strerror if isinstance(ex, OSError) and ex.strerror else str(ex)
            raise OutputError(f"{self.path}: could not be written ({why}); it is as it was") from None
        if source is not None:
            _unlink(self.partial)       # the lock file; the lock goes when it is closed below
        self.file.close()
        self.done = True
        _committed.append(self.path)
        _open.remove(self)
        return self.path

    def discard(self) -> None:
        """Nothing worth keeping was written: remove the partial file, leave the target."""
        if not self.done:
            _unlink(self.partial)
            try:
                self.file.close()       # a buffer that cannot go (a full disk) goes with it
            except OSError:
                pass
            self.done = True
            if self in _open:
                _open.remove(self)

    def leave(self, size: int | None = None) -> None:
        """Stop writing and leave the partial file (cut to ``size`` bytes, when given) beside
        the untouched target: what a crash would leave, a readable prefix for a recording."""
        if self.done:
            return
        try:
            self.file.close()       # whatever the buffer holds may fail to go (a full disk)
        except OSError:
            pass
        if size is not None:
            try:
                os.truncate(self.partial, size)
            except OSError:
                pass
        self.done = True
        if self in _open:
            _open.remove(self)

    def __enter__(self):
        return self

    def __exit__(self, kind, value, tb):
        if kind is None:
            self.commit()
        else:
            self.discard()


def write_whole(path: str, data, verify=None) -> str:
    """``data`` (bytes or text) written to ``path`` whole or not at all (AtomicFile)."""
    out = AtomicFile(path)
    try:
        out.file.write(data.encode() if isinstance(data, str) else data)
    except OSError as ex:
        out.discard()
        raise OutputError(f"{out.path}: could not be written ({ex.strerror or ex}); it is as it was") from None
    return out.commit(verify)


def _unlink(path: str) -> None:
    try:
        os.unlink(path)
    except OSError:
        pass


def _fsync_path(path: str) -> None:
    fd = os.open(path, os.O_RDONLY | os.O_CLOEXEC)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


# ------------------------------------------------------------------ checks of what was written

def blend_is_whole(path: str) -> None:
    """A .blend as Blender writes it: the ``BLENDER`` header and, at the end, the ``ENDB``
    block (a file cut short by a full disk has no end). Compressed saves (zstd) are checked
    by their frame header only: their end is inside the compression."""
    with open(path, "rb") as fh:
        head = fh.read(12)
        fh.seek(0, os.SEEK_END)
        size = fh.tell()
        fh.seek(max(size - 64, 0))
        tail = fh.read()
    if head.startswith(b"\x28\xb5\x2f\xfd"):       # zstd: Blender's compressed save
        return
    if not head.startswith(b"BLENDER"):
        raise OutputError(f"not a .blend file ({size} bytes, no BLENDER header)")
    if b"ENDB" not in tail:
        raise OutputError(f"cut short: {size} bytes and no ENDB block at its end")


def csv_rows(rows: int):
    """A check that a CSV file holds its header and exactly ``rows`` records, its last line ended."""
    def verify(path: str) -> None:
        import csv
        with open(path, newline="", encoding="utf-8") as fh:
            text = fh.read()
        if text and not text.endswith("\n"):
            raise OutputError(f"cut short: its last line is not ended ({len(text)} characters)")
        records = sum(1 for _ in csv.reader(io.StringIO(text))) - 1
        if records != rows:
            raise OutputError(f"holds {records} rows, {rows} were written")
    return verify


def write_together(folder: str, writers: dict) -> dict:
    """Files of one command that go in together (export --csv, analyze --csv): each
    ``writers[name](text_file) -> rows`` writes ``folder/name`` as a partial file; when all are
    written, each is checked (its row count) and renamed into place. An error before the
    renames leaves every target as it was (and a folder made here for nothing removed).
    Returns {name: rows}."""
    made = not os.path.isdir(folder)
    os.makedirs(folder, exist_ok=True)
    outs, counts = [], {}
    try:
        for name, write in writers.items():
            out = AtomicFile(os.path.join(folder, name))
            outs.append(out)
            text = io.TextIOWrapper(out.file, newline="", encoding="utf-8")
            try:
                counts[name] = write(text)
                text.flush()
            except OSError as ex:
                raise OutputError(f"{out.path}: could not be written ({ex.strerror or ex}); "
                                  f"it is as it was") from None
            finally:
                text.detach()           # the AtomicFile keeps the file open until it is renamed
        for out, name in zip(outs, writers):
            out.commit(verify=csv_rows(counts[name]))
    except BaseException:
        for out in outs:
            out.discard()
        if made:
            try:
                os.rmdir(folder)        # made here, for nothing
            except OSError:
                pass
        raise
    return counts


# ------------------------------------------------------------------ writes a signal must not cut

_uninterrupted = 0          # nesting depth of uninterrupted() on the main thread
_deferred = None            # the stop a signal asked for inside it (its KeyboardInterrupt's text)


@contextlib.contextmanager
def uninterrupted():
    """A write that a stop signal must not cut in half (a recording's block counted but its
    chunk not written): on the main thread, where Python runs signal handlers, a stop that
    arrives inside is raised as it ends. Other threads see no signals: nothing to do there."""
    global _uninterrupted, _deferred
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    _uninterrupted += 1
    try:
        yield
    finally:
        _uninterrupted -= 1
    if _uninterrupted == 0 and _deferred is not None:
        reason, _deferred = _deferred, None
        raise KeyboardInterrupt(reason)


def defer_stop(reason: str) -> bool:
    """Called by the stop-signal handler: True when the main thread is inside uninterrupted()
    (the stop is raised when it ends), False when it may be raised now."""
    global _deferred
    if _uninterrupted:
        _deferred = reason
        return True
    return False
