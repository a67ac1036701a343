"""Reading and writing images and depth maps in every supported format, safely.

Imports NumPy, imageio, Pillow, tifffile, h5py and :mod:`sparsedepth._validation`; nothing else of the package.
"""

from .formats import (
    DEPTH_SCALES,
    KINECT_NYU,
    MAX_PIXELS,
    KinectDisparity,
    NYUDepthV2Labeled,
    StereoCalibration,
    disparity_to_depth,
    read_calib,
    read_depth,
    read_depth_array,
    read_depth_png,
    read_image,
    read_mask,
    read_nyu_h5,
    read_pfm,
    write_depth,
    write_pfm,
)

__all__ = ["DEPTH_SCALES", "KINECT_NYU", "KinectDisparity", "MAX_PIXELS", "NYUDepthV2Labeled", "StereoCalibration",
           "disparity_to_depth", "read_calib", "read_depth", "read_depth_array", "read_depth_png", "read_image",
           "read_mask", "read_nyu_h5", "read_pfm", "write_depth", "write_pfm"]
