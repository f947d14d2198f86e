"""The daemon's state on disk (`[state] path`): written atomically, resumed only when it fits.

The estimate itself comes from the core (``FusionCore.export_state`` / ``resume``); this module
is the I/O around it, and the only place the file is read or written.

- Format: one msgpack ``StateFile`` (msgspec): a format version, the wall time of the newest sample
  fused into it, and the core's ``ResumeState``, whose own fingerprint names the config it belongs to.
- Atomic: the bytes go to a temporary file beside the target, are fsynced, then
  ``os.replace``d over it, and the directory is fsynced. A reader (or a restart after a power
  cut or kill -9) sees the old file or the new one, never half of one; a failed write leaves
  the old file as it was.
- Resume: ``load`` refuses, with a reason, a file that is missing, unreadable or truncated
  (``corrupt``), of another format version or config (``foreign``), or older than
  `max_age_s` by wall clock (``stale``: the robot may have been moved while the daemon was
  down, or idle before it). The age runs from the newest sample fused, not from the write: a
  daemon stopped cleanly after minutes without input writes its state at the stop, and that
  state is as old as its data. The caller logs one event either way.
- ``StateSaver``: writes on a thread of its own (an fsync can take milliseconds; the daemon's
  threads publish poses). The daemon's worker hands it the newest export; a write in progress
  is never queued behind, the newest state wins.
"""

from __future__ import annotations

import os
import tempfile
import threading
import time
from pathlib import Path

import msgspec

from ..core.fusion import FusionCore
from ..core.resume import ResumeState
from ..errors import CoreError, TransportError
from ..logs import get_logger
from ..estimator import POSITION

__all__ = ["FILE_VERSION", "StateFile", "StateRefused", "StateSaver", "load_state", "resume_from_file", "save_state"]

log = get_logger("fusiond.state")

FILE_VERSION = 1  # the envelope's layout; the filter state carries its own version


class StateFile(msgspec.Struct, frozen=True, kw_only=True):
    """What the file holds."""

    version: int = FILE_VERSION
    saved_wall: float  # time.time() when its newest sample was fused: its age decides whether a restart resumes it
    state: ResumeState


class StateRefused(TransportError):
    """A state file that is not resumed; ``reason`` is one of missing, corrupt, foreign, stale."""

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(f"{reason}: {detail}")
        self.reason = reason
        self.detail = detail


_encoder = msgspec.msgpack.Encoder()
_decoder = msgspec.msgpack.Decoder(StateFile)


def save_state(path: Path, state: ResumeState, saved_wall: float) -> None:
    """Write ``state`` to ``path`` atomically (temp file, fsync, os.replace, fsync of the directory).

    Raises OSError, leaving any previous file untouched, when the write fails."""
    data = _encoder.encode(StateFile(saved_wall=saved_wall, state=state))
    directory = path.parent
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=directory)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
    try:  # the rename itself is durable only once the directory is on disk
        dfd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(dfd)
    except OSError:
        pass
    finally:
        os.close(dfd)


def load_state(path: Path, fingerprint: str, max_age_s: float, now_wall: float) -> StateFile:
    """The saved state if a restart may resume it; else StateRefused saying why.

    The core checks the state itself again when it resumes (``FusionCore.resume``): this is the
    envelope, the config's fingerprint and the age."""
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise StateRefused("missing", f"no state file at {path}") from None
    except OSError as err:
        raise StateRefused("corrupt", f"cannot read {path}: {err}") from None
    try:
        saved = _decoder.decode(data)
    except (msgspec.DecodeError, msgspec.ValidationError) as err:
        raise StateRefused("corrupt", f"{path} is not a fusiond state file ({len(data)} bytes): {err}") from None
    if saved.version != FILE_VERSION:
        raise StateRefused("foreign", f"state file version {saved.version}, this fusiond reads {FILE_VERSION}")
    if saved.state.fingerprint != fingerprint:
        raise StateRefused("foreign", f"written by another config (fingerprint {saved.state.fingerprint}, this "
                                      f"config {fingerprint})")
    age = now_wall - saved.saved_wall
    if not age <= max_age_s:
        raise StateRefused("stale", f"saved {age:.1f} s ago, more than max_age_s = {max_age_s:g}")
    return saved


def resume_from_file(core: FusionCore, path: Path, max_age_s: float) -> str | None:
    """Before any input: go on from the file when it fits the core's config and is fresh. One log
    event says which: `state_resumed`, or `state_resume_refused` with the reason. Returns None when
    resumed, else that reason."""
    try:
        saved = load_state(path, core.fingerprint, max_age_s, time.time())
        try:
            core.resume(saved.state)
        except CoreError as err:  # fits the config by its fingerprint, yet the numbers are not usable
            raise StateRefused("corrupt", str(err)) from None
    except StateRefused as err:
        log.info("state_resume_refused", path=str(path), reason=err.reason, detail=err.detail)
        return err.reason
    log.info("state_resumed", path=str(path), age_s=round(time.time() - saved.saved_wall, 3),
             stamp=saved.state.stamp, position=saved.state.x[POSITION])
    return None


class StateSaver:
    """A thread that writes the newest state handed to it (``offer``), then waits for the next.

    ``flush`` writes what is pending on the caller's thread and stops the thread: at a clean stop
    the last state must be on disk before the process exits."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._cond = threading.Condition()
        self._pending: tuple[ResumeState, float] | None = None
        self._closed = False
        self.saved = 0  # files written
        self.failed = 0  # writes that raised
        self.last_stamp: float | None = None  # filter stamp of the newest state written
        try:  # a state directory that does not exist yet (a first start) is made, as a log directory would be
            path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            log.error("state_save_failed", path=str(path), error=str(err), count=0)
        self._thread = threading.Thread(target=self._run, name="fusiond-state", daemon=True)
        self._thread.start()

    def offer(self, state: ResumeState, fused_wall: float) -> None:
        """Hand over the newest state and the wall time its newest sample was fused (never blocks on the
        disk; an unwritten older one is replaced)."""
        with self._cond:
            self._pending = (state, fused_wall)
            self._cond.notify()

    def flush(self, state: ResumeState | None = None, fused_wall: float = 0.0, timeout: float = 5.0) -> None:
        """Stop the thread, then write ``state`` (fused last at wall time ``fused_wall``; or whatever is
        still pending) now."""
        with self._cond:
            self._closed = True
            if state is not None:
                self._pending = (state, fused_wall)
            self._cond.notify()
        self._thread.join(timeout)
        with self._cond:
            last, self._pending = self._pending, None
        if last is not None:
            self._write(*last)

    def _run(self) -> None:
        while True:
            with self._cond:
                while self._pending is None and not self._closed:
                    self._cond.wait()
                if self._closed:
                    return  # flush writes what is left, on its own thread
                pending, self._pending = self._pending, None
            self._write(*pending)

    def _write(self, state: ResumeState, fused_wall: float) -> None:
        try:
            save_state(self.path, state, fused_wall)
        except OSError as err:
            self.failed += 1
            if self.failed == 1 or self.failed % 100 == 0:
                log.error("state_save_failed", path=str(self.path), error=str(err), count=self.failed)
            return
        self.saved += 1
        self.last_stamp = state.stamp
