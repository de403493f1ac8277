"""From a capture to a point cloud: decode, triangulate, filter, colour and orient normals."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rangekit.camera import PinholeCamera
from rangekit.coded.decode import decode
from rangekit.coded.hdr import merge_decodes
from rangekit.coded.motion import MAX_MOTION_SHARE
from rangekit.coded.result import DecodeResult
from rangekit.errors import ConfigError, DecodeError
from rangekit.coded.patterns import PatternSpec
from rangekit.surface.cloud import PointCloud
from rangekit.rig.capture_check import RigCheck, check_rig
from rangekit.rig.projector_response import ProjectorResponse
from rangekit.coded.uncertainty import point_sigma
from rangekit.coded.triangulate import TriangulationResult, filter_range_map, triangulate

__all__ = ["EDGE_MARGIN_PX", "Reconstruction", "decode_view", "decoded_coordinates", "reconstruct_decoded",
           "reconstruct_view"]

#: Pixels dropped around depth edges beyond the one-pixel rim. Under the camera blur the points within
#: 2 px of a depth edge mix the two surfaces: on the simulated bunny (4 views) they were 6.8% of the
#: points in the 9th decile of predicted sigma with 3x its error; dropping one more pixel (3.2% of the
#: points) brings every decile's observed error within 3% of the predicted sigma
#: (benchmarks/coded/bench_uncertainty.py, docs/metrology.md).
EDGE_MARGIN_PX = 1


@dataclass(frozen=True, eq=False)
class Reconstruction:
    """One view: the decoded maps, the organised points after filtering, and the coloured cloud."""

    decoded: DecodeResult
    triangulated: TriangulationResult  # organised (H, W, 3), world frame, flying pixels removed
    cloud: PointCloud                  # valid points with colour (white capture), normals (facing camera)
                                       # and sigma where the decoder predicts its coordinates' std
    sigma: np.ndarray | None = None    # (H, W) float32 metres: predicted std along the camera ray, NaN where
                                       # no point or no prediction (rangekit.coded.uncertainty.point_sigma)
    rig_check: RigCheck | None = None  # how well the rig explains the decoded coordinates (rangekit.rig.capture_check)

    def __repr__(self) -> str:
        return f"Reconstruction({self.decoded!r}, {self.cloud!r})"


def reconstruct_view(images, spec: PatternSpec, camera: PinholeCamera, projector: PinholeCamera, *,
                     order: str = "rangekit", subpixel: bool = True, method: str = "auto",
                     max_jump: float = 0.004, max_residual: float = 0.002, min_confidence: float = 0.03,
                     edge_margin: int = EDGE_MARGIN_PX,
                     full_scale: float | None = None, response: ProjectorResponse | None = None,
                     exposures_us=None, decode_options: dict | None = None, motion: bool = False,
                     max_motion: float | None = MAX_MOTION_SHARE) -> Reconstruction:
    """Decode ``images`` and triangulate against ``projector``.

    ``max_jump`` (relative range step, see :func:`rangekit.coded.triangulate.discontinuity_mask`, applied with
    the normals by :func:`rangekit.coded.triangulate.filter_range_map`) removes flying
    pixels at depth edges, and ``edge_margin`` pixels more around them and around every region's rim (mixed
    pixels under the camera blur); ``max_residual`` (metres) removes ray-ray points whose rays miss each other;
    ``min_confidence`` drops pixels whose decoded confidence (about the white - black signal as a fraction
    of full scale) is lower: at 1-2% of full scale noise moves stripe edges by a large fraction of a
    column, which at grazing angles is millimetres. ``response`` is the projector's response (the rig's
    ``projector_response``), which phase methods correct for (see :func:`rangekit.coded.decode.decode`).
    ``exposures_us`` (increasing): ``images`` is then one stack per exposure (multi-exposure capture), each
    decoded and merged per pixel (:func:`rangekit.coded.hdr.merge_decodes`). ``decode_options``: more keyword
    arguments of :func:`rangekit.coded.decode.decode` (a capture layout's, e.g. ``max_global_ratio``).
    ``motion``, ``max_motion``: the decoder's motion check (binary codes; a capture over ``max_motion`` moved is a
    MotionError), as ``rangekit decode`` runs it; off where the caller checks motion its own way (a scan's views).
    """
    dec = decode_view(images, spec, camera, projector, order=order, subpixel=subpixel, full_scale=full_scale,
                      response=response, exposures_us=exposures_us, decode_options=decode_options, motion=motion,
                      max_motion=max_motion)
    return reconstruct_decoded(dec, camera, projector, method=method, max_jump=max_jump, max_residual=max_residual,
                               min_confidence=min_confidence, edge_margin=edge_margin, full_scale=full_scale)


def decode_view(images, spec: PatternSpec, camera: PinholeCamera, projector: PinholeCamera, *,
                order: str = "rangekit", subpixel: bool = True, full_scale: float | None = None,
                response: ProjectorResponse | None = None, exposures_us=None, decode_options: dict | None = None,
                motion: bool = False, max_motion: float | None = MAX_MOTION_SHARE) -> DecodeResult:
    """:func:`reconstruct_view`'s first half, its keywords: the rig's sizes checked against ``images`` and
    ``spec``, then the capture decoded (each exposure's, merged). The result's ``white`` may be a view of
    ``images`` (copy it out to free the frames before :func:`reconstruct_decoded`: the decode stage does)."""
    probe = np.asarray(images[0][0] if exposures_us is not None else images[0])
    if camera.size != (probe.shape[1], probe.shape[0]):
        raise ConfigError(f"the captures are {probe.shape[1]}x{probe.shape[0]} "
                          f"but the rig's camera {camera.name!r} is {camera.width}x{camera.height}")
    if projector.size != (spec.width, spec.height):
        raise ConfigError(f"the pattern spec is for a {spec.width}x{spec.height} projector but the rig's "
                          f"projector is {projector.width}x{projector.height}")
    if exposures_us is not None:
        stacks = list(images)
        decs = [decode(st, spec, order=order, subpixel=subpixel, full_scale=full_scale, response=response,
                       motion=motion, max_motion=max_motion, **(decode_options or {})) for st in stacks]
        top = full_scale or (255.0 if np.asarray(stacks[0][0]).dtype == np.uint8 else 65535.0)
        dec = merge_decodes(decs, exposures_us, top)[0]
    else:
        dec = decode(images, spec, order=order, subpixel=subpixel, full_scale=full_scale, response=response,
                     motion=motion, max_motion=max_motion, **(decode_options or {}))
    return dec


def decoded_coordinates(dec: DecodeResult, min_confidence: float) -> tuple[np.ndarray, np.ndarray | None]:
    """(proj_col, proj_row or None where rows were not coded): ``dec``'s coordinates, NaN where its confidence
    is under ``min_confidence`` (what :func:`reconstruct_decoded` triangulates and checks the rig against)."""
    weak = dec.confidence < min_confidence
    cols = np.where(weak, np.nan, dec.proj_col)
    rows = np.where(weak, np.nan, dec.proj_row) if np.any(np.isfinite(dec.proj_row)) else None
    return cols, rows


def reconstruct_decoded(dec: DecodeResult, camera: PinholeCamera, projector: PinholeCamera, *, method: str = "auto",
                        max_jump: float = 0.004, max_residual: float = 0.002, min_confidence: float = 0.03,
                        edge_margin: int = EDGE_MARGIN_PX, full_scale: float | None = None) -> Reconstruction:
    """The decoded capture ``dec`` triangulated against ``projector`` and filtered (:func:`reconstruct_view`'s
    second half, its keywords); the rig checked against it first (:attr:`Reconstruction.rig_check`)."""
    cols, rows = decoded_coordinates(dec, min_confidence)
    checked = check_rig(camera, projector, cols, rows)
    tri = triangulate(camera, projector, cols, rows, method=method)
    # flying pixels (and ray-ray points whose rays miss) dropped, normals of what is left: one compiled pass
    xyz, normals = filter_range_map(tri.xyz, camera.center, max_jump=max_jump, margin=edge_margin,
                                    extra_drop=~(tri.residual <= max_residual) if tri.method == "ray-ray" else None)
    tri = TriangulationResult(xyz, np.where(np.isfinite(xyz[:, :, 0]), tri.residual, np.nan), tri.method,
                              tri.proj_xy, tri.gains)
    valid = tri.valid
    if not np.any(valid):
        why = f"; {checked.describe()}" if checked.checkable else ""
        raise DecodeError("no 3D point survived decoding and triangulation; check the rig file and that the "
                          f"captures show the object lit by the projector{why}")
    normals = normals[valid]
    normals = np.where(np.isfinite(normals), normals, 0.0)
    white = np.asarray(dec.white, dtype=np.float32)
    white /= 255.0 if dec.white.dtype == np.uint8 else float(full_scale or 65535)
    colours = white[valid] if white.ndim == 3 else np.repeat(white[valid][:, None], 3, axis=1)
    sigma = None
    if dec.col_std is not None:
        if tri.method == "ray-ray":
            sigma = point_sigma(camera, projector, xyz, dec.col_std, dec.row_std, cols, rows, proj_xy=tri.proj_xy,
                                gains=tri.gains)
        else:
            sigma = point_sigma(camera, projector, xyz, dec.col_std)
    return Reconstruction(dec, tri, PointCloud(xyz[valid], np.clip(colours, 0, 1), normals,
                                               None if sigma is None else sigma[valid]), sigma, checked)
