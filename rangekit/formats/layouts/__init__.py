"""Other tools' capture folders as data (issue 35): :data:`LAYOUTS`, every preset by name, and the machinery of
:mod:`rangekit.formats.layouts.layout`. One module per tool holds that tool's presets."""


from rangekit._runtime.lazy import attach_stub

__getattr__, __dir__, __all__ = attach_stub(__name__, __file__)
__all__ = [*__all__, "LAYOUTS"]

from rangekit.formats.layouts.opencv import OPENCV_LAYOUTS  # noqa: E402
from rangekit.formats.layouts.procam import PROCAM_LAYOUTS  # noqa: E402
from rangekit.formats.layouts.roomalive import ROOMALIVE_LAYOUTS  # noqa: E402
from rangekit.formats.layouts.scan3d import SCAN3D_LAYOUTS  # noqa: E402
from rangekit.formats.layouts.slstudio import SLSTUDIO_LAYOUTS  # noqa: E402

#: Every preset by its name ("tool:codec").
LAYOUTS = {**SLSTUDIO_LAYOUTS, **OPENCV_LAYOUTS, **PROCAM_LAYOUTS, **SCAN3D_LAYOUTS, **ROOMALIVE_LAYOUTS}
