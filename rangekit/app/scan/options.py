"""What a scan does: one frozen value, checked in one place (``rangekit scan`` maps its flags onto it, and
maps its errors back to flag names with :data:`SCAN_FLAGS`).

Options left None take the defaults of a new scan (:data:`SCAN_DEFAULTS`) or, with ``resume``, the
session's own settings; an option given with ``resume`` must equal the session's
(:func:`rangekit.app.scan.setup.prepare_scan` checks that, with the folder, the rig and the object).
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from pathlib import Path

from rangekit._runtime.arguments import check_instance, check_items, check_path, check_vector, is_int as _is_int
from rangekit._runtime.option_fields import UNSET, check_ranges, flags, option, specs
from rangekit.app.process.options import ProcessOptions
from rangekit.errors import OptionError

__all__ = ["ScanOptions", "SCAN_FLAGS", "SCAN_METHODS", "SCAN_DEFAULTS", "SCAN_FUSION", "LASER_STEPS", "ARTEFACTS"]

#: Scan methods: coded light (projector patterns, views registered) and laser lines (profiles at small
#: turntable steps, placed by the turntable angle).
SCAN_METHODS = ("coded", "laser")
#: Turntable steps of a laser scan over a full turn (0.9 degrees each).
LASER_STEPS = 400
#: ``artefact``: the simulated acceptance test of VDI/VDE 2634 part 2 (:mod:`rangekit.app.scan.vdi2634`).
ARTEFACTS = ("vdi2634",)
#: Options of a turntable scan that ``artefact`` (one view per artefact position, coded light) does not take.
_NOT_WITH_ARTEFACT = ("resume", "method", "steps", "up", "object", "views", "patterns", "target_mm", "passes",
                      "flipped", "frames", "sim_bump", "triggered")


@dataclass(frozen=True)
class ScanOptions:
    """A scan (``rangekit scan``): where, with what, and what is done with it after acquisition.

    out : a new (or empty) session folder; or
    resume : the folder of a session to continue (its own settings; the given ones must equal them).
    method : ``"coded"`` (projector patterns, views registered) or ``"laser"`` (the rig's line lasers, one
        profile per turntable step).
    rig : ``"sim"`` (the simulator) or a rig file whose ``devices`` name the hardware.
    object : the simulated object: a built-in name (:data:`rangekit.sim.scene.zoo`) or a mesh file.
    views : turntable views over a full turn (coded light, 2..720); steps : a laser scan's steps (2..3600).
    passes : coded-light passes (1..8), the object turned over between them; flipped : with ``resume``, the
        user confirms the object is already turned over for the next pass.
    patterns : the pattern set: a method (:data:`rangekit.coded.patterns.PATTERN_METHODS`, its own options) or a
        named set (:data:`rangekit.app.scan.presets.PRESETS`); default ``hybrid-8step-min3`` (issue 51: 48 frames,
        the 60-frame ``hybrid``'s accuracy, its motion check its Gray blocks against the phase).
    target_mm : a new coded-light scan's patterns are the fewest frames whose measured accuracy meets it: one view's
        points at most this RMS (mm) against the simulator's truth on every measured object
        (:func:`rangekit.app.scan.presets.fastest_for`; not with ``patterns``).
    seed : the simulator's noise seed (0 <= seed < 2**32).
    up : (x, y, z) of a mesh file object that points up on the turntable (Stanford meshes: (0, 1, 0)).
    artefact : ``"vdi2634"``: scan the guideline's artefacts instead (with ``out``, ``rig``, ``positions``,
        ``seed``); positions : (spheres, ball bars, planes) of it.
    allow_auto_exposure : scan although the rig file's exposure is ``"auto"``.
    exposures : multi-exposure capture, 2 to 8 exposures in microseconds, or ``("auto",)``.
    process : decode, register and fuse after acquisition; processing : how
        (:class:`rangekit.app.process.options.ProcessOptions`, every option of ``rangekit process``; None: its
        defaults but the fusion, :data:`SCAN_FUSION` for coded light). After the check it is never None.
    fusion, report, format : shorthands kept for the callers of older versions: each, when given, fills the field
        of ``processing`` it names (``fusion``, ``report``, ``mesh_format``) and reads None afterwards, so that
        ``processing`` is the one source; given together with a ``processing`` whose field differs, refused.
    realtime : the simulator keeps real time: the rig file's waits and frame rate, the projector's latency,
        the turntable's speed (:mod:`rangekit.sim.devices.realtime`); the frames are the same bytes. A new
        coded-light scan then models the rig we recommend, the camera triggered by the projector's VSYNC
        (issue 51: as ``triggered``; :attr:`sim_triggered`): the frames are the same bytes, only the time changes.
    triggered : a new simulated coded-light scan's camera is triggered by the projector's VSYNC (the session's rig
        file says ``capture.trigger`` "projector"): no pattern delay, each frame's trigger count checked, a missed
        trigger named and its view taken again (:mod:`rangekit.app.acquire.triggered`). A hardware rig's file says
        it itself.
    frames : the frame files of a new session: ``"npy.zst"`` (:mod:`rangekit.npy_zst`; the default for coded
        light: 3x faster to read than PNG, 4x to write, as many bytes) or ``"png"`` (the default, and the only
        format, for a laser scan).
    sim_bump : (view, frame, mm): the simulated object is knocked ``mm`` along x from that frame of that view to
        the view's end, then back in place (testing the motion check: the scan takes the view again).
    """

    out: str | Path | None = option(None, "--out")
    resume: str | Path | None = option(None, "--resume")
    method: str | None = option(None, "--method", initial="coded")
    rig: str | Path | None = option(None, "--rig", initial="sim")
    object: str | Path | None = option(None, "--object", initial="lumpy")
    views: int | None = option(None, "--views", lo=2, hi=720, integer=True, initial=12)
    steps: int | None = option(None, "--steps", lo=2, hi=3600, integer=True, initial=LASER_STEPS)
    passes: int | None = option(None, "--passes", lo=1, hi=8, integer=True, initial=1)
    flipped: bool = option(False, "--flipped")
    patterns: str | None = option(None, "--patterns", initial="hybrid-8step-min3")
    target_mm: float | None = option(None, "--target-mm", lo=0.001, hi=10.0, unit="mm")
    seed: int | None = option(None, "--seed", lo=0, hi=2**32 - 1, integer=True, initial=0)
    up: tuple[float, float, float] | None = option(None, "--up")
    artefact: str | None = option(None, "--artefact")
    positions: tuple[int, int, int] | None = option(None, "--positions")
    allow_auto_exposure: bool = option(False, "--allow-auto-exposure")
    exposures: tuple | None = option(None, "--exposures")
    process: bool = option(True, "--no-process")
    fusion: str | None = option(None, "--fusion")
    report: bool | None = option(None, "--no-report")
    format: str | None = option(None, "--format")
    realtime: bool = option(False, "--realtime")
    triggered: bool = option(False, "--triggered")
    frames: str | None = option(None, "--frames")
    sim_bump: tuple[int, int, float] | None = option(None, "--sim-bump")
    processing: ProcessOptions | None = None

    def __post_init__(self) -> None:
        _check_values(self)
        _check_combination(self)
        _fill_processing(self)

    @property
    def folder(self) -> Path:
        """The session folder: ``resume`` or ``out``."""
        return Path(self.resume if self.resume is not None else self.out)

    @property
    def sim_triggered(self) -> bool:
        """Whether a new simulated scan's camera is triggered by the projector (the one rule): ``triggered``, or
        ``realtime`` on a new coded-light scan (issue 51: real time on the simulator models the recommended rig,
        :mod:`rangekit.sim.devices.realtime`). A resumed session's rig file says it itself."""
        return self.resume is None and self.method != "laser" and (self.triggered or self.realtime)

    @property
    def turntable_positions(self) -> int | None:
        """``steps`` or ``views``, whichever is given (None: the default of the method)."""
        return self.steps if self.steps is not None else self.views


