"""A session's faster frame format, ``NNN.npy.zst`` (rangekit.npy_zst, issue 36 item 3): the same pixels as the
PNG, read by standard tools, known by its first bytes, refused with one line when damaged; a session in it
gives the bytes a PNG session gives, and its frames are checked as strictly."""

from __future__ import annotations

import json
from dataclasses import asdict

import numpy as np
import pytest
import zstandard

from rangekit.app.acquire.acquire import acquire
from rangekit.app.process.options import ProcessOptions
from rangekit.app.process.process import process_session
from rangekit.coded.patterns import make_pattern_spec
from rangekit.errors import FileFormatError, RangekitError
from rangekit.formats.capture import list_images, read_stack, stack_from_bytes
from rangekit.formats.sessions.session import CaptureSettings, ScanPlan, Session, SimulatorSettings
from rangekit.image_header import read_image_header
from rangekit.io import decode_image, read_png, write_frame
from rangekit.npy_zst import encode_npy_zst
from rangekit.sim import ImagingModel
from support.sessions import N_VIEWS, sim

IMAGES = {
    "grey 8-bit": np.arange(37 * 53, dtype=np.uint64).reshape(37, 53).astype(np.uint8),
    "grey 16-bit": (np.arange(37 * 53, dtype=np.uint64).reshape(37, 53) * 97 % 65536).astype(np.uint16),
    "RGB 8-bit": np.random.default_rng(0).integers(0, 256, (20, 31, 3), dtype=np.uint8),
    "RGB 16-bit": np.random.default_rng(1).integers(0, 65536, (20, 31, 3), dtype=np.uint16),
}


@pytest.mark.parametrize("name", IMAGES)
def test_round_trip_and_standard_tools(name, tmp_path):
    image = IMAGES[name]
    path = tmp_path / "000.npy.zst"
    data = write_frame(path, image)
    assert path.read_bytes() == data
    back = read_png(path)     # the one image reader knows the format by its first bytes
    assert back.dtype == image.dtype and np.array_equal(back, image) and back.flags.writeable
    # What `zstd -d 000.npy.zst` writes (every zstd frame, one after the other) is a .npy file.
    out = tmp_path / "000.npy"
    with open(path, "rb") as src:
        out.write_bytes(zstandard.ZstdDecompressor().stream_reader(src, read_across_frames=True).read())
    assert np.array_equal(np.load(out), image)
    # The size from the first bytes alone (the memory budget is checked before any pixel is read).
    header = read_image_header(path, data[:4096] if len(data) > 4096 else data)
    assert (header.width, header.height, header.channels, header.bits, header.format) == (
        image.shape[1], image.shape[0], 1 if image.ndim == 2 else 3, 8 * image.itemsize, "npy.zst")


def test_a_frame_folder_in_either_format_reads_the_same(tmp_path):
    frames = [np.full((8, 9), k * 20, dtype=np.uint8) for k in range(12)]
    (tmp_path / "png").mkdir()
    (tmp_path / "zst").mkdir()
    for k, f in enumerate(frames):
        write_frame(tmp_path / "png" / f"{k:03d}.png", f)
        write_frame(tmp_path / "zst" / f"{k:03d}.npy.zst", f)
    a, b = read_stack(list_images(tmp_path / "png")), read_stack(list_images(tmp_path / "zst"))
    assert [p.name for p in list_images(tmp_path / "zst")][:3] == ["000.npy.zst", "001.npy.zst", "002.npy.zst"]
    assert np.array_equal(a, b) and np.array_equal(b, np.stack(frames))


@pytest.mark.parametrize("suffix", ["png", "npy.zst"])
def test_a_stack_read_into_a_given_array_is_the_same_stack(suffix, tmp_path):
    # the decode stage reads each view into the array its thread had for the last one (reused_array): every
    # pixel written whatever was there, the first frame too
    frames = [np.full((8, 9), k * 20, dtype=np.uint8) for k in range(12)]
    for k, f in enumerate(frames):
        write_frame(tmp_path / f"{k:03d}.{suffix}", f)
    paths = list_images(tmp_path)
    dirty = np.full((12, 8, 9), 255, np.uint8)
    made = []

    def empty(shape, dtype):
        made.append((shape, np.dtype(dtype)))
        return dirty

    stack = stack_from_bytes(paths, [p.read_bytes() for p in paths], empty=empty)
    assert stack is dirty and made == [((12, 8, 9), np.dtype(np.uint8))]
    assert np.array_equal(stack, np.stack(frames))


