"""Reading and writing images and depth maps in every supported format, safely.

One module per responsibility:

* :mod:`.files` - messages, pixel limits, decoder errors and atomic writes;
* :mod:`.formats` - the table of file formats (extensions, what each holds, its reader and writer), from
  which every list of extensions of the package is derived: a new format is one entry there plus its module;
* :mod:`.stored` - the dtype/shape rules of stored arrays and their conversion to depth;
* :mod:`.netpbm`, :mod:`.images` - grey and colour images (Netpbm, PNG, JPEG, BMP, TIFF);
* :mod:`.pfm` - Portable Float Maps;
* :mod:`.calibration` - ``calib.txt``, stereo and Kinect disparity to depth, camera intrinsics files;
* :mod:`.arrays` - NumPy ``.npy``/``.npz`` and HDF5 arrays;
* :mod:`.nyu` - the NYU Depth V2 files;
* :mod:`.depth` - depth scales, :func:`read_depth`, :func:`read_mask`;
* :mod:`.pointcloud` - :func:`depth_to_points` (pinhole back-projection) and PLY files;
* :mod:`.colmap` - COLMAP sparse models (cameras, images, 3-D points; text and binary) and each view's sparse depth;
* :mod:`.writing` - :func:`write_depth`, :func:`depth_writer` and the uncertainty writers.

Conventions shared by every function:

* Depth is float64 in metres (or the unit asked through ``scale``) with NaN
  for invalid pixels; see :mod:`.depth`.
* Missing files raise :class:`FileNotFoundError`; anything that is not a
  regular file (directory, FIFO, device), unreadable or inconsistent content,
  images declaring more than ``max_pixels`` pixels (default
  :data:`MAX_PIXELS`, checked from the header before decoding) and unknown
  formats raise :class:`ValueError` naming the file and what was expected.
* Every reader takes ``name=``, the label of the path in its messages (the
  command line passes the flag the user typed, e.g. ``"--depth"``); readers
  with options also take ``option_names=``, a mapping from keyword to label.
* Every writer is atomic (:func:`atomic_target`).

Besides ``__all__``, the package exports :func:`atomic_target`,
:func:`create_temporary`, :func:`fsync`, :func:`resolve_scale` and
:func:`depth_writer` and :func:`ply_writer` for the command line and batch runs.

Imports NumPy, imageio, Pillow, tifffile, h5py and :mod:`sparsedepth._validation`; nothing else of the package.
"""

from .calibration import KINECT_NYU, KinectDisparity, StereoCalibration, disparity_to_depth, read_calib, read_intrinsics
from .colmap import ColmapModel, read_colmap_model, view_depth, view_observations, write_colmap_model
from .formats import read_depth_array
from .depth import DEPTH_SCALES, read_depth, read_depth_png, read_mask, resolve_scale  # noqa: F401 - resolve_scale for the CLI
from .files import MAX_PIXELS, atomic_target, create_temporary, fsync  # noqa: F401 - atomic writes for the CLI and batch runs
from .formats import read_image
from .nyu import NYUDepthV2Labeled, read_nyu_h5
from .pfm import read_pfm, write_pfm
from .pointcloud import depth_to_points, ply_writer, read_ply, write_ply  # noqa: F401 - ply_writer for the CLI
from .writing import depth_writer, write_depth  # noqa: F401 - depth_writer for the CLI

__all__ = ["ColmapModel", "DEPTH_SCALES", "KINECT_NYU", "KinectDisparity", "MAX_PIXELS", "NYUDepthV2Labeled",
           "StereoCalibration", "depth_to_points", "disparity_to_depth", "read_calib", "read_depth", "read_depth_array", "read_depth_png", "read_image",
           "read_colmap_model", "read_intrinsics", "read_mask", "read_nyu_h5", "read_pfm", "read_ply", "view_depth", "view_observations",
           "write_colmap_model", "write_depth", "write_pfm", "write_ply"]
