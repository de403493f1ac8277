"""``rangekit photometric``: normals, albedo, depth and a mesh from a DiLiGenT-style folder."""

from __future__ import annotations

import argparse
import time

from rangekit.cli._common import check_output, result, say
from rangekit.formats.output_sets import claim_folder
from rangekit.formats.sessions.files import MESH_FILE


def cmd_photometric(args: argparse.Namespace) -> int:
    """rangekit photometric DIR [--method ls|robust|uncalibrated] --out OUT: normals, albedo, depth, mesh"""
    from rangekit.app.commands.photometric import photometric_folder

    t0 = time.perf_counter()
    check_output(args.out, folder=True)
    replace = claim_folder(args.out, "photometric", force=args.force, inputs=[args.folder])
    out = photometric_folder(args.folder, args.out, method=args.method, progress=say)
    replace()
    result(f"wrote {out}/normals.npy, normals.png, albedo.png, depth.npy, {MESH_FILE} (pixel units, orthographic) in "
        f"{time.perf_counter() - t0:.1f} s")
    return 0


def add_parsers(sub) -> None:
    pst = sub.add_parser("photometric", help="photometric stereo: normals, albedo, depth and a mesh from a DiLiGenT-style folder",
                         description="Read a DiLiGenT-style folder (filenames.txt, light_directions.txt, "
                                     "light_intensities.txt, mask.png, optional Normal_gt.mat), recover the normals "
                                     "(OpenCV camera frame: x right, y down, z forward; NaN outside the mask), the "
                                     "albedo, and integrate the normals into depth and a mesh (pixel units).")
    pst.add_argument("folder", metavar="DIR", help="folder in the DiLiGenT layout")
    pst.add_argument("--method", default="robust", choices=("ls", "robust", "uncalibrated"),
                     help="least squares, robust to shadows and highlights (default), or without light directions")
    pst.add_argument("--out", required=True, help="output folder")
    pst.add_argument("--force", action="store_true", help="write over files in --out this run did not make: another command's set (a session, a capture, results), files of yours, an input")
    pst.set_defaults(func=cmd_photometric)
