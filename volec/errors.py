"""Exceptions volec raises for problems a user can act on.

Every message names the file (and field) at fault and, where there is one, what to do.
"""


class VolecError(Exception):
    """Base class of every error volec raises on purpose."""


class CaptureError(VolecError):
    """A capture on disk is malformed or inconsistent (missing keys, bad matrices, sizes)."""


class OutputExistsError(VolecError):
    """An output would overwrite an earlier result that the user did not ask to replace."""
