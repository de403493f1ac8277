"""The front door checks its arguments (issue 48): every public name of ``rangekit.__all__`` that takes arguments,
called with None, a wrong type, NaN and an empty value for each argument, raises a rangekit error at once (an
:class:`~rangekit.errors.InputError`; a wrong type an ArgumentTypeError, also a TypeError) whose message names the
argument and says what it got in a short line; never an AttributeError or TypeError from deep inside, never any
work: the other arguments point at nothing (a folder that is not there), so a call the door lets through fails
elsewhere, naming something else. The values each argument accepts (None for an optional one, an empty dict of
extra fields...) are left out of its probes."""

from __future__ import annotations

import inspect
import re

import numpy as np
import pytest

import rangekit as rk
from rangekit.errors import ArgumentTypeError, InputError, RangekitError

NAN = float("nan")

# The four probes of an argument, by kind; a kind whose argument takes None (an optional one) leaves it out.
PATH = {"None": None, "wrong type": 123, "NaN": NAN, "empty": ""}
NUMBER = {"None": None, "wrong type": "1", "NaN": NAN, "empty": ""}
FLAG = {"None": None, "wrong type": "no", "NaN": NAN, "empty": ""}
NAME = {"None": None, "wrong type": 5, "NaN": NAN, "empty": ""}
CLOUD = {"None": None, "wrong type": "cloud", "NaN": NAN, "empty": []}
MESH = {"None": None, "wrong type": "mesh", "NaN": NAN, "empty": ()}
ARRAY = {"None": None, "wrong type": "points", "NaN": NAN, "empty": []}
ITEMS = {"None": None, "wrong type": "items", "NaN": NAN, "empty": []}
VECTOR = {"None": None, "wrong type": "up", "NaN": NAN, "empty": ()}
OBJECT = {"None": None, "wrong type": "fast", "NaN": NAN, "empty": {}}
CALLBACK = {"wrong type": "x", "NaN": NAN, "empty": ""}


def optional(kind: dict) -> dict:
    """The kind's probes but None (the argument's default)."""
    return {k: v for k, v in kind.items() if k != "None"}


def but(kind: dict, *labels: str) -> dict:
    """The kind's probes but ``labels`` (values the argument accepts, e.g. an empty dict of extra fields)."""
    return {k: v for k, v in kind.items() if k not in labels}


@pytest.fixture(scope="module")
def base(tmp_path_factory, small_rig):
    """Valid, cheap values of every argument; the paths point at nothing."""
    tmp = tmp_path_factory.mktemp("front_door")
    (tmp / "capture").mkdir()
    rng = np.random.default_rng(0)
    points = rng.normal(size=(60, 3)) * 0.01
    cloud = rk.PointCloud(points, normals=np.tile([0.0, 0.0, 1.0], (60, 1)))
    mesh = rk.TriangleMesh(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]]),
                           np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]))
    images = rng.uniform(0.1, 1.0, size=(3, 4, 4))
    lights = np.eye(3)
    return {
        "load_cloud": {"path": tmp / "c.ply"}, "load_range_grid": {"path": tmp / "g.ply"},
        "load_mesh": {"path": tmp / "m.ply"}, "load_rig": {"path": tmp / "rig.json"},
        "save_cloud": {"path": tmp / "out.ply", "cloud": cloud}, "save_mesh": {"path": tmp / "out.ply", "mesh": mesh},
        "save_rig": {"rig": small_rig, "path": tmp / "out" / "rig.json"},
        "Rig": {"cameras": small_rig.cameras, "projector": small_rig.projector, "T_world_table": small_rig.T_world_table},
        "PointCloud": {"points": points}, "TriangleMesh": {"vertices": mesh.vertices, "triangles": mesh.triangles},
        "as_cloud": {"x": points}, "as_mesh": {"x": mesh}, "from_open3d": {}, "from_trimesh": {},
        "to_trimesh": {}, "to_open3d": {},
        "estimate_normals": {"points": points}, "voxel_downsample": {"points": points, "voxel": 0.001},
        "merge_clouds": {"clouds": [cloud], "T_world_view": np.eye(4)[None]},
        "transform_cloud": {"cloud": cloud, "T_a_b": np.eye(4)},
        "poisson_mesh": {"cloud": cloud}, "make_watertight": {"mesh": mesh},
        "icp": {"source": cloud, "target": cloud}, "IcpOptions": {},
        "register_views": {"clouds": [cloud, cloud]}, "MultiViewOptions": {},
        "render": {"x": mesh}, "reconstruct": {"images_or_folder": tmp / "capture"},
        "register": {"paths": [tmp / "a.ply", tmp / "b.ply"], "out_dir": tmp / "registered"},
        "photometric_folder": {"folder": tmp / "diligent", "out": tmp / "normals"},
        "photometric_stereo": {"images": images, "lights": lights},
        "scan": {"options": rk.ScanOptions(resume=tmp / "no_session")}, "ScanOptions": {"out": tmp / "scan1"},
        "process": {"session": tmp / "no_session"}, "ProcessOptions": {},
    }


