"""The names of ``rangekit.photometric``, each loaded from its module on first use (rangekit._runtime.lazy.attach_stub)."""

from .solve import PhotometricResult as PhotometricResult
from .accuracy import AngularError as AngularError, angular_error as angular_error
from .calibrated import photometric_stereo as photometric_stereo
from .uncalibrated import uncalibrated_photometric_stereo as uncalibrated_photometric_stereo
from .integrate import integrate_normals as integrate_normals
from .mesh import depth_to_mesh as depth_to_mesh
