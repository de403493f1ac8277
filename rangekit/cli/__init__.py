"""The ``rangekit`` command line. Each command parses, converts human units, calls the library, prints.

Run ``rangekit --help`` or ``rangekit COMMAND --help``.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from rangekit.errors import InputError, RangekitError

__all__ = ["main"]


def _say(msg: str) -> None:
    print(msg, flush=True)


def _console():
    """Progress for long stages: a bar on a terminal, plain lines in CI, pipes and files."""
    from rangekit.progress import Console

    return Console(sys.stdout)


def _sim_render_tof(args: argparse.Namespace) -> int:
    """--sensor tof | tof-pulsed: the panel scene from --near to --far metres."""
    from dataclasses import replace

    from rangekit.sim.tof import (KINECT_V2_PLAN, LUXONIS_PLAN, ToFSensor, render_pulsed, render_tof, tof_camera,
                                  tof_scene, write_pulsed_capture, write_tof_capture)
    from rangekit.tof import FrequencyPlan

    t0 = time.perf_counter()
    scene = tof_scene(args.near, args.far)
    camera = tof_camera(*(args.size or (320, 240)))
    info = {"scene": f"panels {args.near:g} to {args.far:g} m"}
    if args.sensor == "tof-pulsed":
        _say(f"rendering pulsed round trips ({camera.width}x{camera.height}, jitter {args.jitter_ps:g} ps)")
        cap = render_pulsed(scene, camera=camera, jitter_s=args.jitter_ps * 1e-12, seed=args.seed)
        write_pulsed_capture(cap, args.out, info=info)
    else:
        if args.frequencies_mhz:
            plan = FrequencyPlan.uniform([f * 1e6 for f in args.frequencies_mhz], args.steps or 4)
        else:
            plan = {"kinect": KINECT_V2_PLAN, "luxonis": LUXONIS_PLAN}[args.plan]
            if args.steps:
                plan = FrequencyPlan.uniform(plan.frequencies, args.steps)
        sensor = ToFSensor()
        if args.multipath:
            sensor = replace(sensor, multipath_strength=args.multipath[0], multipath_extra_m=args.multipath[1])
        _say(f"rendering {plan.n_samples} raw samples ({plan.describe()}, {camera.width}x{camera.height}, "
             f"3x3 rays per pixel)")
        cap = render_tof(scene, plan, camera=camera, sensor=sensor, noise=not args.no_noise, seed=args.seed)
        write_tof_capture(cap, args.out, info=info)
    _say(f"wrote {args.out} (tof.json, rig.json, ground_truth.npz, preview.png) in {time.perf_counter() - t0:.1f} s")
    return 0


def _sim_render_stereo(args: argparse.Namespace) -> int:
    """--sensor stereo: the white box and sphere seen by the simulated active-stereo pair."""
    from rangekit.sim.stereo import render_stereo, stereo_rig, stereo_scene, write_stereo_capture

    t0 = time.perf_counter()
    rig = stereo_rig(*(args.size or (640, 400)))
    _say(f"rendering the stereo pair ({rig.cameras[0].width}x{rig.cameras[0].height}, "
         f"dots {'off' if args.no_dots else 'on'})")
    cap = render_stereo(stereo_scene(), rig, dots=not args.no_dots, seed=args.seed)
    write_stereo_capture(cap, rig, args.out)
    _say(f"wrote {args.out} (left.png, right.png, rig.json, ground_truth.npz) in {time.perf_counter() - t0:.1f} s")
    return 0


def cmd_sim_render(args: argparse.Namespace) -> int:
    """rangekit sim render [--sensor projector|tof|tof-pulsed|stereo] [--object NAME_OR_MESH] --out DIR"""
    from dataclasses import replace

    if args.sensor != "projector":
        given = [f for f, v in (("--object", args.object), ("--patterns", args.patterns), ("--rig", args.rig))
                 if v is not None]
        if given:
            raise InputError(f"{', '.join(given)}: only for --sensor projector; the {args.sensor} sensor renders its "
                             "own scene (docs/simulator.md)")
        return _sim_render_stereo(args) if args.sensor == "stereo" else _sim_render_tof(args)
    args.object = args.object or "lumpy"
    args.patterns = args.patterns or "graycode"

    from rangekit.coded.patterns import make_pattern_spec
    from rangekit.rig import load_rig
    from rangekit.sim import ImagingModel, SimRig, default_scene
    from rangekit.sim.capture import write_capture

    t0 = time.perf_counter()
    imaging = ImagingModel(bits=args.bits, colour=args.patterns == "debruijn")
    if args.no_noise:
        imaging = imaging.noiseless()
    if args.global_fraction is not None:
        imaging = replace(imaging, global_fraction=args.global_fraction)
    rig = load_rig(args.rig) if args.rig else None
    sim = SimRig(default_scene(args.object), rig, imaging=imaging, seed=args.seed)
    if sim.turntable is not None:
        sim.turntable.rotate_to(np.radians(args.angle_deg))
    spec = make_pattern_spec(args.patterns, sim.projector.resolution)
    write_capture(sim, spec, args.out, info={"object": args.object}, progress=_say)
    _say(f"done in {time.perf_counter() - t0:.1f} s")
    return 0


def _size(text: str) -> tuple[int, int]:
    """Argument type for image, sensor and projector sizes: WIDTHxHEIGHT in pixels."""
    try:
        w, h = (int(v) for v in text.lower().split("x"))
        if w > 0 and h > 0:
            return w, h
    except ValueError:
        pass
    raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT in pixels, e.g. 1280x800, found {text!r}")


def cmd_tof(args: argparse.Namespace) -> int:
    """rangekit tof RAW_DIR --out OUT: range, depth, confidence and a cloud from raw ToF samples."""
    from rangekit.formats.range_files import load_ground_truth, load_tof_folder, write_depth_outputs
    from rangekit.tof import decode_cw, pulsed_range, range_to_depth, range_to_points

    t0 = time.perf_counter()
    raw = load_tof_folder(args.raw_dir)
    cam = raw.camera
    if raw.pulsed:
        rng_map = pulsed_range(raw.round_trip_s)
        depth = range_to_depth(rng_map, cam)
        valid = np.isfinite(rng_map)
        points = range_to_points(rng_map, cam)[valid]
        confidence = valid.astype(np.float32)
        _say(f"pulsed: {valid.mean():.1%} of {cam.width}x{cam.height} pixels returned")
    else:
        res = decode_cw(raw.samples, raw.plan, cam, electrons_per_unit=raw.electrons_per_dn,
                        read_noise_e=raw.read_noise_e, saturation=raw.saturation_dn, min_snr=args.min_snr,
                        flying_angle=None if args.keep_flying else np.radians(args.flying_angle_deg),
                        max_range=args.max_range)
        rng_map, depth, points, confidence, valid = res.range, res.depth, res.points, res.confidence, res.valid
        n = valid.size
        _say(f"{raw.plan.describe()} ({raw.plan.unambiguous_range:.3f} m unambiguous): valid {valid.sum() / n:.1%}, "
             f"low signal {res.low_signal.sum() / n:.1%}, ambiguous {res.ambiguous.sum() / n:.1%}, "
             f"flying {res.flying.sum() / n:.1%}")
    truth = load_ground_truth(args.raw_dir)
    if truth is not None and "range" in truth:
        ok = valid & np.isfinite(truth["range"]) & truth.get("valid", np.ones_like(valid))
        if ok.any():
            err = (rng_map - truth["range"])[ok]
            wrong = np.abs(err) > 0.3
            _say(f"against ground_truth.npz ({ok.sum():,} pixels): range RMS {np.sqrt(np.mean(err[~wrong] ** 2)) * 1e3:.2f} mm, "
                 f"median |error| {np.median(np.abs(err)) * 1e3:.2f} mm, wrong wrap (> 0.3 m) {wrong.mean():.3%}")
    names = write_depth_outputs(args.out, depth, points, range_map=rng_map, confidence=confidence)
    _say(f"wrote {args.out}/{', '.join(names)} ({len(points):,} points) in {time.perf_counter() - t0:.1f} s")
    return 0


def cmd_stereo(args: argparse.Namespace) -> int:
    """rangekit stereo LEFT RIGHT --rig RIG.json --out OUT: depth of the left camera from a stereo pair."""
    from pathlib import Path

    from rangekit.errors import ConfigError
    from rangekit.io import read_png
    from rangekit.formats.range_files import load_ground_truth, write_depth_outputs
    from rangekit.rig import load_rig
    from rangekit.stereo import stereo_depth

    t0 = time.perf_counter()
    rig = load_rig(args.rig)
    if len(rig.cameras) < 2:
        raise ConfigError(f"{args.rig}: the stereo command needs two cameras in 'cameras' (left = cameras[0], "
                          f"right = cameras[1]), found {len(rig.cameras)}")
    left, right = read_png(args.left), read_png(args.right)
    if left.shape[:2] != right.shape[:2]:
        raise InputError(f"{args.left} is {left.shape[1]}x{left.shape[0]} but {args.right} is "
                         f"{right.shape[1]}x{right.shape[0]} (width x height); a stereo pair needs two images of one "
                         "size")
    opts = {} if args.num_disparities is None else {"num_disparities": args.num_disparities}
    res = stereo_depth(left, right, rig.cameras[0], rig.cameras[1], method=args.method, min_depth=args.min_depth,
                       alpha=args.alpha, **opts)
    dmap = res.disparity
    ok = np.isfinite(res.depth)
    _say(f"{dmap.method}: disparities [{dmap.min_disparity}, {dmap.min_disparity + dmap.num_disparities}) px, "
         f"baseline {res.rectification.baseline * 1e3:.1f} mm; depth for {ok.mean():.1%} of the left image in "
         f"{time.perf_counter() - t0:.1f} s")
    truth = load_ground_truth(Path(args.left).parent)
    if truth is not None and "depth" in truth and truth["depth"].shape == res.depth.shape:
        vis = truth.get("valid", np.isfinite(truth["depth"])) & np.isfinite(truth["depth"])
        both = vis & ok
        if both.any():
            err = (res.depth - truth["depth"])[both]
            _say(f"against ground_truth.npz: depth for {both.sum() / max(vis.sum(), 1):.1%} of the {vis.sum():,} "
                 f"visible pixels, RMS {np.sqrt(np.mean(err ** 2)) * 1e3:.2f} mm, median |error| "
                 f"{np.median(np.abs(err)) * 1e3:.2f} mm")
    names = write_depth_outputs(args.out, res.depth, res.points, confidence=res.confidence)
    _say(f"wrote {args.out}/{', '.join(names)} ({len(res.points):,} points)")
    return 0


def cmd_decode(args: argparse.Namespace) -> int:
    """rangekit decode IMAGES --pattern SPEC_OR_NAME --projector WxH [--order opencv] --out maps.npz"""
    from pathlib import Path

    from rangekit.formats.capture import list_images, read_stack
    from rangekit.coded.decode import decode
    from rangekit.errors import ConfigError
    from rangekit.io import atomic_save_npz, read_json
    from rangekit.coded.patterns import PATTERN_METHODS, PatternSpec, make_pattern_spec

    t0 = time.perf_counter()
    source = args.images[0] if len(args.images) == 1 else args.images
    paths = list_images(source)
    if args.pattern in PATTERN_METHODS:
        if args.projector is None:
            raise ConfigError(f"--pattern {args.pattern} needs --projector WxH (the projector's resolution)")
        spec = make_pattern_spec(args.pattern, args.projector)
    else:
        spec = PatternSpec.from_dict(read_json(args.pattern, what="pattern spec"), where=args.pattern)
        if args.projector is not None and args.projector != (spec.width, spec.height):
            raise ConfigError(f"{args.pattern} is for a {spec.width}x{spec.height} projector, --projector says "
                              f"{args.projector[0]}x{args.projector[1]}")
    _say(f"reading {len(paths)} images")
    images = read_stack(paths)
    _say(f"decoding {spec.method} ({'subpixel' if not args.integer else 'integer'})")
    res = decode(images, spec, order=args.order, subpixel=not args.integer)
    atomic_save_npz(args.out, proj_col=res.proj_col, proj_row=res.proj_row, confidence=res.confidence,
                    shadow=res.shadow, low_contrast=res.low_contrast, global_dominated=res.global_dominated,
                    inconsistent=res.inconsistent)
    _say(f"{res!r}")
    _say(f"wrote {Path(args.out)} in {time.perf_counter() - t0:.1f} s")
    return 0


def cmd_reconstruct(args: argparse.Namespace) -> int:
    """rangekit reconstruct CAPTURE_DIR [--rig RIG.json] --out cloud.ply"""
    from rangekit.formats.capture import load_capture
    from rangekit.errors import ConfigError
    from rangekit.formats.clouds import save_cloud
    from rangekit.app.reconstruct import reconstruct_view
    from rangekit.rig import load_rig

    t0 = time.perf_counter()
    cap = load_capture(args.capture)
    if cap.spec is None:
        raise ConfigError(f"{args.capture}: no patterns.json; decode the images with 'rangekit decode' and a "
                          "--pattern, or add the pattern spec to the folder")
    rig = load_rig(args.rig) if args.rig else cap.rig
    if rig is None or rig.projector is None:
        raise ConfigError(f"{args.capture}: no rig.json with a projector; pass --rig RIG.json")
    _say(f"decoding {len(cap.images)} images ({cap.spec.method})")
    bits = cap.info.get("imaging", {}).get("bits")
    full_scale = float((1 << bits) - 1) if bits else None
    rec = reconstruct_view(cap.images, cap.spec, rig.camera, rig.projector, subpixel=not args.integer,
                           method=args.method, full_scale=full_scale, response=rig.projector_response)
    save_cloud(args.out, rec.cloud)
    _say(f"{rec.decoded!r}")
    _say(f"{rec.triangulated!r}")
    _say(f"wrote {len(rec.cloud)} points to {args.out} in {time.perf_counter() - t0:.1f} s")
    return 0


def cmd_register(args: argparse.Namespace) -> int:
    """rangekit register SCAN... [--init none|poses.json|turntable:AXIS:STEP] --out DIR"""
    import numpy as np

    from rangekit.geometry import rotation_angle
    from rangekit.app.register_files import register_files

    t0 = time.perf_counter()
    voxel = args.voxel_mm * 1e-3 if args.voxel_mm else None
    rep = register_files(args.scans, args.out, init=args.init, voxel=voxel, mesh=not args.no_mesh, progress=_say)
    res = rep.result
    _say("edges (view i - view j): ICP inlier RMSE, overlap, accepted, synchronisation residual")
    for k, e in enumerate(res.edges):
        rot = res.sync.edge_rotation_error[k] if k < len(res.sync.edge_rotation_error) else np.nan
        _say(f"  {e.i:2d}-{e.j:<2d} rmse {e.rmse * 1e3:7.3f} mm  overlap {e.overlap:5.2f}  "
             f"{'ok ' if e.accepted else 'rejected'}  {e.reason}")
    acc = [k for k, e in enumerate(res.edges) if e.accepted]
    rot = np.degrees(np.asarray(res.sync.edge_rotation_error))
    tr = np.asarray(res.sync.edge_translation_error) * 1e3
    _say(f"synchronisation over {len(acc)} accepted edges: rotation residual mean {np.mean(rot):.4f} deg, "
         f"max {np.max(rot):.4f} deg; translation residual mean {np.mean(tr):.4f} mm, max {np.max(tr):.4f} mm")
    for k, T in enumerate(res.T_world_view):
        _say(f"  view {k}: {rep.sources[k]}: rotation {np.degrees(rotation_angle(T[:3, :3])):8.3f} deg, "
             f"translation {np.linalg.norm(T[:3, 3]) * 1e3:8.2f} mm")
    _say(f"wrote {args.out}/poses.json, merged.ply{', mesh.ply' if rep.mesh_path else ''} in "
         f"{time.perf_counter() - t0:.1f} s")
    return 0


def cmd_mesh(args: argparse.Namespace) -> int:
    """rangekit mesh CLOUD --out MESH"""
    from rangekit.formats.meshes import save_mesh
    from rangekit.surface.cloud import oriented_normals_cloud
    from rangekit.surface.fusion import poisson_mesh
    from rangekit.formats.clouds import load_cloud

    t0 = time.perf_counter()
    cloud = load_cloud(args.cloud)
    if cloud.normals is None:
        _say(f"read {len(cloud)} points without normals: estimating outward normals")
        cloud = oriented_normals_cloud(cloud.points)
    _say(f"{len(cloud)} points; screened Poisson, depth {args.depth}")
    mesh = poisson_mesh(cloud, depth=args.depth)
    save_mesh(args.out, mesh)
    _say(f"wrote {args.out}: {len(mesh.vertices)} vertices, {len(mesh.triangles)} triangles, watertight "
         f"{mesh.is_watertight}, in {time.perf_counter() - t0:.1f} s")
    return 0


def cmd_devices(args: argparse.Namespace) -> int:
    """rangekit devices [--timeout 1.0]: list serial ports and depthai cameras"""
    from rangekit.drivers.discovery import list_depthai_devices, list_serial_ports

    ports = list_serial_ports()
    _say("serial ports:" if ports else "serial ports: none found")
    for p in ports:
        _say(f"  {p['device']}  {p['description']}  USB {p['vid_pid'] or '-'}  serial {p['serial_number'] or '-'}")
    cams = list_depthai_devices(timeout_s=args.timeout)
    _say("depthai devices:" if cams else "depthai devices: none found")
    for c in cams:
        _say(f"  {c['device_id']}  {c['name']}  {c['state']}  {c['protocol']}")
    return 0


def cmd_scan(args: argparse.Namespace) -> int:
    """rangekit scan --out DIR | --resume DIR [--rig sim|RIG.json] [--object lumpy] [--views 12] [--patterns hybrid]"""
    from dataclasses import asdict
    from pathlib import Path

    from rangekit.app.acquire import ScanPlan, acquire, load_session
    from rangekit.errors import ConfigError
    from rangekit.coded.patterns import PatternSpec, make_pattern_spec
    from rangekit.app.process import FUSION_METHODS
    from rangekit.rig import load_rig

    t0 = time.perf_counter()
    folder = args.resume or args.out
    extra: dict = {}
    # Everything is checked before any work starts or anything moves: the folder, the rig, the object.
    if args.fusion not in FUSION_METHODS:
        raise ConfigError(f"--fusion must be one of {', '.join(FUSION_METHODS)}, found {args.fusion!r}")
    if args.resume:
        data, views = load_session(args.resume)
        spec = PatternSpec.from_dict(data["pattern"], where=f"{args.resume}/session.json")
        rig = load_rig(f"{args.resume}/rig.json")
        n_views = len(views)
        hardware = "hardware" in data
        _say(f"resuming {args.resume}: {sum(v.done for v in views)}/{n_views} views already done")
    else:
        out = Path(args.out)
        if (out / "session.json").exists():
            raise ConfigError(f"{out}: already holds a session (session.json); continue it with "
                              f"'rangekit scan --resume {out}' or choose another folder")
        if out.exists() and (not out.is_dir() or any(out.iterdir())):
            raise ConfigError(f"{out}: exists and is not an empty folder; choose a new or empty folder")
        if args.views < 2:
            raise ConfigError(f"--views must be at least 2 to register a scan, found {args.views}")
        hardware = args.rig not in (None, "sim")
        rig = load_rig(args.rig) if hardware else None
        if hardware:
            from rangekit.drivers import validate_rig_for_hardware

            validate_rig_for_hardware(rig, where=args.rig)
        n_views, spec = args.views, None
    if hardware:
        from rangekit.drivers import open_rig_devices

        where = f"{args.resume}/rig.json" if args.resume else args.rig
        if rig.projector is None:
            raise ConfigError(f"{where}: a scan needs a projector (field 'projector')")
        devices = open_rig_devices(rig, where=where)
        if devices.camera is None or devices.projector is None:
            devices.close()
            raise ConfigError(f"{where}: 'devices' must name a camera (type depthai) and a projector display "
                              "(devices.projector.display)")
        extra = {"hardware": {"rig_file": str(where)}}
    else:
        from rangekit.sim import ImagingModel, SimRig, default_scene

        if args.resume:
            sim_info = data.get("simulator") or {}
            obj, seed, imaging = sim_info["object"], sim_info["seed"], ImagingModel(**sim_info["imaging"])
        else:
            obj, seed, imaging = args.object, args.seed, ImagingModel()
            default_scene(obj)  # a bad object name or file fails here, before the folder is made
        devices = SimRig(default_scene(obj), rig, imaging=imaging, seed=seed)
        rig = devices.rig
        extra = {"simulator": {"object": obj, "seed": seed, "imaging": asdict(imaging)}}
    spec = spec or make_pattern_spec(args.patterns, (rig.projector.width, rig.projector.height))
    try:
        views = acquire(devices, rig, spec, folder, plan=ScanPlan(n_views=n_views), resume=bool(args.resume),
                        pattern_settle_s=float(rig.capture.get("pattern_delay_s", 0.1)) if hardware else 0.0,
                        settle_s=float(rig.capture.get("turntable_settle_s", 0.5)) if hardware else 0.0,
                        extra=extra, progress=_console())
    except KeyboardInterrupt:
        print(f"rangekit: interrupted; completed views are safe. Continue with: rangekit scan --resume {folder}",
              file=sys.stderr)
        return 130
    finally:
        if hardware:
            devices.close()
    _say(f"acquired {sum(v.done for v in views)} views x {spec.n_frames} frames into {folder} in "
         f"{time.perf_counter() - t0:.1f} s")
    if args.no_process:
        _say(f"process it later with: rangekit process {folder}")
        return 0
    t_acq = time.perf_counter() - t0
    return _process(folder, args, acquisition_s=t_acq, resume_cmd=f"rangekit scan --resume {folder}")


def _process(folder: str, args: argparse.Namespace, *, acquisition_s: float | None = None,
             resume_cmd: str | None = None) -> int:
    from rangekit.app.process import process_session
    from rangekit.progress import format_seconds

    t0 = time.perf_counter()
    try:
        res = process_session(folder, fusion=args.fusion, report=not args.no_report, progress=_console())
    except KeyboardInterrupt:
        print(f"rangekit: interrupted; the views decoded so far are cached. Continue with: "
              f"{resume_cmd or f'rangekit process {folder}'}", file=sys.stderr)
        return 130
    _say("")
    _say(f"== {folder}: summary ==")
    if acquisition_s is not None:
        _say(f"acquisition: {format_seconds(acquisition_s)}")
    for line in res.summary_lines():
        _say(line)
    total = time.perf_counter() - t0 + (acquisition_s or 0.0)
    _say(f"wrote {folder}/mesh.ply, merged.ply, poses.json, summary.json"
         + ("" if args.no_report else ", report.html") + f" in {format_seconds(total)}")
    return 0


def cmd_process(args: argparse.Namespace) -> int:
    """rangekit process DIR [--fusion poisson|tsdf]: decode, register and fuse a session into DIR/mesh.ply"""
    return _process(args.session, args)


def _ply_has_faces(path) -> bool:
    """True if ``path`` is a PLY whose header declares at least one face."""
    import re

    with open(path, "rb") as f:
        head = f.read(4096)
    if not head.startswith(b"ply"):
        return False
    m = re.search(rb"element\s+face\s+(\d+)", head.split(b"end_header")[0])
    return bool(m and int(m.group(1)) > 0)


def cmd_render(args: argparse.Namespace) -> int:
    """rangekit render MESH_OR_CLOUD --out PNG: a shaded picture of a mesh or a cloud"""
    from pathlib import Path

    from rangekit.errors import FileFormatError
    from rangekit.io import write_png
    from rangekit.app.snapshot import fit_camera, montage, render_cloud, render_mesh

    src = Path(args.input)
    size = args.size
    mesh = cloud = None
    if not src.is_file():
        raise FileFormatError(f"{src}: no such file (expected a mesh or a point cloud)")
    if src.suffix.lower() in (".obj", ".stl", ".off", ".glb", ".gltf") or _ply_has_faces(src):
        from rangekit.formats.meshes import load_mesh_file

        mesh = load_mesh_file(src)
    else:
        from rangekit.formats.clouds import load_cloud

        cloud = load_cloud(src)
    pts = mesh.vertices if mesh is not None else cloud.points
    if len(pts) == 0:
        raise FileFormatError(f"{src}: holds no points or vertices to render")
    up = np.asarray(args.up, dtype=np.float64)
    images = []
    for az in args.azimuth:
        cam = fit_camera(pts, azimuth=np.radians(az), elevation=np.radians(args.elevation), size=size, up=up,
                         tight=True, margin=1.1)
        images.append(render_mesh(mesh, cam, smooth=True, colour_by_vertex=args.colour) if mesh is not None
                      else render_cloud(cloud, cam))
    write_png(args.out, images[0] if len(images) == 1 else montage(images, cols=min(len(images), 4)))
    _say(f"wrote {args.out}: {'mesh' if mesh is not None else 'cloud'} of {len(pts):,} "
         f"{'vertices' if mesh is not None else 'points'}, {len(images)} view(s)")
    return 0


def cmd_rig_init(args: argparse.Namespace) -> int:
    """rangekit rig init [--sim] > rig.json: a template rig file, or the simulator's true rig"""
    import json

    if args.sim:
        from rangekit.sim import default_rig

        data = default_rig().to_dict()
    else:
        from rangekit.rig import template_rig

        data = template_rig()
    sys.stdout.write(json.dumps(data, indent=2) + "\n")
    return 0