def _damaged():
    good = encode_npy_zst(IMAGES["grey 8-bit"])
    c = zstandard.ZstdCompressor()
    return {
        "cut short": (good[:-7], ["cut short"]),
        "bytes after the pixels": (good + good[:40], ["bytes after them"]),
        "not a NumPy file inside": (c.compress(b"hello world, not an array"), ["not a NumPy .npy image header"]),
        "a float array": (c.compress(_npy(np.zeros((4, 4), np.float32))), ["float32", "uint8 or uint16"]),
        "four channels": (c.compress(_npy(np.zeros((4, 4, 4), np.uint8))), ["(4, 4, 4)", "(H, W, 3)"]),
        "damaged zstd": (good[:4] + b"\xff" * 40, ["damaged zstd data"]),
        "more pixels than the header says": (c.compress(_npy(np.zeros((4, 4), np.uint8))[:-16])
                                             + c.compress(b"\0" * 32), ["its header says 16"]),
    }


def _npy(a: np.ndarray) -> bytes:
    import io

    buf = io.BytesIO()
    np.save(buf, a)
    return buf.getvalue()


@pytest.mark.parametrize("case", list(_damaged()))
def test_a_damaged_frame_is_refused_naming_the_file(case):
    data, words = _damaged()[case]
    with pytest.raises(FileFormatError) as err:
        decode_image(data, "view_001/005.npy.zst")
    msg = str(err.value)
    assert msg.startswith("view_001/005.npy.zst: ") and "\n" not in msg
    assert all(w in msg for w in words), msg


def test_writing_refuses_what_a_frame_cannot_be(tmp_path):
    with pytest.raises(FileFormatError, match=r"000.npy.zst: a frame file needs .* found float64 \(3, 3\)"):
        write_frame(tmp_path / "000.npy.zst", np.zeros((3, 3)))
    assert not (tmp_path / "000.npy.zst").exists()


def _session(out, frame_format):
    devices = sim()
    return acquire(devices, devices.rig, make_pattern_spec("graycode", (1280, 800)), out, plan=ScanPlan(N_VIEWS),
                   simulator=SimulatorSettings("lumpy", 3, asdict(ImagingModel())),
                   capture=CaptureSettings(bits=8, frame_format=frame_format))


@pytest.fixture(scope="module")
def two_sessions(tmp_path_factory):
    """The same 4-view scan (small rig) with PNG frames and with .npy.zst frames."""
    root = tmp_path_factory.mktemp("frames")
    for fmt in ("png", "npy.zst"):
        _session(root / fmt, fmt)
    return {fmt: root / fmt for fmt in ("png", "npy.zst")}


def test_a_session_in_npy_zst_is_the_same_scan(two_sessions):
    png, zst = two_sessions["png"], two_sessions["npy.zst"]
    data = json.loads((zst / "session.json").read_text())
    assert data["capture"]["frame_format"] == "npy.zst"
    assert "frame_format" not in json.loads((png / "session.json").read_text())["capture"]   # as before
    assert sorted(data["views"][0]["sha256"])[:2] == ["000.npy.zst", "001.npy.zst"]
    for k in range(N_VIEWS):
        for i in (0, 7, 43):
            assert np.array_equal(read_png(png / f"view_{k:03d}" / f"{i:03d}.png"),
                                  read_png(zst / f"view_{k:03d}" / f"{i:03d}.npy.zst"))
    assert Session.load(zst).frame_files[:1] == ["000.npy.zst"]


@pytest.mark.slow
def test_processing_either_format_writes_the_same_bytes(two_sessions, tmp_path):
    import shutil

    out = {}
    for fmt, folder in two_sessions.items():
        out[fmt] = shutil.copytree(folder, tmp_path / fmt)
        process_session(out[fmt], ProcessOptions(report=False))
    for name in ("mesh.ply", "mesh_watertight.ply", "merged.ply", "poses.json"):
        assert (out["png"] / name).read_bytes() == (out["npy.zst"] / name).read_bytes(), name


def test_a_changed_npy_zst_frame_is_found(two_sessions, tmp_path):
    import shutil

    d = shutil.copytree(two_sessions["npy.zst"], tmp_path / "s")
    frame = d / "view_001" / "005.npy.zst"
    raw = bytearray(frame.read_bytes())
    raw[len(raw) // 2] ^= 0x01
    frame.write_bytes(bytes(raw))
    with pytest.raises(RangekitError, match=r"view_001.*005\.npy\.zst has changed"):
        process_session(d, ProcessOptions(report=False))


def test_the_frame_format_in_session_json_is_checked(two_sessions, tmp_path):
    import shutil

    d = shutil.copytree(two_sessions["npy.zst"], tmp_path / "s")
    data = json.loads((d / "session.json").read_text())
    data["capture"]["frame_format"] = "jpeg"
    (d / "session.json").write_text(json.dumps(data))
    with pytest.raises(RangekitError, match=r"capture\.frame_format.*'npy\.zst' or 'png'.*jpeg"):
        Session.load(d)
