"""One base for every error fusiond raises on purpose, one subclass per layer.

A caller that wants "anything fusiond refused" catches ``FusiondError``; one that
handles a layer catches its class. Each also has the builtin base its kind of error
has (``ConfigError`` and ``BagError`` are ``ValueError``s, ``SessionError`` a
``RuntimeError``), so an ``except ValueError`` catches a refused value too; the layer
modules re-export them (``fusiond.config.ConfigError``, ``fusiond.replay.bag.BagError``,
``fusiond.transport.session.SessionError``) beside the code that raises them.
"""

from __future__ import annotations

__all__ = [
    "FusiondError", "ConfigError", "EstimatorError", "CoreError", "CodecError", "TransportError",
    "SessionError", "PlaybackError", "ReplayError", "BagError", "CalibrationError",
    "DoctorError", "TuneError",
]


class FusiondError(Exception):
    """Base of every error fusiond raises deliberately; its message is phrased for the user."""


class ConfigError(FusiondError, ValueError):
    """A configuration problem, phrased for the user (one line, names the key)."""


class EstimatorError(FusiondError, ValueError):
    """A value or model the estimator cannot take (a zero quaternion, a non-positive time constant)."""


class CoreError(FusiondError, RuntimeError):
    """The fusion core asked for something it cannot give yet (an estimate before any sample)."""


class CodecError(FusiondError, ValueError):
    """A payload or message that the codecs cannot turn into a sample or a wire message."""


class TransportError(FusiondError, RuntimeError):
    """Zenoh I/O failed or a peer did not answer."""


class SessionError(TransportError):
    """Zenoh accepted the configuration but could not open (port in use, unreachable router, ...)."""


class PlaybackError(TransportError, ValueError):
    """`fusiond play` cannot play as asked (a bad rate)."""


class ReplayError(FusiondError):
    """Offline replay cannot run as asked."""


class BagError(ReplayError, ValueError):
    """A bag that cannot be replayed as configured, phrased for the user."""


class CalibrationError(FusiondError, ValueError):
    """Not enough or unusable data to calibrate from."""


class DoctorError(FusiondError, ValueError):
    """The doctor's checks cannot be put in an order (a check that needs one that is not there, or a cycle)."""


class TuneError(FusiondError, RuntimeError):
    """A replay of tune's or of the doctor's advice ended without a result (a forked replay that died)."""
