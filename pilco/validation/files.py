"""Paths of files, and the format version recorded in a file pilco wrote.

The contents of a file (a truncated archive, a missing entry, an unknown component type)
are checked by its reader (:func:`pilco.deploy.read_npz`, :mod:`pilco.models.storage`),
which names the file in its ``ValueError``.
"""
from __future__ import annotations

import os

__all__ = ["check_path", "check_format_version"]


def check_path(path, name: str = "path") -> str:
    """A file path (``str`` or ``os.PathLike``) as a ``str``, or a clear error."""
    if isinstance(path, (bytes, bytearray)) or not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"{name} must be a file path (str or os.PathLike), got "
                        f"{type(path).__name__}")
    path = os.fspath(path)
    if not isinstance(path, str) or not path:
        raise ValueError(f"{name} must be a non-empty file path, got {path!r}")
    return path


def check_format_version(meta: dict, path: str, kind: str, supported: int,
                         reader: str) -> int:
    """The ``version`` of a pilco file's metadata if this ``reader`` reads it (1 to
    ``supported``), else a ``ValueError`` saying which version wrote the file."""
    version = meta.get("version")
    if isinstance(version, bool) or not isinstance(version, int) or not 1 <= version <= supported:
        written = meta.get("pilco_version")
        by = f" (written by pilco {written})" if isinstance(written, str) else ""
        known = "version 1" if supported == 1 else f"versions 1 to {supported}"
        raise ValueError(f"{path} has {kind} format version {version!r}{by}; {reader} reads "
                         f"{kind} format {known}")
    return version