def _check_values(o: ScanOptions) -> None:
    """Each field on its own: type and range."""
    from rangekit.app.process.fused_outputs import MESH_EXPORT_FORMATS
    from rangekit.app.process.options import FUSION_METHODS
    from rangekit.coded.patterns import PATTERN_METHODS
    from rangekit.app.scan.presets import PRESETS

    for name, what in (("out", "a new session folder"), ("resume", "a session folder"), ("rig", "'sim' or a rig file"),
                       ("object", "a built-in object's name or a mesh file")):
        check_path(f"{{{name}}}", getattr(o, name), what=what, optional=True, error=OptionError)
    check_ranges(o, OptionError)
    from rangekit.formats.sessions.session import FRAME_FORMATS

    for name, choices in (("method", SCAN_METHODS), ("patterns", PATTERN_METHODS + tuple(PRESETS)), ("artefact", ARTEFACTS),
                          ("frames", FRAME_FORMATS)):
        value = getattr(o, name)
        if value is not None and value not in choices:
            raise OptionError(f"{{{name}}} must be one of {', '.join(choices)}, found {value!r}")
    for name, choices in (("fusion", FUSION_METHODS), ("format", MESH_EXPORT_FORMATS)):
        if getattr(o, name) is not None and getattr(o, name) not in choices:
            raise OptionError(f"{{{name}}} must be one of {', '.join(choices)}, found {getattr(o, name)!r}")
    for name in ("flipped", "allow_auto_exposure", "process", "report", "realtime", "triggered"):
        if not isinstance(getattr(o, name), bool) and not (name == "report" and o.report is None):
            raise OptionError(f"{{{name}}}: expected True or False, found {getattr(o, name)!r}")
    check_instance("{processing}", o.processing, ProcessOptions, "a ProcessOptions", optional=True, error=OptionError)
    check_vector("{up}", o.up, 3, optional=True, error=OptionError)
    if o.positions is not None and (len(check_items("{positions}", o.positions, "three integers SPHERES BARS PLANES",
                                                    error=OptionError)) != 3
                                    or not all(_is_int(n) for n in o.positions)):
        raise OptionError(f"{{positions}}: expected three integers SPHERES BARS PLANES, found {o.positions!r}")
    if o.exposures is not None:
        given = tuple(check_items("{exposures}", o.exposures, "'auto' alone or 2 to 8 exposures in microseconds",
                                  error=OptionError))
        if given != ("auto",) and not all(_is_int(e) and 1 <= e <= 1_000_000 for e in given):
            raise OptionError("{exposures}: expected 'auto' alone or 2 to 8 exposures in microseconds (1..1000000), "
                              f"found {' '.join(map(str, given))}")
        if given != ("auto",) and not 2 <= len(set(given)) <= 8:
            raise OptionError(f"{{exposures}}: expected 2 to 8 different exposures, found {' '.join(map(str, given))}")


