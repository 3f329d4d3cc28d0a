"""Exceptions volec raises for problems a user can act on.

Every message names the file (and field) at fault and, where there is one, what to do. The
command line prints a :class:`VolecError` as one line and exits with status 2; anything else
is a bug in volec (or in a library it calls) and gives a traceback and status 1.
"""


class VolecError(Exception):
    """Base class of every error volec raises on purpose."""


class CaptureError(VolecError):
    """A capture on disk is malformed or inconsistent (missing keys, bad matrices, sizes)."""


class OutputExistsError(VolecError):
    """An output would overwrite an earlier result that the user did not ask to replace."""


class BusyError(VolecError):
    """Another volec run is writing into the same output folder."""


class ConfigError(VolecError, ValueError):
    """A setting or a name given to volec is not valid (a ValueError too, for callers that
    catch those)."""


class ScaleError(VolecError):
    """The capture's units are unknown or implausible: a volume in millilitres would be a guess."""


class UnknownNameError(VolecError, KeyError):
    """A name (a food item, a shape family, a preset) volec does not know (a KeyError too)."""

    def __str__(self) -> str:  # KeyError would print the message quoted
        return str(self.args[0]) if self.args else ""


class DataError(VolecError, ValueError):
    """Data handed to volec (a point cloud, an array) cannot be used as it is (a ValueError
    too, for callers that catch those)."""
