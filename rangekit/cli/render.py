"""``rangekit render``: a mesh or point cloud to a PNG, no display needed."""

from __future__ import annotations

import argparse

import numpy as np

from rangekit.cli._common import check_output, finite_float, result, size


def cmd_render(args: argparse.Namespace) -> int:
    """rangekit render MESH_OR_CLOUD --out PNG: a shaded picture of a mesh or a cloud"""
    from rangekit.app.commands.picture import render_file
    from rangekit.io import PNG_SUFFIXES, write_png

    check_output(args.out, suffixes=PNG_SUFFIXES, what="PNG image", force=args.force, inputs=[args.input])
    pic = render_file(args.input, azimuths=[np.radians(az) for az in args.azimuth],
                      elevation=np.radians(args.elevation), size=args.size, up=args.up, colour=args.colour)
    write_png(args.out, pic.image)
    result(f"wrote {args.out}: {'mesh' if pic.is_mesh else 'cloud'} of {pic.n_points:,} "
        f"{'vertices' if pic.is_mesh else 'points'}, {pic.n_views} view(s)")
    return 0


def add_parsers(sub) -> None:
    ren = sub.add_parser("render", help="render a mesh or point cloud to a PNG (no display needed)",
                         description="Shade a mesh (ray cast) or a cloud (z-buffer splats) from one or more sides.")
    ren.add_argument("input", metavar="MESH_OR_CLOUD", help="mesh (.ply with faces, .obj, .stl, .off, .glb) or "
                                                            "cloud (.ply, .xyz, .npy, .pcd, .txt, .e57)")
    ren.add_argument("--out", required=True, help="output PNG")
    ren.add_argument("--force", action="store_true", help="overwrite --out if it exists")
    ren.add_argument("--azimuth", type=finite_float, nargs="+", default=[30.0],
                     help="viewing azimuth(s) in degrees about --up; several give a montage (default 30)")
    ren.add_argument("--elevation", type=finite_float, default=25.0, help="degrees above the horizontal (default 25)")
    ren.add_argument("--up", type=finite_float, nargs=3, default=[0.0, 0.0, 1.0], metavar=("X", "Y", "Z"),
                     help="the object's up direction (default 0 0 1; Stanford scans: 0 1 0)")
    ren.add_argument("--size", type=size, default=(800, 600), help="image size WxH (default 800x600)")
    ren.add_argument("--colour", action="store_true", help="shade a mesh with its vertex colours (default grey)")
    ren.set_defaults(func=cmd_render)
