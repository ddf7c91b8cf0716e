"""eoloc's exceptions: one base, :class:`EolocError`, for every mistake a user can fix (a file
that cannot be read or used, a configuration that fails validation). Each message names the file,
key or field and the fix. Per-target problems are never exceptions: they are statuses
(:class:`eoloc.Status`). EolocError derives from ValueError, so code that caught ValueError
before still catches these."""

from __future__ import annotations


class EolocError(ValueError):
    """Base of eoloc's user-facing errors. ``issues``: the per-line problems that explain it (the
    bad lines of a file none of whose lines could be used), shown before the message."""

    def __init__(self, message: str, issues=()) -> None:
        super().__init__(message)
        self.issues = list(issues)


class ConfigError(EolocError):
    """The configuration file is missing, not TOML, or fails validation (message names the key)."""


class TableError(EolocError):
    """The file cannot be read at all (missing, no header, required columns absent)."""


class DEMError(EolocError):
    """A DEM cannot be used: missing, unreadable, no CRS, incompatible tiles (message names the file)."""


class KLVError(EolocError):
    """The file cannot be read as KLV at all (missing, empty, no ST 0601 packet in it)."""


class VideoError(EolocError):
    """A video file cannot be opened or decoded (missing, no video stream, corrupt beyond the
    decoder's recovery): the message names the file and, where it applies, the frame."""


class ModelFileError(EolocError):
    """A compensation model file cannot be used (wrong format, version or feature set)."""


class InputError(EolocError):
    """The inputs are readable but cannot give what was asked (too few usable observations, a time
    outside the telemetry, a frame that sees no ground, a scenario no target of which can be
    located): the message says what is missing and how to supply it."""


def one_line(exc: BaseException) -> str:
    """An exception as one line, with its type: for a message that quotes what a library said."""
    text = str(exc).strip().replace("\n", " ")
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


class MissingExtraError(EolocError):
    """A command or function needs an optional part of eoloc that is not installed (the message
    names the package and the ``pip install 'eoloc[extra]'`` that brings it)."""
