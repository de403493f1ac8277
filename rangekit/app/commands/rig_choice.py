"""Which rig describes a capture, and the rig refined from the capture itself (issue 47).

:func:`choose_rig`: several rig files (``rangekit reconstruct --rig A.json B.json ...``; a calibration file of
another tool is imported on the way, :func:`load_rigs`) are each checked against the capture's decoded
correspondences (:mod:`rangekit.rig.capture_check`), and the one whose check is smallest is used. A rig that
cannot be the capture's (its camera or projector of another size than the capture's frames) is ranked last,
with the reason; when none can, the error names each one's.

:func:`refine_from_capture`: when the rig used does not fit (over :data:`~rangekit.rig.capture_check.POOR_FIT_PX`)
and the capture checks it (rows coded, or two cameras), the second device's pose is bundle-adjusted over the
capture's correspondences (:func:`rangekit.rig.refine.refine_extrinsics`); a refinement the data cannot support is
refused, with its reason, and the rig kept as given.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from rangekit.camera import PinholeCamera
from rangekit.errors import CalibrationError, ConfigError, InputError
from rangekit.rig.capture_check import RigCheck, decoded_pairs
from rangekit.rig.rig_file import Rig, load_rig

__all__ = ["RigChoice", "Refined", "choose_rig", "load_rigs", "refine_from_capture", "refined_rig_files"]


@dataclass(frozen=True)
class RigChoice:
    """The rig a capture is reconstructed with, among those given, and how each fitted."""

    name: str                                   # the chosen rig's file
    rig: Rig
    check: RigCheck                             # the chosen rig's check, as given
    exchanged: bool                             # two cameras: the first capture is the rig's camera 2
    ranking: tuple[tuple[str, RigCheck | str], ...]   # every rig, best first: its check, or why it cannot be

    def lines(self) -> list[str]:
        """One line per rig when several were given, best first (none for one)."""
        if len(self.ranking) < 2:
            return []
        out = []
        for k, (name, fit) in enumerate(self.ranking):
            figure = (f"{fit.median_px:.2f} px, {fit.median_mm:.3f} mm" if isinstance(fit, RigCheck) and fit.checkable
                      else "unchecked (columns only)" if isinstance(fit, RigCheck) else f"cannot be: {fit}")
            out.append(f"rig {k + 1} of {len(self.ranking)}: {name}: {figure}" + ("  <- used" if k == 0 else ""))
        return out


def load_rigs(paths: Sequence[str | Path], *, report: Callable[[str], object] | None = None) -> list[tuple[str, Rig]]:
    """(name, rig) of each file: a rig file (.json with rangekit's fields), or another tool's calibration imported
    as ``rangekit rig import`` would (:func:`rangekit.formats.rig_files.importers.import_rig`)."""
    from rangekit.formats.rig_files.importers import import_rig

    rigs = []
    for path in paths:
        path = Path(path)
        if path.suffix.lower() == ".json":
            try:
                rigs.append((str(path), load_rig(path)))
                continue
            except ConfigError as exc:
                if "unknown top-level field" not in str(exc) and "schema" not in str(exc):
                    raise
        rigs.append((str(path), Rig.from_dict(import_rig(path, report=report), where=str(path))))
    return rigs


def choose_rig(rigs: Sequence[tuple[str, Rig]], check: Callable[[Rig], tuple[RigCheck, bool]]) -> RigChoice:
    """The rig of ``rigs`` whose ``check`` (its :class:`RigCheck` on the capture and whether its cameras are
    exchanged; raising InputError when it cannot be the capture's) is smallest; the first when none is checkable."""
    fits, reasons = [], []
    for k, (name, rig) in enumerate(rigs):
        try:
            checked, exchanged = check(rig)
        except InputError as exc:
            reasons.append((name, str(exc)))
            continue
        fits.append((checked.median_px if checked.checkable else np.inf, k, name, rig, checked, exchanged))
    if not fits:
        raise ConfigError("no rig can be this capture's: " + "; ".join(f"{n}: {why}" for n, why in reasons))
    fits.sort(key=lambda f: (f[0], f[1]))
    _, _, name, rig, checked, exchanged = fits[0]
    ranking = tuple((f[2], f[4]) for f in fits) + tuple(reasons)
    return RigChoice(name, rig, checked, exchanged, ranking)


@dataclass(frozen=True)
class Refined:
    """The second device (projector, or camera 2) to triangulate with, and what the refinement did."""

    second: PinholeCamera                      # the rig's projector, or its camera 2, refined or as given
    refinement: object | None                  # rangekit.rig.refine.RigRefinement when refined
    line: str                                  # one line for people ("" when the rig fits and nothing was tried)


def refine_from_capture(first: PinholeCamera, second: PinholeCamera, u2: np.ndarray, v2: np.ndarray,
                        checked: RigCheck, *, refine: bool = True, free_intrinsics: bool = False,
                        exchanged: bool = False) -> Refined:
    """The rig's second device refined from the correspondences ``u2``, ``v2`` ((H, W) ``second``'s coordinates over
    ``first``'s pixels, NaN where none) when ``checked`` says the rig does not fit the capture (module doc).
    ``exchanged``: ``first`` is the rig's camera 2 (two cameras, files named for the other), so ``second``, the
    rig's camera 1, is held and ``first`` refined: the rig's first device anchors its world either way."""
    held, moved = (second, first) if exchanged else (first, second)
    if not checked.checkable or checked.fits:
        return Refined(moved, None, "")
    if not refine:
        return Refined(moved, None, "rig not refined (--no-refine): kept as given")
    from rangekit.rig.refine import refine_extrinsics

    uv1, uv2, _ = decoded_pairs(u2, v2)
    uv_held, uv_moved = (uv2, uv1) if exchanged else (uv1, uv2)
    try:
        done = refine_extrinsics(held, moved, uv_held, uv_moved, free_intrinsics=free_intrinsics)
    except CalibrationError as exc:
        return Refined(moved, None, f"rig not refined: {exc}; kept as given")
    return Refined(done.second, done, done.describe())


def refined_rig_files(out: str | Path, rig: Rig, refined: Refined, *,
                      to_rig_projector: Callable[[PinholeCamera], PinholeCamera] | None = None) -> tuple[Path, Path]:
    """Write the refined rig beside the output ``out`` (``<out stem>.refined-rig.json``: ``rig`` with the refined
    projector or camera 2 in its place) and the refinement's figures (``<out stem>.refinement.json``);
    ``to_rig_projector``: the refined projector back in the rig file's projector pixels (a layout's blocks).
    Returns both paths."""
    from rangekit.formats.rig_files.json_text import rig_json_text
    from rangekit.io import atomic_write_json, atomic_write_text

    r = refined.refinement
    second = refined.second if to_rig_projector is None else to_rig_projector(refined.second)
    if rig.projector is not None:
        new = replace(rig, projector=second)
    else:
        new = replace(rig, cameras=(rig.cameras[0], second) + tuple(rig.cameras[2:]))
    out = Path(out)
    rig_path, figures_path = out.with_name(out.stem + ".refined-rig.json"), out.with_name(out.stem + ".refinement.json")
    atomic_write_text(rig_path, rig_json_text(new.to_dict()))
    atomic_write_json(figures_path, {"rig": rig_path.name, "before_px": r.before_px, "after_px": r.after_px,
                                     "n_points": r.n_points, "iterations": r.iterations, "seconds": r.seconds,
                                     "rotation_deg": r.rotation_deg, "translation_mm": r.translation_mm,
                                     "freed": list(r.freed), "line": refined.line})
    return rig_path, figures_path