#: Each public name that takes arguments: its arguments and the probes each refuses. ``name=alias`` when the
#: message names the argument so (``as_cloud``'s ``x`` is called by its ``what``, "cloud").
ARGUMENTS = {
    "load_cloud": {"path": PATH}, "load_range_grid": {"path": PATH}, "load_mesh": {"path": PATH},
    "load_rig": {"path": PATH},
    "save_cloud": {"path": PATH, "cloud": CLOUD, "fields": but(optional(OBJECT), "empty")},
    "save_mesh": {"path": PATH, "mesh": MESH, "units": NAME},
    "save_rig": {"rig": OBJECT, "path": PATH},
    "Rig": {"cameras": ITEMS, "projector": optional(OBJECT), "T_world_table": optional(ARRAY),
            "devices": but(OBJECT, "empty"), "capture": but(OBJECT, "empty"),
            "projector_response": optional(OBJECT), "lasers": but(ITEMS, "empty")},
    "PointCloud": {"points": ARRAY, "colours": optional(ARRAY), "normals": optional(ARRAY), "sigma": optional(ARRAY)},
    "TriangleMesh": {"vertices": ARRAY, "triangles": but(ARRAY, "empty"), "vertex_colours": optional(ARRAY),
                     "observed": optional(ARRAY), "carved": optional(ARRAY)},
    "as_cloud": {"x=cloud": CLOUD, "what": NAME}, "as_mesh": {"x=mesh": MESH, "what": NAME},
    "from_open3d": {"x": CLOUD}, "from_trimesh": {"x": CLOUD}, "to_trimesh": {"x": CLOUD}, "to_open3d": {"x": CLOUD},
    "estimate_normals": {"points": ARRAY, "k": NUMBER, "viewpoint": optional(VECTOR)},
    "voxel_downsample": {"points": ARRAY, "voxel": NUMBER, "normals": optional(ARRAY)},
    "merge_clouds": {"clouds": ITEMS, "T_world_view": ARRAY},
    "transform_cloud": {"cloud": CLOUD, "T_a_b": ARRAY},
    "poisson_mesh": {"cloud": CLOUD, "depth": NUMBER, "density_quantile": NUMBER, "watertight": FLAG,
                     "n_threads": NUMBER},
    "make_watertight": {"mesh": MESH},
    "icp": {"source": CLOUD, "target": CLOUD, "init_T_target_source": optional(ARRAY), "options": OBJECT,
            "target_scan": optional(OBJECT), "hold": optional(OBJECT)},
    "IcpOptions": {"method": NAME, "max_distance": NUMBER, "max_iterations": NUMBER, "kernel": NAME,
                   "kernel_scale": optional(NUMBER), "trim": NUMBER, "voxel_sizes": but(ITEMS, "empty"),
                   "max_samples": optional(NUMBER), "tolerance": NUMBER, "rng": NUMBER},
    "register_views": {"clouds": ITEMS, "init_T_world_view": optional(ARRAY), "options": OBJECT,
                       "progress": CALLBACK, "names": optional(ITEMS), "map_pairs": CALLBACK,
                       "ahead": optional(OBJECT)},
    "MultiViewOptions": {"voxel": optional(NUMBER), "fine_voxel": optional(NUMBER), "min_overlap": NUMBER,
                         "max_rmse": NUMBER, "max_coarse_rmse": NUMBER, "rounds": NUMBER, "min_constraint": NUMBER,
                         "joint_iterations": NUMBER, "joint_tolerance": NUMBER, "joint_samples": NUMBER,
                         "pairs": CALLBACK, "coarse_neighbours": optional(NUMBER), "icp": OBJECT, "turntable": FLAG,
                         "rng": NUMBER},
    "render": {"x": {**CLOUD, "wrong type": 123, "empty path": ""}, "azimuths": ITEMS, "elevation": NUMBER,
               "size": {**VECTOR, "wrong type": "big"}, "up": VECTOR, "colour": FLAG},
    "reconstruct": {"images_or_folder": {**CLOUD, "empty path": "", "no folder": "scan1"}, "rig": optional(PATH),
                    "pattern": optional(NAME), "method": NAME, "subpixel": FLAG},
    "register": {"paths": ITEMS, "out_dir": PATH, "init": optional(NAME), "voxel": optional(NUMBER), "mesh": FLAG,
                 "progress": CALLBACK, "neighbours": optional(NUMBER)},
    "photometric_folder": {"folder": PATH, "out": PATH, "method": NAME, "progress": CALLBACK},
    "photometric_stereo": {"images": ARRAY, "lights": ARRAY, "mask": optional(ARRAY), "method": NAME,
                           "channels": NAME},
    "scan": {"options": {**OBJECT, "wrong type": "scan1"}, "on_event": CALLBACK},
    "ScanOptions": {"out": PATH, "resume": optional(PATH), "method": optional(NAME), "rig": optional(PATH),
                    "object": optional(PATH), "views": optional(NUMBER), "steps": optional(NUMBER),
                    "passes": optional(NUMBER), "flipped": FLAG, "patterns": optional(NAME), "target_mm": optional(NUMBER),
                    "seed": optional(NUMBER),
                    "up": optional(VECTOR), "artefact": optional(NAME), "positions": optional(VECTOR),
                    "allow_auto_exposure": FLAG, "exposures": {**optional(VECTOR), "wrong type": 5}, "process": FLAG,
                    "fusion": optional(NAME), "report": optional(FLAG), "format": optional(NAME), "realtime": FLAG,
                    "triggered": FLAG, "frames": optional(NAME), "sim_bump": optional(VECTOR),
                    "processing": optional(OBJECT)},
    "process": {"session": PATH, "options": optional(OBJECT), "on_event": CALLBACK, "evaluate": CALLBACK},
    "ProcessOptions": {"fusion": NAME, "method": NAME, "table_margin": NUMBER, "report": FLAG, "truth": FLAG,
                       "mesh_format": NAME, "poisson_depth": optional(NUMBER), "max_motion": optional(NUMBER),
                       "poisson_points": optional(NUMBER)},
}

