"""Property-based tests of the rig file and pattern spec readers: for any JSON, and for any
mutation of a valid file (a key dropped, a value of the wrong type, nan, inf, a huge or negative number,
nested junk), the reader returns a valid object or raises a RangekitError, never anything else and never
slowly (each call runs under an alarm)."""

from __future__ import annotations

import copy
import json
import signal
from contextlib import contextmanager

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rangekit.coded.patterns import PATTERN_METHODS, PatternSpec, make_pattern_spec
from rangekit.errors import RangekitError
from rangekit.formats.capture import pattern_spec_for
from rangekit.rig.rig_file import Rig, load_rig, template_rig
from rangekit.rig.checks import validate_capture, validate_devices, validate_rig_for_hardware

FUZZ = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                         HealthCheck.function_scoped_fixture])
CALL_LIMIT_S = 5.0  # a reader that takes longer on a small JSON document hangs


@contextmanager
def _no_hang(what: str):
    def stop(signum, frame):
        raise TimeoutError(f"{what} ran more than {CALL_LIMIT_S} s")

    old = signal.signal(signal.SIGALRM, stop)
    signal.setitimer(signal.ITIMER_REAL, CALL_LIMIT_S)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


def _valid_or_rangekit_error(fn, *args, **kwargs):
    """``fn(*args)``: its result, or None when it raised a RangekitError; anything else fails the test."""
    with _no_hang(fn.__qualname__):
        try:
            return fn(*args, **kwargs)
        except RangekitError:
            return None


# ----------------------------------------------------------------------------- strategies
_NUMBERS = st.one_of(
    st.integers(min_value=-2**70, max_value=2**70),
    st.sampled_from([0, 1, -1, 2, 3, 4, 7, 64, 65, 1280, 16384, 16385, 10**8, 10**18, 2**63, -2**63]),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.5, 1e8, 1e300, -1e-300, 1280.0, 2.5, float("nan"), float("inf"), -float("inf")]),
)
_SCALARS = st.one_of(st.none(), st.booleans(), _NUMBERS, st.text(max_size=12),
                     st.sampled_from(["", "columns", "rows", "graycode", "phase", "debruijn", "horus", "sim",
                                      "depthai", "CAM_A", "rangekit.rig/1", "/dev/ttyUSB0"]))
JSON = st.recursive(_SCALARS, lambda inner: st.one_of(st.lists(inner, max_size=5),
                                                      st.dictionaries(st.text(max_size=8), inner, max_size=5)),
                    max_leaves=20)


def _paths(obj, prefix=()):
    """Every path (tuple of keys/indices) into a nested JSON value, the root included."""
    yield prefix
    if isinstance(obj, dict):
        for k, v in obj.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            yield from _paths(v, prefix + (i,))


def _mutate(doc, path, op, junk):
    """A deep copy of ``doc`` with the value at ``path`` dropped, replaced by ``junk``, wrapped or emptied."""
    doc = copy.deepcopy(doc)
    if not path:
        return junk if op != "wrap" else [doc]
    parent = doc
    for key in path[:-1]:
        parent = parent[key]
    key = path[-1]
    if op == "drop":
        del parent[key]
    elif op == "wrap":
        parent[key] = [parent[key]]
    elif op == "empty":
        parent[key] = {} if isinstance(parent[key], dict) else []
    elif op == "scale" and isinstance(parent[key], (int, float)) and not isinstance(parent[key], bool):
        parent[key] = parent[key] * junk if isinstance(junk, (int, float)) and not isinstance(junk, bool) else junk
    else:
        parent[key] = junk
    return doc


@st.composite
def mutations(draw, valid_docs):
    doc = draw(st.sampled_from(valid_docs))
    n = draw(st.integers(1, 3))
    for _ in range(n):
        path = draw(st.sampled_from(list(_paths(doc))))
        op = draw(st.sampled_from(["drop", "replace", "replace", "wrap", "empty", "scale"]))
        doc = _mutate(doc, path, op, draw(JSON))
    return doc


def _rig_docs():
    from rangekit.sim import default_rig

    sim = default_rig().to_dict()
    stereo = template_rig()
    stereo["cameras"] = [stereo["cameras"][0], dict(stereo["cameras"][0], name="right")]
    depthai = template_rig()
    depthai["devices"] = {"depthai": {"device_id": "1844", "sockets": ["CAM_B", "CAM_C"], "size": [1280, 800]},
                          "camera": {"type": "sim"}, "turntable": {"type": "sim"}}
    depthai["capture"] = {"bits": 12, "pattern_delay_s": 0.2}
    depthai["projector_response"] = {"gamma": 2.2}
    return [json.loads(json.dumps(d)) for d in (template_rig(), sim, stereo, depthai)]


def _pattern_docs():
    # modulated: SLStudio's 24 periods do not fit 40 rows (two pixels a period at least): 8 here
    docs = [make_pattern_spec(m, (64, 40), **({"n_periods": 8} if m == "modulated" else {})).to_dict()
            for m in PATTERN_METHODS]
    docs.append(make_pattern_spec("phase", (64, 40), axes=("rows",), periods=[48.0, 12.0], steps=5).to_dict())
    docs.append(make_pattern_spec("debruijn", (96, 8), k=4, n=3, stripe_width=3).to_dict())
    return [json.loads(json.dumps(d)) for d in docs]