def _check_combination(o: ScanOptions) -> None:
    """The fields together: one folder, options that go with the method, ``artefact``'s own set."""
    if o.artefact is not None:
        given = [f"{{{name}}}" for name in _NOT_WITH_ARTEFACT if getattr(o, name) not in (None, False)]
        if given:
            raise OptionError(f"{', '.join(given)}: not used by {{artefact}} {o.artefact} (one single-view "
                              "coded-light capture per artefact position on the simulator); leave them out")
        if o.out is None:
            raise OptionError(f"{{artefact}} {o.artefact}: expected {{out}} DIR, found none")
        return
    if o.positions is not None:
        raise OptionError("{positions}: artefact positions of {artefact} vdi2634; give {artefact} vdi2634 or "
                          "leave it out")
    if (o.out is None) == (o.resume is None):
        raise OptionError("{out} and {resume}: expected one of them (a new session folder, or the session to "
                          f"continue), found {'both' if o.out is not None else 'neither'}")
    if o.steps is not None and o.views is not None:
        raise OptionError("{steps} and {views} both give the turntable positions; give one ({steps} for a laser "
                          "scan)")
    if o.method != "laser" and o.steps is not None and o.resume is None:
        raise OptionError("{steps}: turntable steps of a laser scan; with {method} coded give {views}")
    if o.flipped and o.resume is None:
        raise OptionError("{flipped} confirms, when resuming a multi-pass scan, that the object was turned over; "
                          "give it with {resume} DIR")
    if o.method == "laser" and o.patterns is not None:
        raise OptionError("{patterns}: a laser scan projects no patterns; leave {patterns} out with {method} laser")
    if o.target_mm is not None and (o.patterns is not None or o.method == "laser" or o.resume is not None):
        raise OptionError(f"{{target_mm}} {o.target_mm:g} picks a new coded-light scan's patterns; "
                          + ("{patterns} names them too: give one of the two" if o.patterns is not None
                             else "a laser scan projects no patterns: leave {target_mm} out" if o.method == "laser"
                             else "a resumed scan keeps its session's patterns: leave {target_mm} out"))
    if o.method == "laser" and o.passes not in (None, 1):
        raise OptionError(f"{{passes}}: a laser scan takes one pass, found {o.passes}; leave {{passes}} out with "
                          "{method} laser")
    if o.resume is not None and o.up is not None:
        raise OptionError("{up}: a resumed scan keeps its session's object as it stands; leave {up} out")
    if o.resume is not None and o.exposures is not None:
        raise OptionError("{exposures}: a resumed scan keeps its session's exposures; leave {exposures} out")
    if o.realtime and o.rig not in (None, "sim"):
        raise OptionError(f"{{realtime}} makes the simulator keep real time; {{rig}} {o.rig} is hardware, which "
                          "keeps it anyway: leave {realtime} out")
    if o.triggered and (o.rig not in (None, "sim") or o.resume is not None or o.method == "laser"):
        raise OptionError("{triggered} makes a new simulated coded-light scan's camera triggered by the projector; "
                          + (f"{{rig}} {o.rig} says it in its file (capture.trigger)" if o.rig not in (None, "sim")
                             else "a resumed session's rig file says it (capture.trigger)" if o.resume is not None
                             else "a laser scan's lasers send no trigger") + ": leave {triggered} out")
    if o.resume is not None and o.frames is not None:
        raise OptionError("{frames}: a resumed scan keeps its session's frame format; leave {frames} out")
    if o.sim_bump is not None:
        b = o.sim_bump
        ok = (isinstance(b, tuple) and len(b) == 3 and _is_int(b[0]) and _is_int(b[1]) and b[0] >= 0 and b[1] >= 0
              and isinstance(b[2], (int, float)) and not isinstance(b[2], bool) and 0 < b[2] <= 50)
        if not ok:
            raise OptionError(f"{{sim_bump}}: expected VIEW:FRAME:MM (whole numbers >= 0, 0 < MM <= 50), found {b!r}")
        if o.rig not in (None, "sim") or o.method == "laser":
            raise OptionError("{sim_bump} knocks the simulated object during a coded-light scan; leave it out with "
                              f"{{rig}} {o.rig} or {{method}} {o.method}")
    if o.method == "laser" and o.frames not in (None, "png"):
        raise OptionError("{frames}: a laser scan's frames are PNG files; leave {frames} out")
    if o.method == "laser" and o.exposures is not None:
        raise OptionError("{exposures}: multi-exposure capture is for coded light; leave it out with {method} laser")