def _processing_options(p: argparse.ArgumentParser) -> None:
    from rangekit.app.process import FUSION_METHODS

    p.add_argument("--fusion", default="poisson", choices=FUSION_METHODS,
                   help="fusion into one mesh: poisson (default, screened Poisson of the merged cloud) or tsdf")
    p.add_argument("--no-report", action="store_true", help="skip report.html")


_POSE_HINTS = ("facing the camera, tilted ~30 deg to the left", "tilted ~30 deg to the right",
               "top edge tilted ~30 deg away", "bottom edge tilted ~30 deg away", "turned ~20 deg in its plane, tilted left",
               "near the left edge of the view, tilted right", "near the right edge of the view, tilted left",
               "near the top of the view, tilted down", "near the bottom of the view, tilted up",
               "closer to the camera, tilted ~40 deg", "further away, tilted ~20 deg")


def cmd_calibrate(args: argparse.Namespace) -> int:
    """rangekit calibrate --rig sim|RIG.json --out RIG.json: camera, projector, turntable and projector response"""
    from pathlib import Path

    from rangekit.boards import Board
    from rangekit.calib.procedure import CalibrationSettings, calibrate_rig, compare_rigs, comparison_lines
    from rangekit.errors import ConfigError
    from rangekit.rig import load_rig, save_rig

    out = Path(args.out)
    if out.exists() and not args.force:
        raise ConfigError(f"{out}: exists; choose another file or pass --force to overwrite it")
    if args.poses < 3:
        raise ConfigError(f"--poses must be at least 3 (Zhang's method), found {args.poses}; 15-25 is typical")
    board = Board(kind=args.board, cols=args.cols, rows=args.rows, square=args.square_mm / 1000.0)
    settings = CalibrationSettings(board=board, n_poses=args.poses)
    hardware = args.rig != "sim"
    t0 = time.perf_counter()
    if hardware:
        from rangekit.drivers import open_rig_devices, validate_rig_for_hardware

        template = load_rig(args.rig)
        validate_rig_for_hardware(template, where=args.rig)
        if not sys.stdin.isatty():
            raise ConfigError("calibrating real hardware is interactive (you move the board between captures); "
                              "run 'rangekit calibrate' in a terminal")
        devices = open_rig_devices(template, where=args.rig)

        def place(i: int, n: int) -> None:
            input(f"pose {i + 1}/{n}: hold the {board.cols}x{board.rows} board still, {_POSE_HINTS[i % len(_POSE_HINTS)]}, "
                  "wholly inside the projected light; press Enter to capture ")

        def on_turntable() -> None:
            input("turntable: fix the board on the turntable, standing and tilted back towards the camera, off the "
                  "axis, so that it stays visible while the table turns +-40 deg; press Enter ")
        truth = None
    else:
        from rangekit.sim.calibration import board_poses, board_scene, turntable_board_scene
        from rangekit.sim.devices import SimRig, default_rig

        template = truth = default_rig()
        poses = board_poses(truth, board, args.poses, seed=args.seed)
        devices = SimRig(board_scene(board, poses[0]), truth, seed=args.seed)

        def place(i: int, n: int) -> None:
            devices.set_scene(board_scene(board, poses[i]))

        def on_turntable() -> None:
            devices.set_scene(turntable_board_scene(truth, board))
    try:
        res = calibrate_rig(devices, settings=settings, place_board=place, place_on_turntable=on_turntable,
                            template=template, progress=_console())
    finally:
        if hardware:
            devices.close()
    save_rig(res.rig, out)
    _say("")
    _say("== calibration ==")
    for line in res.summary_lines():
        _say(line)
    if truth is not None:
        _say("deviation from the simulator's true rig (rangekit rig init --sim):")
        for line in comparison_lines(compare_rigs(res.rig, truth)):
            _say("  " + line)
    _say(f"wrote {out} in {time.perf_counter() - t0:.1f} s")
    return 0