RIG_DOCS = _rig_docs()
PATTERN_DOCS = _pattern_docs()


def _check_rig(rig):
    if rig is not None:
        assert isinstance(rig, Rig) and rig.cameras
        assert all(1 <= c.width <= 16384 and 1 <= c.height <= 16384 for c in rig.cameras)
        Rig.from_dict(json.loads(json.dumps(rig.to_dict())), where="round trip")  # what it wrote it reads


def _check_spec(spec):
    if spec is not None:
        assert isinstance(spec, PatternSpec)
        assert 1 <= spec.width <= 16384 and 1 <= spec.height <= 16384
        assert len(spec.frame_names) == spec.n_frames <= 4096
        assert PatternSpec.from_dict(json.loads(json.dumps(spec.to_dict()))) == spec
        if spec.width * spec.height <= 10**5:
            frame = spec.frame(spec.n_frames - 1)
            assert frame.shape[:2] == (spec.height, spec.width)


# ----------------------------------------------------------------------------- rig files
def test_the_valid_rig_documents_are_valid():
    for doc in RIG_DOCS:
        rig = Rig.from_dict(doc)
        validate_rig_for_hardware(rig, where="rig.json")


@FUZZ
@given(JSON)
def test_rig_reader_on_any_json(doc):
    _check_rig(_valid_or_rangekit_error(Rig.from_dict, doc, where="rig.json"))


@FUZZ
@given(mutations(RIG_DOCS))
def test_rig_reader_and_hardware_checks_on_mutated_rig_files(doc):
    rig = _valid_or_rangekit_error(Rig.from_dict, doc, where="rig.json")
    _check_rig(rig)
    if rig is not None:
        _valid_or_rangekit_error(validate_rig_for_hardware, rig, where="rig.json")


@FUZZ
@given(JSON, JSON)
def test_devices_and_capture_checks_on_any_json(devices, capture):
    _valid_or_rangekit_error(validate_devices, devices, where="rig.json")
    _valid_or_rangekit_error(validate_capture, capture, where="rig.json")


@FUZZ
@given(mutations(RIG_DOCS), st.sampled_from(["json", "nan", "truncate", "bytes"]))
def test_load_rig_on_mutated_files(tmp_path, doc, damage):
    text = json.dumps(doc)  # Python writes NaN and Infinity, which its reader accepts
    if damage == "nan":
        text = text.replace("1.0", "NaN", 1).replace("0.0", "-Infinity", 1)
    elif damage == "truncate":
        text = text[: len(text) // 2]
    path = tmp_path / "rig.json"
    path.write_bytes(text.encode() if damage != "bytes" else b"\xff\xfe" + text.encode("utf-16-le"))
    _check_rig(_valid_or_rangekit_error(load_rig, path))


# ----------------------------------------------------------------------------- pattern specs
def test_the_valid_pattern_documents_are_valid():
    for doc in PATTERN_DOCS:
        _check_spec(PatternSpec.from_dict(doc))


@FUZZ
@given(JSON)
def test_pattern_reader_on_any_json(doc):
    _check_spec(_valid_or_rangekit_error(PatternSpec.from_dict, doc, where="patterns.json"))


@FUZZ
@given(st.fixed_dictionaries({"method": st.sampled_from(PATTERN_METHODS)},
                             optional={"width": _NUMBERS, "height": _NUMBERS, "axes": JSON, "frames": JSON,
                                       "options": st.dictionaries(
                                           st.sampled_from(["steps", "fine_steps", "periods", "period", "k", "n",
                                                            "stripe_width", "other"]),
                                           st.one_of(_NUMBERS, JSON), max_size=4)}))
def test_pattern_reader_on_every_method_with_junk_fields(doc):
    _check_spec(_valid_or_rangekit_error(PatternSpec.from_dict, doc, where="patterns.json"))


@FUZZ
@given(mutations(PATTERN_DOCS))
def test_pattern_reader_on_mutated_specs(doc):
    _check_spec(_valid_or_rangekit_error(PatternSpec.from_dict, doc, where="patterns.json"))


@FUZZ
@given(mutations(PATTERN_DOCS), st.sampled_from([None, (64, 40), (96, 8)]))
def test_pattern_spec_for_on_mutated_files(tmp_path, doc, projector):
    path = tmp_path / "patterns.json"
    path.write_text(json.dumps(doc))
    spec = _valid_or_rangekit_error(pattern_spec_for, str(path), projector)
    _check_spec(spec)
    if spec is not None and projector is not None:
        assert (spec.width, spec.height) == projector


@pytest.mark.parametrize("doc", [
    {"method": "phase", "width": 64, "height": 40, "options": {"steps": 1e8}},
    {"method": "hybrid", "width": 64, "height": 40, "options": {"steps": 10**12}},
    {"method": "debruijn", "width": 64, "height": 40, "options": {"n": 50}},
    {"method": "phase", "width": 64, "height": 40, "options": {"periods": [64] + [1.0] * 10**5}},
    {"method": "graycode", "width": 2**62, "height": 40},
])
def test_absurd_pattern_specs_are_refused_at_once(doc):
    assert _valid_or_rangekit_error(PatternSpec.from_dict, doc) is None
