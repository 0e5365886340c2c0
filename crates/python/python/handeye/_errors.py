"""The exceptions of handeye: every error the library reports is one of these.

The message is the one the ``handeye`` command line prints for the same problem.
"""


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
