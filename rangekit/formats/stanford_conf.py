"""The Stanford 3D Scanning Repository's ``.conf`` file: the pose of every range scan of a set.

Lines ``bmesh NAME TX TY TZ QX QY QZ QW`` give a scan's translation (metres) and the quaternion of the
inverse of its rotation (the convention of Stanford's ``scanalyze``; the bunny's and dragon's sets use
it). ``camera`` and ``mesh`` lines are skipped. :func:`load_stanford_conf` returns ``T_world_view`` in the
file's world frame, so ``register --init bun.conf`` and the tests compare with the authors' alignment.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rangekit.errors import ConfigError
from rangekit.geometry import make_T
from rangekit.regular_files import read_regular_file

__all__ = ["MAX_CONF_SCANS", "load_stanford_conf"]

#: The most ``bmesh`` lines a ``.conf`` may hold (Stanford's sets have 10 to 70 scans): a larger file is refused
#: at the first line past it, before any pose is computed.
MAX_CONF_SCANS = 10_000


def load_stanford_conf(path: str | Path, expected: int | None = None) -> tuple[list[str], np.ndarray]:
    """(scan file names, (n, 4, 4) T_world_view) from a ``.conf`` file; errors name the file and line.
    ``expected``: the number of scans the poses are for; a file with more ``bmesh`` lines is refused at the
    first one too many (as one over :data:`MAX_CONF_SCANS`), one with fewer after reading it."""
    from scipy.spatial.transform import Rotation

    text = read_regular_file(path, what="a Stanford .conf file").decode("utf-8", "replace")
    most = MAX_CONF_SCANS if expected is None else min(int(expected), MAX_CONF_SCANS)
    names, values = [], []
    for number, line in enumerate(text.splitlines(), 1):
        p = line.split()
        if not p or p[0] != "bmesh":
            continue
        if len(names) == most:
            raise ConfigError(f"{path}: line {number}: more than {most} 'bmesh' lines, "
                              + (f"but {most} scans were given; expected one line per scan" if most == expected
                                 else "the most a .conf may hold"))
        try:
            numbers = np.array(p[2:9], dtype=np.float64)
            if len(p) != 9 or not np.all(np.isfinite(numbers)) or not np.linalg.norm(numbers[3:]) > 0.5:
                raise ValueError
        except ValueError:
            raise ConfigError(f"{path}: line {number}: expected 'bmesh NAME TX TY TZ QX QY QZ QW' with 7 finite "
                              f"numbers and a unit quaternion, found {line.strip()!r:.120}") from None
        names.append(p[1])
        values.append(numbers)
    if not names:
        raise ConfigError(f"{path}: no 'bmesh NAME TX TY TZ QX QY QZ QW' line; not a Stanford .conf file")
    values = np.stack(values)
    Rs = Rotation.from_quat(values[:, 3:]).inv().as_matrix()   # one call for every scan
    return names, np.stack([make_T(R, t) for R, t in zip(Rs, values[:, :3])])
