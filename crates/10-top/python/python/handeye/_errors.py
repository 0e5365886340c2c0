"""The exceptions and the warning of handeye: every error the library reports is one of these
exceptions; an answer whose verdict is not GOOD comes with a :class:`CalibrationWarning`.

The message is the one the ``handeye`` command line prints for the same problem.
"""

import warnings


class HandeyeError(Exception):
    """Base of every handeye error."""


class InputError(HandeyeError, ValueError):
    """Bad input: wrong shapes, NaN, non-rigid matrices, millimetres where metres are expected,
    a solve the solver refuses (too few poses, rotations about one axis), a malformed file.

    A refused solve carries its REDO verdict as ``verdict`` (None for other input errors).
    """

    verdict = None


class FileError(HandeyeError, OSError):
    """A file or folder that cannot be read or written."""


class CalibrationWarning(UserWarning):
    """An answer came back, but its verdict is CHECK or REDO: the message is the verdict's reason
    and next step (what ``handeye solve`` prints), ``verdict`` the :class:`Verdict` itself.

    Turn it into an error with ``warnings.simplefilter("error", handeye.CalibrationWarning)``.
    """

    verdict = None

    def __init__(self, message, verdict=None):
        super().__init__(message)
        self.verdict = verdict


def warn_verdict(verdict, stacklevel):
    """Warns (once) with a :class:`CalibrationWarning` when ``verdict`` is not GOOD;
    ``stacklevel`` counts from the caller of this function, as ``warnings.warn`` does."""
    if verdict is not None and verdict.level != "GOOD":
        warnings.warn(CalibrationWarning(str(verdict), verdict), stacklevel=stacklevel + 1)