#: A coded-light scan's fusion when neither ``fusion`` nor ``processing`` is given: the blocks volume its views are
#: integrated into as they come, so that after the last frame only the last view's part is left (issue 51: mesh.ply
#: within a few seconds of the last frame; ``rangekit process`` keeps Poisson). A laser scan fuses with Poisson.
SCAN_FUSION = "blocks"
#: The shorthands of ``processing``'s fields: ScanOptions' field -> ProcessOptions' field.
_SHORTHANDS = {"fusion": "fusion", "report": "report", "format": "mesh_format"}


def _fill_processing(o: ScanOptions) -> None:
    """``processing`` made whole: the shorthands given (``fusion``, ``report``, ``format``) written into it, then
    read as None; a shorthand that differs from the ``processing`` given is refused (one value per option)."""
    given = {_SHORTHANDS[name]: getattr(o, name) for name in _SHORTHANDS if getattr(o, name) is not None}
    section = o.processing
    if section is None:
        given.setdefault("fusion", "poisson" if o.method == "laser" else SCAN_FUSION)
        section = ProcessOptions(**given)
    else:
        for name, value in given.items():
            if getattr(section, name) != value:
                short = next(k for k, v in _SHORTHANDS.items() if v == name)
                raise OptionError(f"{{{short}}} {value!r} and {{processing.{name}}} {getattr(section, name)!r}: two "
                                  f"values of one option; give it once, in {{processing}}")
    object.__setattr__(o, "processing", section)
    for name in _SHORTHANDS:
        object.__setattr__(o, name, None)


#: Every field, in order (the command line's test checks each has its flag and the reverse).
SCAN_FIELDS = tuple(f.name for f in fields(ScanOptions))
#: The options of a new scan left None (each field's ``initial``, :mod:`rangekit._runtime.option_fields`).
SCAN_DEFAULTS = {name: s.initial for name, s in specs(ScanOptions).items() if s.initial is not UNSET}
#: Each field's ``rangekit scan`` flag (``process`` and ``report`` are the flags' negations), ``processing``'s
#: fields as ``processing.NAME`` with ``rangekit process``'s flags (the same on both commands).
SCAN_FLAGS = {**flags(ScanOptions), **flags(ProcessOptions, prefix="processing.")}
__all__ += ["SCAN_FIELDS"]