#: Public names that take no arguments to check, and why.
NOT_CHECKED = {
    "__version__": "a string, not called",
    "ScanResult": "what rk.scan returns, not made by a caller",
}


def _cases():
    for name, arguments in ARGUMENTS.items():
        for argument, probes in arguments.items():
            for label, value in probes.items():
                yield pytest.param(name, argument, value, id=f"{name}-{argument.split('=')[0]}-{label}")


def test_every_public_name_and_argument_is_probed():
    assert set(rk.__all__) == set(ARGUMENTS) | set(NOT_CHECKED)
    for name, arguments in ARGUMENTS.items():
        parameters = {p for p, kind in inspect.signature(getattr(rk, name)).parameters.items()
                      if kind.kind is not kind.VAR_KEYWORD}   # rk.process's **removed: the keywords of before
        assert {a.split("=")[0] for a in arguments} == parameters, name


@pytest.mark.parametrize("name, argument, value", list(_cases()))
def test_a_wrong_argument_is_refused_at_the_door_naming_it(base, name, argument, value):
    argument, _, said = argument.partition("=")
    with pytest.raises(RangekitError) as caught:
        getattr(rk, name)(**{**base[name], argument: value})
    message = str(caught.value)
    assert isinstance(caught.value, InputError), f"{type(caught.value).__name__}: {message}"
    assert re.search(rf"(?<![\w-]){re.escape(said or argument)}\b", message), message
    assert "\n" not in message and len(message) < 600, message


