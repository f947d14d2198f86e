"""A bag opened and decoded in a forked child while this process gets ready and fuses.

Opening a bag (rosbags' import, its reader, the index), reading it and decoding its samples is a
third of a replay's time and needs nothing the fusion computes; fusing needs each sample in turn. On
a machine with two cores the two run side by side: a child forked once the config is loaded, before
the filter is imported (a config loads without it, and the child reads the bags without numpy:
``kind.ModelIn``, the struct fast paths of ``codecs.bag_readers``), opens the bags, sends what they
hold (the header: the topics, which configured ones are missing, the message count), then their
samples in bag order, pickled in batches, through a pipe. This process meanwhile imports and builds
the filter and the doctor, then takes the samples as it fuses. The child decodes
three to four times faster than the filter fuses, so it is done early (``complete``), and the rest of
the recording is in memory from then on.

A replay whose doctor reads every sample as read (no evaluation holding fixes back) may ask the child for the
doctor's sample part too (``doctor``): the child has every sample long before the filter has fused them, so
once it has sent them it feeds a doctor of its own the same samples in the same order and sends what it made
of them (``Doctor.sample_side``) after the last frame; the replay's doctor adopts it (``doctor_side``). Such
a child is forked with numpy imported, which its doctor needs. Where its part does not arrive (the child
died, or failed at it), the replay feeds its own doctor the samples it kept. The child keeps the samples
for it only up to what the pipe's backlog may hold (BACKLOG batches): a longer recording's doctor is fed
in the replay, as without the child, and the child's memory stays bounded.

Nothing differs from reading in this process: the same BagError when the bags cannot be opened, the
same header, the same samples in the same order, the same count of messages that did not decode
(``decode_errors``, known once every sample has been taken), and a bag damaged halfway raises its
BagError after the samples before the damage, as reading in turn does. A child that ends without a
word (killed, out of memory) loses nothing: the bags are opened and read here, past the samples
already taken, and the log says so (``read_ahead_rerun``). Closing early (the consumer stopped)
stops and reaps the child.

``BagSamples`` is what reading here gives (``replay.bag``); a ``ReadAhead`` answers the same
questions a replay asks of it (``missing``, ``bag_topics``, ``total``, ``decode_errors``, iteration).
"""

from __future__ import annotations

import os
import pickle
import signal
import struct
from collections import deque
from collections.abc import Iterator, Sequence
from itertools import islice
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING

from ..errors import ReplayError
from ..logs import get_logger
from ..processes import fork_writer, stop_child, workers_available, write_all

if TYPE_CHECKING:
    from ..config import Config, SensorConfig
    from ..doctor import SampleSide
    from ..samples import Sample
    from .bag import BagSamples

log = get_logger(__name__)

__all__ = ["ReadAhead", "reading_ahead"]

BATCH = 128  # samples a pickled batch carries: ~17 kB, each a few us to unpickle
PIPE_BYTES = 1 << 20  # the pipe's buffer, asked of Linux (its unprivileged maximum): the child rarely waits
# Batches taken in ahead of the filter at most (~130k samples, tens of MB): beyond, the pipe holds the child
# back, so that a replay streaming an hour of 1 kHz IMU holds what it did reading in turn, not the hour
BACKLOG = 1024
_LENGTH = struct.Struct("<Q")  # a frame: its length, then a pickled (tag, value)
# the child's frames, in order: ("opened", (missing, bag topics, total)), ("batch", samples)...,
# then ("end", decode errors); ("error", exception) in place of any of them ends the stream. Asked for the
# doctor's sample part, the child sends ("doctor", SampleSide) after "end" (nothing when it could not)


def reading_ahead(paths: Sequence[Path | str], sensors: Sequence[SensorConfig],
                  doctor: Config | None = None) -> ReadAhead | None:
    """The bags read ahead in a forked child (``ReadAhead``), or None where that would not help (one CPU,
    or no fork here: ``processes.workers_available``) or cannot be had (no process or pipe left: the log
    says so): the caller reads them itself then. ``doctor``: the config whose doctor's sample part the child
    makes too (module doc)."""
    if workers_available() < 2:
        return None
    try:
        return ReadAhead(paths, sensors, doctor)
    except OSError as err:
        log.warning("read_ahead_unavailable", reason=str(err))
        return None


