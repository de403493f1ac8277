"""Parsing helpers shared by the point cloud readers (PLY, PCD): file bytes, truncation errors, and
whitespace-separated numbers read with vectorised numpy."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from rangekit.errors import FileFormatError
from rangekit.surface.cloud import PointCloud

__all__ = ["read_bytes", "truncated_error", "ascii_rows", "cloud_of_finite_rows"]


def read_bytes(path: Path, what: str = "point cloud") -> bytes:
    """The file's bytes; FileFormatError naming the file when it is missing or unreadable."""
    try:
        return path.read_bytes()
    except FileNotFoundError as exc:
        raise FileFormatError(f"{path}: {what} file not found") from exc
    except OSError as exc:
        raise FileFormatError(f"{path}: cannot read {what} file: {exc.strerror or exc}") from exc


def cloud_of_finite_rows(path: Path, points: np.ndarray, normals: np.ndarray | None = None,
                colours: np.ndarray | None = None, sigma: np.ndarray | None = None) -> PointCloud:
    """A PointCloud of the rows whose point is finite; FileFormatError if none is."""
    points = np.asarray(points, dtype=np.float64)
    keep = np.isfinite(points).all(axis=1)
    if not keep.all():
        points = points[keep]
        normals = None if normals is None else normals[keep]
        colours = None if colours is None else colours[keep]
        sigma = None if sigma is None else sigma[keep]
    if len(points) == 0:
        found = "an empty cloud" if keep.size == 0 else f"{keep.size} points, none of them finite"
        raise FileFormatError(f"{path}: expected at least one point, found {found}")
    return PointCloud(points, colours=colours, normals=normals, sigma=sigma)


def truncated_error(path: Path, element: str, declared: int, found: int) -> FileFormatError:
    """The error for a file whose body ends before the ``declared`` rows of ``element``."""
    what = {"vertex": "vertices", "face": "faces", "point": "points"}.get(element, f"'{element}' entries")
    return FileFormatError(f"{path}: header declares {declared} {what} but the file ends after {found}")


_SPACE = np.zeros(256, dtype=bool)
_SPACE[[9, 10, 11, 12, 13, 32]] = True


def ascii_rows(path: Path, data: bytes, offset: int, n_rows: int, first_line: int
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Numbers on the first ``n_rows`` non-blank lines of ``data[offset:]``, vectorised.

    Returns all values in order (float64), the count of values on each row and each row's 1-based line
    number in the file (``first_line`` is the number of the line at ``offset``). Fewer rows are returned
    when the text ends early; a token that is not a number raises FileFormatError naming its line.
    """
    buf = np.frombuffer(data, dtype=np.uint8, offset=offset)
    newlines = np.flatnonzero(buf == 10)
    if len(newlines) > n_rows > 0:  # look at the first n_rows lines only, unless some of them are blank
        rows = ascii_rows(path, data[:offset + newlines[n_rows - 1] + 1], offset, n_rows, first_line)
        if len(rows[1]) == n_rows:
            return rows
    space = _SPACE[buf]
    starts = ~space
    starts[1:] &= space[:-1]
    newlines = np.flatnonzero(buf == 10)
    line_of_token = np.searchsorted(newlines, np.flatnonzero(starts))
    per_line = np.bincount(line_of_token, minlength=len(newlines) + 1)
    lines = np.flatnonzero(per_line)[:n_rows]
    counts = per_line[lines]
    if len(lines) == 0:
        return np.empty(0), counts, lines + first_line
    end = newlines[lines[-1]] if lines[-1] < len(newlines) else len(buf)
    text = data[offset:offset + end]
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # numpy warns (instead of raising) on text it cannot parse
            values = np.fromstring(text, dtype=np.float64, sep=" ")
    except (ValueError, DeprecationWarning):
        values = None
    if values is None or len(values) != counts.sum():
        # Slow path, only to name the culprit: find the first token that is not a number.
        for k, token in enumerate(text.split()):
            try:
                float(token)
            except ValueError:
                line = first_line + int(line_of_token[k])
                raise FileFormatError(f"{path}: line {line}: expected a number, found "
                                      f"{token[:40].decode('latin-1')!r}") from None
        raise FileFormatError(f"{path}: expected whitespace-separated numbers after the header, found text "
                              f"numpy cannot parse")
    return values, counts, lines + first_line