def cmd_photometric(args: argparse.Namespace) -> int:
    """rangekit photometric DIR [--method ls|robust|uncalibrated] --out OUT: normals, albedo, depth, mesh"""
    from pathlib import Path

    import numpy as np

    from rangekit.photometric.diligent import load_diligent
    from rangekit.io import write_png
    from rangekit.formats.meshes import save_mesh
    from rangekit.surface.mesh import TriangleMesh
    from rangekit.photometric import (angular_error, depth_to_mesh, integrate_normals, photometric_stereo,
                                      uncalibrated_photometric_stereo)

    t0 = time.perf_counter()
    data = load_diligent(args.folder)
    _say(f"read {len(data.filenames)} images of {data.mask.shape[1]}x{data.mask.shape[0]} from {args.folder} "
         f"({int(data.mask.sum())} pixels in the mask) in {time.perf_counter() - t0:.1f} s")
    t1 = time.perf_counter()
    if args.method == "uncalibrated":
        res = uncalibrated_photometric_stereo(data.images, data.mask)
    else:
        res = photometric_stereo(data.images, data.lights, data.mask, method=args.method)
    _say(f"normals ({args.method}) in {time.perf_counter() - t1:.1f} s")
    if data.normals_gt is not None:
        err = angular_error(res.normals, data.normals_gt, data.mask)
        _say(f"angular error against Normal_gt.mat: mean {err.mean_deg:.3f} deg, median {err.median_deg:.3f} deg")
    t2 = time.perf_counter()
    depth = integrate_normals(res.normals, data.mask)
    V, F = depth_to_mesh(depth, data.mask, pixel_size=1.0)
    _say(f"integrated the normals into depth and a mesh of {len(V):,} vertices in {time.perf_counter() - t2:.1f} s")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    np.save(out / "normals.npy", res.normals.astype(np.float32))
    np.save(out / "depth.npy", depth.astype(np.float32))
    n = np.nan_to_num(res.normals)
    # Colour code as the benchmarks show it: RGB = (x, up, towards the viewer) / 2 + 1/2.
    rgb = np.stack([n[..., 0], -n[..., 1], -n[..., 2]], axis=-1) * 0.5 + 0.5
    write_png(out / "normals.png", np.where(data.mask[..., None], np.rint(rgb * 255), 0).astype(np.uint8))
    albedo = np.nan_to_num(res.albedo if res.albedo.ndim == 2 else res.albedo.mean(axis=2))
    scale = np.percentile(albedo[data.mask], 99) if data.mask.any() else 1.0
    write_png(out / "albedo.png", np.rint(np.clip(albedo / max(scale, 1e-12), 0, 1) * 255).astype(np.uint8))
    save_mesh(out / "mesh.ply", TriangleMesh(V, F))
    _say(f"wrote {out}/normals.npy, normals.png, albedo.png, depth.npy, mesh.ply (pixel units, orthographic) in "
         f"{time.perf_counter() - t0:.1f} s")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="rangekit", description="Active 3D scanning: simulate, capture, "
                                     "decode, register and fuse range data.")
    parser.add_argument("--version", action="version", version=f"rangekit {__import__('rangekit').__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    sim = sub.add_parser("sim", help="simulated rig: render captures with exact ground truth",
                         description="Simulated projector-camera-turntable rig.")
    sim_sub = sim.add_subparsers(dest="sim_command", metavar="SUBCOMMAND")
    sim_sub.required = True
    render = sim_sub.add_parser(
        "render", help="render a pattern sequence on a simulated object and write captures + ground truth",
        description="Render the captures a real rig would take of an object, plus ground_truth.npz "
                    "(depth, xyz, normals, proj_col, proj_row, valid), the rig file and a preview PNG.")
    from rangekit.coded.patterns import PATTERN_METHODS

    render.add_argument("--sensor", default="projector", choices=("projector", "tof", "tof-pulsed", "stereo"),
                        help="projector-camera rig (default), continuous-wave or pulsed time of flight, or the "
                             "active-stereo pair")
    render.add_argument("--object", default=None,
                        help="built-in object (plane, sphere, box, cylinder, torus, board, lumpy) or a mesh "
                             "file trimesh can read (metres); default: lumpy")
    render.add_argument("--patterns", default=None, choices=PATTERN_METHODS,
                        help="pattern set to project; default: graycode (44 frames on the default rig)")
    render.add_argument("--out", required=True, help="output folder (created if missing)")
    render.add_argument("--rig", help="rig file to simulate (default: the built-in simulated rig)")
    render.add_argument("--angle-deg", type=float, default=0.0, help="turntable angle in degrees (default 0)")
    render.add_argument("--bits", type=int, default=8, choices=(8, 10, 12, 16), help="camera bit depth")
    render.add_argument("--seed", type=int, default=0, help="noise seed (default 0)")
    render.add_argument("--no-noise", action="store_true", help="disable shot and read noise")
    render.add_argument("--global-fraction", type=float, default=None,
                        help="interreflection term, fraction of the mean projected light (default 0)")
    tof = render.add_argument_group("time of flight (--sensor tof, tof-pulsed)")
    tof.add_argument("--plan", default="kinect", choices=("kinect", "luxonis"),
                     help="frequency plan: kinect = 16/80/120 MHz x 3 steps (18.7 m), luxonis = 80/100 MHz x 4 "
                          "steps (7.5 m); default kinect")
    tof.add_argument("--frequencies-mhz", type=float, nargs="+", help="custom frequencies in MHz (instead of --plan)")
    tof.add_argument("--steps", type=int, help="phase steps per frequency (default: the plan's, or 4)")
    tof.add_argument("--near", type=float, default=0.5, help="nearest panel, metres (default 0.5)")
    tof.add_argument("--far", type=float, default=15.0, help="farthest panel, metres (default 15)")
    tof.add_argument("--multipath", type=float, nargs=2, metavar=("STRENGTH", "EXTRA_M"),
                     help="add a second return of STRENGTH x the direct light, EXTRA_M metres longer round trip")
    tof.add_argument("--jitter-ps", type=float, default=50.0, help="tof-pulsed: timing jitter, ps RMS (default 50)")
    sz = render.add_argument_group("time of flight and stereo")
    sz.add_argument("--size", type=_size, default=None,
                    help="sensor size WIDTHxHEIGHT (default: tof 320x240, stereo 640x400)")
    sz.add_argument("--no-dots", action="store_true", help="stereo: switch the dot projector off")
    render.set_defaults(func=cmd_sim_render)

    dec = sub.add_parser("decode", help="decode coded-light images into projector coordinates (maps.npz)",
                         description="Decode a capture into per-pixel projector column/row maps with confidence.")
    dec.add_argument("images", nargs="+", metavar="IMAGES",
                     help="a folder (images taken in natural numeric order) or a list of image files")
    dec.add_argument("--pattern", required=True,
                     help=f"pattern method ({', '.join(PATTERN_METHODS)}) or a patterns.json spec file")
    dec.add_argument("--projector", type=_size, help="projector resolution WxH, e.g. 1280x800")
    dec.add_argument("--order", default="rangekit", choices=("rangekit", "opencv"),
                     help="capture order; 'opencv' = GrayCodePattern (pairs, then white, black)")
    dec.add_argument("--integer", action="store_true", help="integer codes only (no subpixel refinement)")
    dec.add_argument("--out", required=True, help="output .npz with proj_col, proj_row, confidence and masks")
    dec.set_defaults(func=cmd_decode)

    rec = sub.add_parser("reconstruct", help="decode and triangulate a capture folder into a point cloud",
                         description="Decode a capture folder (from 'rangekit sim render' or acquisition) and "
                                     "triangulate it against the projector into a coloured cloud with normals.")
    rec.add_argument("capture", metavar="CAPTURE_DIR", help="capture folder (images + patterns.json)")
    rec.add_argument("--rig", help="rig file (default: the folder's rig.json)")
    rec.add_argument("--method", default="auto", choices=("auto", "ray-plane", "ray-ray"),
                     help="triangulation; auto = ray-ray where rows are coded, else ray-plane")
    rec.add_argument("--integer", action="store_true", help="integer codes only (no subpixel refinement)")
    rec.add_argument("--out", required=True, help="output cloud (.ply, .xyz or .npy)")
    rec.set_defaults(func=cmd_reconstruct)

    reg = sub.add_parser("register", help="register scans into one frame, merge and mesh them",
                         description="Register point clouds (PLY incl. Stanford range grids, PCD, XYZ, NPY) into "
                                     "the first scan's frame; writes DIR/poses.json, DIR/merged.ply, DIR/mesh.ply.")
    reg.add_argument("scans", nargs="+", metavar="SCAN", help="scan files")
    reg.add_argument("--init", default="none",
                     help="prior poses: none (coarse alignment of all pairs), a poses.json, or "
                          "turntable:AX,AY,AZ:STEP_DEG[:PX,PY,PZ] (view i turned i*STEP degrees about the axis)")
    reg.add_argument("--voxel-mm", type=float, default=None,
                     help="voxel for features and the first ICP round, mm (default: scene diagonal / 80)")
    reg.add_argument("--no-mesh", action="store_true", help="skip meshing")
    reg.add_argument("--out", required=True, help="output folder")
    reg.set_defaults(func=cmd_register)

    mesh = sub.add_parser("mesh", help="fuse one cloud into a watertight mesh (screened Poisson)",
                          description="Screened Poisson reconstruction with low-density trimming and hole closing.")
    mesh.add_argument("cloud", metavar="CLOUD", help="point cloud file (normals are estimated if missing)")
    mesh.add_argument("--depth", type=int, default=9, help="octree depth (default 9)")
    mesh.add_argument("--out", required=True, help="output mesh (.ply, .obj, .stl)")
    mesh.set_defaults(func=cmd_mesh)

    scan = sub.add_parser("scan", help="scan: acquire a turntable session (resumable), then process it into a mesh",
                          description="Acquire a crash-safe scan session (every turntable view, every pattern; "
                                      "--resume continues an interrupted one without redoing finished views), then "
                                      "decode, register and fuse it into DIR/mesh.ply.")
    where = scan.add_mutually_exclusive_group(required=True)
    where.add_argument("--out", help="new session folder")
    where.add_argument("--resume", metavar="DIR", help="continue the session in DIR")
    scan.add_argument("--rig", default="sim",
                      help="'sim' (default) or a rig file whose 'devices' name the turntable, projector and camera")
    scan.add_argument("--object", default="lumpy", help="simulated object: built-in name or mesh file")
    scan.add_argument("--views", type=int, default=12, help="turntable views over a full turn (default 12)")
    from rangekit.coded.patterns import PATTERN_METHODS as _PM

    scan.add_argument("--patterns", default="hybrid", choices=_PM,
                      help="pattern set (default hybrid: Gray code + phase shift)")
    scan.add_argument("--seed", type=int, default=0, help="simulator noise seed")
    scan.add_argument("--no-process", action="store_true", help="acquire only (process later with 'rangekit process')")
    _processing_options(scan)
    scan.set_defaults(func=cmd_scan)

    proc = sub.add_parser("process", help="decode, register and fuse an acquired session into a mesh",
                          description="Process a session folder (from 'rangekit scan'): every view decoded and "
                                      "triangulated, registered from the turntable angles, fused into mesh.ply.")
    proc.add_argument("session", metavar="DIR", help="session folder")
    _processing_options(proc)
    proc.set_defaults(func=cmd_process)

    ren = sub.add_parser("render", help="render a mesh or point cloud to a PNG (no display needed)",
                         description="Shade a mesh (ray cast) or a cloud (z-buffer splats) from one or more sides.")
    ren.add_argument("input", metavar="MESH_OR_CLOUD", help="mesh (.ply with faces, .obj, .stl, .off) or cloud "
                                                            "(.ply, .xyz, .npy, .pcd, .txt)")
    ren.add_argument("--out", required=True, help="output PNG")
    ren.add_argument("--azimuth", type=float, nargs="+", default=[30.0],
                     help="viewing azimuth(s) in degrees about --up; several give a montage (default 30)")
    ren.add_argument("--elevation", type=float, default=25.0, help="degrees above the horizontal (default 25)")
    ren.add_argument("--up", type=float, nargs=3, default=[0.0, 0.0, 1.0], metavar=("X", "Y", "Z"),
                     help="the object's up direction (default 0 0 1; Stanford scans: 0 1 0)")
    ren.add_argument("--size", type=_size, default=(800, 600), help="image size WxH (default 800x600)")
    ren.add_argument("--colour", action="store_true", help="shade a mesh with its vertex colours (default grey)")
    ren.set_defaults(func=cmd_render)

    cal = sub.add_parser("calibrate", help="calibrate camera, projector, turntable axis and projector response",
                         description="Capture a board at several poses under coded light (the simulator moves it; "
                                     "on hardware you do, pose by pose), calibrate the camera and the projector "
                                     "(bundle adjusted together), the turntable axis and the projector's gamma, and "
                                     "write a rig file. On the simulator it also prints each parameter's deviation "
                                     "from the true rig.")
    cal.add_argument("--rig", default="sim", help="'sim' (default) or a rig file naming the devices (its geometry "
                                                   "is replaced)")
    cal.add_argument("--out", required=True, help="rig file to write")
    cal.add_argument("--force", action="store_true", help="overwrite --out if it exists")
    cal.add_argument("--poses", type=int, default=20, help="board poses (default 20)")
    cal.add_argument("--board", default="checkerboard", choices=("checkerboard", "charuco"), help="board type")
    cal.add_argument("--cols", type=int, default=10, help="squares along the board's width (default 10)")
    cal.add_argument("--rows", type=int, default=7, help="squares along its height (default 7)")
    cal.add_argument("--square-mm", type=float, default=20.0, help="square side in millimetres (default 20)")
    cal.add_argument("--seed", type=int, default=0, help="simulator: noise and pose seed")
    cal.set_defaults(func=cmd_calibrate)

    pst = sub.add_parser("photometric", help="photometric stereo: normals, albedo, depth and a mesh from a DiLiGenT-style folder",
                         description="Read a DiLiGenT-style folder (filenames.txt, light_directions.txt, "
                                     "light_intensities.txt, mask.png, optional Normal_gt.mat), recover the normals "
                                     "(OpenCV camera frame: x right, y down, z forward; NaN outside the mask), the "
                                     "albedo, and integrate the normals into depth and a mesh (pixel units).")
    pst.add_argument("folder", metavar="DIR", help="folder in the DiLiGenT layout")
    pst.add_argument("--method", default="robust", choices=("ls", "robust", "uncalibrated"),
                     help="least squares, robust to shadows and highlights (default), or without light directions")
    pst.add_argument("--out", required=True, help="output folder")
    pst.set_defaults(func=cmd_photometric)

    tofp = sub.add_parser("tof", help="time of flight: range, depth and a cloud from raw ToF samples",
                          description="Decode a ToF capture folder (rangekit sim render --sensor tof|tof-pulsed, "
                                      "layout in docs/tof.md): N-bucket phase, amplitude and offset per frequency, "
                                      "multi-frequency unwrapping, flying-pixel filter, radial range to depth.")
    tofp.add_argument("raw_dir", metavar="RAW_DIR", help="ToF capture folder (tof.json, rig.json, samples/)")
    tofp.add_argument("--out", required=True, help="output folder: depth.npy (z, metres, NaN invalid), range.npy, "
                                                    "confidence.npy/png, depth.png, cloud.ply")
    tofp.add_argument("--max-range", type=float, help="metres; default the plan's unambiguous range")
    tofp.add_argument("--min-snr", type=float, default=3.0,
                      help="drop pixels whose phase noise exceeds 1/MIN_SNR rad (default 3)")
    tofp.add_argument("--flying-angle-deg", type=float, default=15.0,
                      help="flying-pixel filter threshold in degrees (default 15)")
    tofp.add_argument("--keep-flying", action="store_true", help="do not filter flying pixels")
    tofp.set_defaults(func=cmd_tof)

    stp = sub.add_parser("stereo", help="active stereo: depth of the left camera from a stereo pair",
                         description="Rectify a raw stereo pair with the rig file's two cameras (cameras[0] = left, "
                                     "cameras[1] = right), match it (census + semi-global matching, or OpenCV "
                                     "StereoSGBM), check left-right consistency, refine to subpixel and convert to "
                                     "depth on the left camera's own pixel grid (docs/stereo.md).")
    stp.add_argument("left", metavar="LEFT", help="left image (PNG, 8 or 16 bit, grey or RGB)")
    stp.add_argument("right", metavar="RIGHT", help="right image, same size")
    stp.add_argument("--rig", required=True, help="rig file with two cameras (left first)")
    stp.add_argument("--out", required=True, help="output folder: depth.npy (left z, metres, NaN invalid), depth.png, "
                                                   "confidence.npy/png, cloud.ply")
    stp.add_argument("--method", default="census-sgm", choices=("census-sgm", "sgbm"),
                     help="our census + semi-global matcher (default) or OpenCV's StereoSGBM")
    stp.add_argument("--num-disparities", type=int, help="disparity search range (multiple of 16; default from "
                                                         "--min-depth)")
    stp.add_argument("--min-depth", type=float, default=0.4, help="nearest depth to search, metres (default 0.4)")
    stp.add_argument("--alpha", type=float, default=0.0,
                     help="rectification scaling: 0 crops to valid pixels (finer at low resolution, default), 1 keeps "
                          "every source pixel; 0.5 reaches the image borders at 640x400 (docs/stereo.md)")
    stp.set_defaults(func=cmd_stereo)

    rig = sub.add_parser("rig", help="rig files: write a template",
                         description="Rig files (docs/rig.md documents every field).")
    rig_sub = rig.add_subparsers(dest="rig_command", metavar="SUBCOMMAND")
    rig_sub.required = True
    init = rig_sub.add_parser("init", help="print a template rig file for real hardware (rangekit rig init > rig.json)",
                              description="Print a rig file to standard output: a template to edit for real "
                                          "hardware, or with --sim the simulator's default rig (its true "
                                          "parameters).")
    init.add_argument("--sim", action="store_true", help="print the simulator's default rig instead")
    init.set_defaults(func=cmd_rig_init)

    dev = sub.add_parser("devices", help="list serial ports and depthai cameras",
                         description="List serial ports (device, USB VID:PID, serial number) and depthai cameras.")
    dev.add_argument("--timeout", type=float, default=1.0, help="seconds to search for depthai cameras (default 1)")
    dev.set_defaults(func=cmd_devices)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except RangekitError as exc:
        print(f"rangekit: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("rangekit: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