@pytest.mark.parametrize("call, argument", [
    (lambda b: rk.load_rig(None), "path"),
    (lambda b: rk.scan("scan1"), "options"),
    (lambda b: rk.reconstruct(b["reconstruct"]["images_or_folder"], rig=123), "rig"),
    (lambda b: rk.reconstruct(b["reconstruct"]["images_or_folder"], subpixel="no"), "subpixel"),
    (lambda b: rk.ScanOptions(out="scan1", exposures=5), "exposures"),
    (lambda b: rk.process(b["process"]["session"], "fast"), "options"),
    (lambda b: rk.register(**b["register"], voxel="1"), "voxel"),
    (lambda b: rk.process(b["process"]["session"], on_event="x"), "on_event"),
    (lambda b: rk.render(b["render"]["x"], size="big"), "size"),
], ids=["load_rig-None", "scan-str", "reconstruct-rig-int", "subpixel-str", "exposures-int", "process-str",
        "register-voxel-str", "on_event-str", "render-size-str"])
def test_the_issue_s_calls_are_refused_naming_the_argument(base, call, argument):
    """The probe of issue 48: each raised an AttributeError or TypeError from inside (``subpixel="no"`` was True)."""
    with pytest.raises(InputError, match=rf"^{argument}: expected .*, found "):
        call(base)


@pytest.mark.parametrize("keyword", ["decoded_views", "registration_ahead", "map_pairs"])
def test_the_process_hand_over_keywords_are_refused_naming_them(base, keyword):
    """Issue 49: the scan hands its work on inside the job runner (its memo); the keywords are gone from rk.process
    and a call still giving one is told so, by name, before any work."""
    with pytest.raises(InputError, match=rf"^{keyword}: .*removed in issue 49"):
        rk.process(base["process"]["session"], **{keyword: None})


def test_a_wrong_type_is_also_a_type_error_and_a_wrong_value_is_not(tmp_path):
    with pytest.raises(TypeError):
        rk.load_rig(None)
    with pytest.raises(ArgumentTypeError, match=r"subpixel: expected True or False, found 'no' \(str\)"):
        rk.reconstruct(tmp_path, subpixel="no")
    with pytest.raises(InputError, match=r"^voxel: expected a finite number \(metres\), found nan \(float\)$") as caught:
        rk.voxel_downsample(np.zeros((3, 3)), NAN)
    assert not isinstance(caught.value, TypeError)


def test_an_array_is_named_by_its_shape_not_printed(base):
    with pytest.raises(InputError, match=r"T_a_b: expected a \(4, 4\) array of finite numbers, found an array of "
                                         r"shape \(1000, 3\) float64$"):
        rk.transform_cloud(base["transform_cloud"]["cloud"], np.zeros((1000, 3)))


def test_the_command_line_says_a_refused_argument_in_one_line(capsys, monkeypatch, tmp_path):
    """A front-door error reaching the CLI is one line, exit 1 (an InputError, not an option of the command)."""
    import rangekit.app.commands.picture as picture
    from rangekit.cli import main

    monkeypatch.setattr(picture, "render_file", lambda *a, **k: rk.render(None))
    code = main(["render", str(tmp_path / "nothing.ply"), "--out", str(tmp_path / "nothing.png")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 1 and len(err) == 1 and err[0].startswith("rangekit: error: ") and "render x: expected" in err[0]


def test_one_name_for_each_thing():
    """load_*/save_* for files; the device protocol and the rig file have distinct names; one to_open3d."""
    import rangekit.formats.meshes as meshes
    import rangekit.rig.devices as devices
    import rangekit.sim as sim
    import rangekit.surface as surface

    assert rk.load_mesh is meshes.load_mesh and not hasattr(meshes, "load_mesh_file")
    assert not hasattr(sim, "load_mesh") and callable(sim.load_scene_object)
    assert rk.Rig is not devices.RigDevices and not hasattr(devices, "Rig")
    assert surface.to_open3d is rk.to_open3d
    for name in ("scan", "process", "reconstruct", "register", "photometric_folder", "photometric_stereo",
                 "load_rig", "ScanOptions"):
        assert name in dir(rk) and callable(getattr(rk, name))
    assert rk.photometric.integrate_normals is not None   # a subpackage through the same door