class ReadAhead:
    """``open_bag_samples(paths, sensors)`` in a forked child. ``opened()`` waits for the bags to be
    open (raising what opening them raised) and returns this reader; iterate once; then ``decode_errors``.
    Use it as a context manager, or ``close()`` it."""

    def __init__(self, paths: Sequence[Path | str], sensors: Sequence[SensorConfig],
                 doctor: Config | None = None) -> None:
        self._paths, self._sensors = [Path(p) for p in paths], list(sensors)
        self._doctor_cfg = doctor
        self.feeds_doctor = doctor is not None  # the caller's doctor is to take its sample part from here
        self._side: SampleSide | None = None
        self.missing: list[str] = []
        self.bag_topics: dict[str, str] = {}
        self.total = 0
        self.decode_errors = 0
        self.complete = False  # every sample has arrived (the child is done): the rest is in memory
        self._header = False
        self._taken = 0  # samples handed to the consumer
        self._batches: deque[list[Sample]] = deque()
        self._buffer = bytearray()
        self._ended: tuple[str, object] | None = None  # the child's last frame ("end" or "error")
        self._eof = False  # the pipe closed: with no last frame, the child died
        self._local: BagSamples | None = None  # the bags opened here, once the child died
        if doctor is not None:
            # the child's doctor needs numpy. Imported here, it is imported once for both processes; imported in
            # the child after its samples (~80 ms), the doctor's part comes after this process's pass has ended
            # (by 45 ms on the Jackal bag, making its replay 8 % slower)
            import numpy  # noqa: F401
        self._read_end, self.pid = self._fork()

    def opened(self) -> ReadAhead:
        """This reader once the bags are open (their header known); what opening them raised, raised here."""
        while not self._header and self._ended is None and not self._eof:
            self._pump(block=True)
        if self._header:
            return self
        if self._ended is not None:  # the bags could not be opened: the child's BagError
            self.close()
            raise self._ended[1]  # type: ignore[misc]
        self._died()  # before the header: open the bags here
        from .bag import open_bag_samples

        try:
            self._local = open_bag_samples(self._paths, self._sensors)
        except BaseException:
            self.close()
            raise
        self._take_header((self._local.missing, self._local.bag_topics, self._local.total))
        return self

    def __iter__(self) -> Iterator[Sample]:
        try:
            while True:
                if self._batches:
                    batch = self._batches.popleft()
                    if len(self._batches) < BACKLOG:
                        self._pump(block=False)  # take what the child has sent meanwhile: it seldom waits
                    self._taken += len(batch)
                    yield from batch
                elif self._ended is not None:
                    tag, value = self._ended
                    if tag == "error":
                        raise value  # type: ignore[misc]  # as reading here would, after the samples before it
                    return
                elif self._eof:  # the pipe closed without a last frame: the child died
                    yield from self._rerun()
                    return
                else:
                    self._pump(block=True)
        finally:
            if not self._doctor_pending():  # else the child is reaped once its doctor's part is taken
                self.close()

    def doctor_side(self) -> SampleSide | None:
        """The doctor's sample part the child made (``feeds_doctor``), asked once every sample has been taken
        (it waits for the child to send it, which it has nearly always done by then: it decodes several times
        faster than the filter fuses); None when it sent none (it died, or failed at it): the caller's doctor
        is then fed the samples itself. The child is reaped."""
        while self._doctor_pending():
            self._pump(block=True)
        self.close()
        return self._side

    def _doctor_pending(self) -> bool:
        """Every sample sent, and the doctor's part still to come from a child that is alive."""
        return (self.feeds_doctor and self._side is None and self._ended is not None and self._ended[0] == "end"
                and not self._eof and self._read_end >= 0)

    def close(self) -> None:
        """Stop the child if it still runs and reap it; close bags opened here (idempotent)."""
        if self._local is not None:
            self._local.close()
            self._local = None
        if self._read_end < 0:
            return
        running = self._ended is None or self._doctor_pending()  # (a doctor's part no one waits for any more)
        fd, self._read_end = self._read_end, -1
        if running:  # still running, or died: a kill is harmless either way
            stop_child(fd, self.pid)
        else:
            os.close(fd)
            os.waitpid(self.pid, 0)

    def __enter__(self) -> ReadAhead:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    def _fork(self) -> tuple[int, int]:
        def write(fd: int) -> None:
            signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle; it stops us
            self._send_all(fd)

        return fork_writer(write, PIPE_BYTES)

    def _send_all(self, fd: int) -> None:
        """In the child: the header, every sample in batches, then the decode errors; an exception in place."""
        from .bag import open_bag_samples

        batch: list[Sample] = []
        kept: list[Sample] | None = None  # for the doctor, once all are sent
        try:
            with open_bag_samples(self._paths, self._sensors) as bag:
                _write(fd, ("opened", (bag.missing, bag.bag_topics, bag.total)))
                if self._doctor_cfg is not None and _keeps_for_doctor(bag.total):
                    kept = []
                for sample in bag:
                    batch.append(sample)
                    if len(batch) == BATCH:
                        _write(fd, ("batch", batch))
                        if kept is not None:
                            kept += batch
                        batch = []
                last: tuple[str, object] = ("end", bag.decode_errors)
        except Exception as err:  # noqa: BLE001 - carried to the parent, which raises it in its place
            last = ("error", err)
        if batch:  # the samples before the end, or before what was raised
            _write(fd, ("batch", batch))
            if kept is not None:
                kept += batch
        try:
            _write(fd, last)
        except (pickle.PicklingError, TypeError, AttributeError):  # an exception that does not pickle: its text
            _write(fd, ("error", ReplayError(f"{type(last[1]).__name__}: {last[1]}")))
        if kept is not None and last[0] == "end":
            self._send_doctor(fd, kept)

    def _send_doctor(self, fd: int, samples: list[Sample]) -> None:
        """In the child, after the last frame: the doctor's sample part of ``samples`` (module doc); nothing
        when making it fails (the parent's doctor is then fed the samples there, and says what fails)."""
        try:
            from ..doctor import Doctor

            doctor = Doctor(self._doctor_cfg)
            for sample in samples:
                doctor.add_sample(sample)
            payload = pickle.dumps(("doctor", doctor.sample_side()), protocol=pickle.HIGHEST_PROTOCOL)
        except Exception:  # noqa: BLE001 - the parent redoes it, where the error shows
            return
        write_all(fd, _LENGTH.pack(len(payload)) + payload)

    def _pump(self, block: bool) -> None:
        """Read what the pipe holds (``block``: wait until a frame is whole, or the pipe closes) and unpickle
        the whole frames."""
        fd, buf = self._read_end, self._buffer
        if fd < 0 or self._eof:
            return
        while True:
            if not block:
                os.set_blocking(fd, False)
            try:
                chunk = os.read(fd, PIPE_BYTES)
            except BlockingIOError:
                return
            finally:
                if not block:
                    os.set_blocking(fd, True)
            if not chunk:  # the child closed its end: nothing more comes
                self._eof = True
                self._frames()
                return
            buf.extend(chunk)
            if self._frames() or not block:
                return

    def _frames(self) -> bool:
        """Unpickle the whole frames in the buffer; did any arrive?"""
        buf, got, at = self._buffer, False, 0
        while len(buf) - at >= _LENGTH.size:
            (n,) = _LENGTH.unpack_from(buf, at)
            start = at + _LENGTH.size
            if len(buf) - start < n:
                break
            with memoryview(buf) as whole, whole[start:start + n] as frame:
                tag, value = pickle.loads(frame)  # the views released before the buffer is cut below
            at = start + n
            got = True
            if tag == "batch":
                self._batches.append(value)
            elif tag == "opened":
                self._take_header(value)
            elif tag == "doctor":
                self._side = value
            else:
                self._ended = (tag, value)
                self.complete = True
                if tag == "end":
                    self.decode_errors = int(value)
        if at:
            del buf[:at]
        return got

    def _take_header(self, header: tuple[list[str], dict[str, str], int]) -> None:
        self.missing, self.bag_topics, self.total = list(header[0]), dict(header[1]), int(header[2])
        self._header = True
        self.feeds_doctor = self.feeds_doctor and _keeps_for_doctor(self.total)  # as the child decides it

    def _died(self) -> None:
        log.warning("read_ahead_rerun", samples_taken=self._taken,
                    reason="the child reading the bags ended without a word: reading them here")

    def _rerun(self) -> Iterator[Sample]:
        """The child died: read the bags here from the start, past the samples already taken."""
        if self._local is None:  # (``opened`` said so when the child died before the header)
            self._died()
        from .bag import open_bag_samples

        bag = self._local = self._local or open_bag_samples(self._paths, self._sensors)
        for sample in islice(bag, self._taken, None):
            self._taken += 1
            yield sample
        self.decode_errors = bag.decode_errors
        self._ended = ("end", self.decode_errors)


def _keeps_for_doctor(total: int) -> bool:
    """Does the child keep a recording of ``total`` messages for the doctor's sample part (module doc)?"""
    return total <= BACKLOG * BATCH


def _write(fd: int, frame: tuple[str, object]) -> None:
    payload = pickle.dumps(frame, protocol=pickle.HIGHEST_PROTOCOL)
    write_all(fd, _LENGTH.pack(len(payload)) + payload)
