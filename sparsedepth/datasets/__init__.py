"""Real RGB + depth frames: shipped samples, the shared data folder and NYU files.

Every loader returns a :class:`Frame` whose ``depth`` is the ground truth as
float64 with NaN for invalid pixels, in metres (``units="m"``) or, for
uncalibrated stereo data, disparity in pixels (``units="disparity_px"``).

Three sources:

* :func:`load_motorcycle` - the Middlebury 2014 *Motorcycle* pair shipped with
  scikit-image (always available);
* :func:`load_embedded_frame` - small frames shipped in ``sparsedepth/data``
  (see ``sparsedepth/data/SOURCES.md``), always available;
* :func:`load_shared_frame` - the frames of the ``shared/data`` folder (see its
  ``SOURCES.md``), located by :func:`shared_data_dir`; :func:`shared_frame_scenes`
  says which of them show one scene.

:func:`load_nyu_labeled` reads one frame of the NYU Depth V2 labeled ``.mat``.

One module per responsibility:

* :mod:`.frame` - :class:`Frame`, its units, the camera constants and the
  helpers both sources share;
* :mod:`.embedded` - frames that need no external folder (shipped samples,
  scikit-image's Motorcycle, NYU labeled files);
* :mod:`.shared` - the shared data folder and its registry of frames.

May import NumPy, scikit-image, :mod:`sparsedepth.io` and
:mod:`sparsedepth._validation`; nothing else of the package.
"""

from .embedded import list_embedded_frames, load_embedded_frame, load_motorcycle, load_nyu_labeled
from .frame import MOTORCYCLE_CALIBRATION, NYU_RGB_INTRINSICS, Frame
from .shared import list_shared_frames, load_shared_frame, shared_data_dir, shared_frame_scenes

__all__ = [
    "Frame",
    "MOTORCYCLE_CALIBRATION",
    "NYU_RGB_INTRINSICS",
    "list_embedded_frames",
    "list_shared_frames",
    "load_embedded_frame",
    "load_motorcycle",
    "load_nyu_labeled",
    "load_shared_frame",
    "shared_data_dir",
    "shared_frame_scenes",
]
