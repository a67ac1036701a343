"""Point clouds: depth to 3-D points through a pinhole camera, and PLY files.

What lives here: :func:`depth_to_points` (back-projection of a depth map
with the intrinsics ``(fx, fy, cx, cy)``, colours from the image),
:func:`write_ply` / :func:`ply_writer` (binary little-endian PLY, vertices
only, written atomically) and :func:`read_ply` (the PLY files this module
writes, binary little-endian or ASCII).

Imports NumPy, :mod:`sparsedepth._validation` and :mod:`.files` /
:mod:`.stored` only.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

import numpy as np

from .._validation import argument_label, check_input_file, check_intrinsics
from .files import atomic_target, check_extension, file_label, read_bytes
from .stored import check_real_array

__all__ = ["PLY_COMMENT", "depth_to_points", "ply_writer", "read_ply", "write_ply"]

#: The ``comment`` line of every PLY file written here: the unit and the axes.
PLY_COMMENT = "sparsedepth point cloud: x y z in metres, camera frame (x right, y down, z forward)"

_XYZ = (("x", "<f4"), ("y", "<f4"), ("z", "<f4"))
_RGB = (("red", "u1"), ("green", "u1"), ("blue", "u1"))
# PLY type names (the 1994 specification's and the sized aliases most writers also use)
_FLOAT_NAMES = ("float", "float32")
_UCHAR_NAMES = ("uchar", "uint8")
_MAX_HEADER_BYTES = 1 << 16


def _as_colors(image, shape: tuple[int, int]) -> np.ndarray:
    """(H, W, 3) uint8 colours of ``image``: grey is repeated, alpha dropped, 16-bit and float scaled to 8 bits."""
    array = check_real_array(image, "image")
    if array.ndim == 3 and array.shape[2] == 1:
        array = array[:, :, 0]
    if array.ndim == 2:
        array = np.repeat(array[:, :, None], 3, axis=2)
    if array.ndim != 3 or array.shape[2] not in (3, 4):
        raise ValueError(f"`image` must be grey (H, W) or colour (H, W, 3) / (H, W, 4), got shape {array.shape}.")
    if array.shape[:2] != tuple(shape):
        raise ValueError(f"`image` has shape {array.shape[:2]} but `depth` has shape {tuple(shape)}; "
                         "they must be the same pixel grid.")
    array = array[:, :, :3]
    if array.dtype == np.uint8:
        return array
    if np.issubdtype(array.dtype, np.floating):
        if not np.all(np.isfinite(array)) or array.min(initial=0) < 0 or array.max(initial=0) > 1:
            raise ValueError("a float `image` must hold finite values in [0, 1]; convert it to uint8 first.")
        return np.rint(array * 255.0).astype(np.uint8)
    if array.dtype == np.uint16:
        return np.rint(array / 257.0).astype(np.uint8)
    if array.min(initial=0) < 0 or array.max(initial=0) > 255:
        raise ValueError(f"an integer `image` of dtype {array.dtype} must hold values in [0, 255] "
                         "(or be uint16); convert it to uint8 first.")
    return array.astype(np.uint8)


_FLOAT32_MAX = float(np.finfo(np.float32).max)


def depth_to_points(depth, intrinsics, *, image=None, name: str = "intrinsics") -> tuple[np.ndarray, np.ndarray | None]:
    """Back-project a depth map to 3-D points in the camera frame (pinhole model).

    Parameters
    ----------
    depth : (H, W) array_like of real numbers
        Depth ``z`` along the optical axis, in metres; pixels that are NaN,
        infinite or ``<= 0`` are missing and skipped.
    intrinsics : sequence of 4 floats, 3x3 array_like or camera object
        ``(fx, fy, cx, cy)`` in pixels, for this ``(H, W)`` grid (scale them
        with the image: see Notes); or the matrix ``K``, or an object with
        ``fx``, ``fy``, ``cx``, ``cy`` or an ``intrinsic_matrix`` (Open3D's
        ``PinholeCameraIntrinsic``), see
        :func:`~sparsedepth._validation.check_intrinsics`.
    image : (H, W) or (H, W, 3) or (H, W, 4) array_like, optional
        The image registered with ``depth``.  uint8 as is, uint16 divided by
        257, float in [0, 1] times 255; grey is repeated in the three
        channels, alpha dropped.
    name : str, optional
        How ``intrinsics`` is named in messages (``"--intrinsics"`` on the
        command line).

    Returns
    -------
    points : (N, 3) ndarray of float32
        ``x, y, z`` in metres of the ``N`` valid pixels, in C (row-major)
        order.
    colors : (N, 3) ndarray of uint8 or None
        RGB of the same pixels; None without ``image``.

    Raises
    ------
    ValueError
        If ``depth`` is not 2-D, ``image`` does not match its grid or has
        values out of range, a focal length is not a positive number, or a
        point would lie beyond the float32 range (focal lengths far too
        small for the image, or a depth beyond it).
    TypeError
        If ``depth`` or ``image`` is not real-valued, or ``intrinsics`` is not
        four numbers.

    Notes
    -----
    The pixel in row ``v`` and column ``u`` (both from 0) has its centre at
    image coordinates ``(u, v)``: integer coordinates are pixel centres, the
    convention of OpenCV and of the KITTI and NYU calibrations.  With depth
    :math:`z` it becomes

    .. math:: x = \\frac{(u - c_x)\\, z}{f_x}, \\qquad
              y = \\frac{(v - c_y)\\, z}{f_y}, \\qquad z = z,

    computed in float64 and stored as float32.  Keeping every ``N``-th row
    and column (``depth[::N, ::N]``) maps old pixel ``N u'`` to new pixel
    ``u'``, so the intrinsics of the smaller grid are exactly
    ``(fx / N, fy / N, cx / N, cy / N)`` under this convention.

    Examples
    --------
    >>> points, colors = depth_to_points([[2.0, np.nan]], (1.0, 1.0, 0.0, 0.0))
    >>> points
    array([[0., 0., 2.]], dtype=float32)
    """
    fx, fy, cx, cy = check_intrinsics(intrinsics, name=name)
    array = check_real_array(depth, "depth")
    if array.ndim != 2:
        raise ValueError(f"`depth` must be a 2-D (H, W) array, got shape {array.shape}.")
    values = array.astype(np.float64)
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(values) & (values > 0)
    colors = None if image is None else _as_colors(image, values.shape)
    rows, cols = np.nonzero(valid)
    z = values[rows, cols]
    with np.errstate(over="ignore"):
        xyz = ((cols - cx) * z / fx, (rows - cy) * z / fy, z)
    _check_float32_range(xyz, (fx, fy, cx, cy), values.shape, argument_label(name))
    points = np.empty((z.size, 3), dtype=np.float32)
    for axis, coordinate in enumerate(xyz):
        points[:, axis] = coordinate
    return points, None if colors is None else np.ascontiguousarray(colors[rows, cols])


def _check_float32_range(xyz, intrinsics, shape, label: str) -> None:
    """``ValueError`` naming the intrinsics (or the depth) if a coordinate is beyond the float32 range."""
    largest = [float(np.max(np.abs(c), initial=0.0)) for c in xyz]
    if all(value <= _FLOAT32_MAX for value in largest):
        return
    if largest[2] > _FLOAT32_MAX:
        raise ValueError(f"`depth` reaches {largest[2]:.4g}, beyond the float32 range of a point cloud "
                         f"({_FLOAT32_MAX:.4g}); give the depth in metres.")
    fx, fy, cx, cy = intrinsics
    axis = "x" if largest[0] > _FLOAT32_MAX else "y"
    raise ValueError(
        f"{label} (fx, fy, cx, cy) = ({fx:.6g}, {fy:.6g}, {cx:.6g}, {cy:.6g}) put the points of this "
        f"{shape[0]}x{shape[1]} (H x W) depth at |{axis}| up to {max(largest[:2]):.4g} m, beyond the float32 range "
        f"of a point cloud ({_FLOAT32_MAX:.4g}); focal lengths and principal point are in pixels of this grid "
        "(focal lengths of hundreds to thousands for common cameras).")


def _vertex_dtype(with_colors: bool) -> np.dtype:
    return np.dtype(list(_XYZ + _RGB) if with_colors else list(_XYZ))


def _header(count: int, with_colors: bool, fmt: str = "binary_little_endian") -> bytes:
    lines = ["ply", f"format {fmt} 1.0", f"comment {PLY_COMMENT}", f"element vertex {count}",
             "property float x", "property float y", "property float z"]
    if with_colors:
        lines += ["property uchar red", "property uchar green", "property uchar blue"]
    lines.append("end_header")
    return ("\n".join(lines) + "\n").encode("ascii")


def ply_writer(points, colors=None) -> Callable[[Path], None]:
    """Check and encode a point cloud as :func:`write_ply` does; return ``writer(tmp)``.

    Every check happens here, before anything is written; the returned
    function only writes the encoded bytes to the file it is given (the
    command line writes all its outputs together this way).
    """
    xyz = check_real_array(points, "points")
    if xyz.ndim != 2 or xyz.shape[1] != 3:
        raise ValueError(f"`points` must be an (N, 3) array of x, y, z, got shape {xyz.shape}.")
    if not np.all(np.isfinite(xyz)):
        raise ValueError("`points` has NaN or infinite coordinates; drop those points first.")
    vertices = np.empty(xyz.shape[0], dtype=_vertex_dtype(colors is not None))
    with np.errstate(over="raise"):
        try:
            for axis, (field, _) in enumerate(_XYZ):
                vertices[field] = xyz[:, axis]
        except FloatingPointError:
            raise ValueError("`points` has coordinates beyond the float32 range.") from None
    if colors is not None:
        rgb = check_real_array(colors, "colors")
        if rgb.shape != xyz.shape:
            raise ValueError(f"`colors` must be an (N, 3) array like `points` {xyz.shape}, got shape {rgb.shape}.")
        if rgb.dtype != np.uint8 and (rgb.min(initial=0) < 0 or rgb.max(initial=0) > 255
                                      or not np.array_equal(rgb, np.rint(rgb))):
            raise ValueError("`colors` must hold integers in [0, 255] (uint8 RGB).")
        for axis, (field, _) in enumerate(_RGB):
            vertices[field] = rgb[:, axis]
    data = _header(vertices.size, colors is not None) + vertices.tobytes()
    return lambda tmp: Path(tmp).write_bytes(data)


def write_ply(path, points, colors=None) -> None:
    """Write a point cloud as a binary little-endian PLY file (atomically).

    Parameters
    ----------
    path : str or os.PathLike
        Destination with extension ``.ply``; its folder must exist.
    points : (N, 3) array_like of real numbers
        ``x, y, z`` (metres), finite; stored as float32.
    colors : (N, 3) array_like of integers in [0, 255], optional
        RGB of each point, stored as uchar.

    Raises
    ------
    FileNotFoundError
        If the destination folder does not exist.
    ValueError
        If the extension is not ``.ply``, the shapes are wrong, a coordinate
        is not finite or a colour is out of range.
    TypeError
        If ``points`` or ``colors`` is not real-valued.

    Notes
    -----
    The header follows the PLY format of Turk (1994), line by line::

        ply
        format binary_little_endian 1.0
        comment sparsedepth point cloud: x y z in metres, camera frame (...)
        element vertex N
        property float x
        property float y
        property float z
        property uchar red
        property uchar green
        property uchar blue
        end_header

    (no colour lines without ``colors``), followed by ``N`` records of 15
    bytes (12 without colours), the NumPy dtype
    ``[('x', '<f4'), ('y', '<f4'), ('z', '<f4'), ('red', 'u1'), ('green', 'u1'), ('blue', 'u1')]``.
    The file appears only once complete (see :func:`atomic_target`).

    References
    ----------
    .. [1] G. Turk, "The PLY polygon file format", 1994.

    Examples
    --------
    >>> import tempfile, os
    >>> fname = os.path.join(tempfile.mkdtemp(), "cloud.ply")
    >>> write_ply(fname, [[0.0, 0.0, 1.0]], [[255, 0, 0]])
    >>> read_ply(fname)
    (array([[0., 0., 1.]], dtype=float32), array([[255,   0,   0]], dtype=uint8))
    """
    check_extension(Path(path), (".ply",), "write a point cloud to")
    writer = ply_writer(points, colors)
    with atomic_target(path) as tmp:
        writer(tmp)


def _parse_header(raw: bytes, where: str) -> tuple[str, int, bool, int]:
    """(format, vertex count, with colours, offset of the data) of a PLY header; ValueError naming what is found."""
    end = raw.find(b"end_header", 0, _MAX_HEADER_BYTES)
    if not raw.startswith((b"ply\n", b"ply\r\n")) or end < 0:
        raise ValueError(f"{where}: not a PLY file (expected a header from 'ply' to 'end_header', "
                         f"found {raw[:20]!r}).")
    newline = raw.find(b"\n", end)
    if newline < 0:
        raise ValueError(f"{where}: 'end_header' is not followed by a newline.")
    try:
        text = raw[:newline].decode("ascii")
    except UnicodeDecodeError:
        raise ValueError(f"{where}: the PLY header is not ASCII text.") from None
    fmt, count, properties = None, None, []
    for line in text.splitlines()[1:-1]:
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        if words[0] == "format" and fmt is None and len(words) == 3:
            if words[1] not in ("ascii", "binary_little_endian") or words[2] != "1.0":
                raise ValueError(f"{where}: PLY format '{' '.join(words[1:])}' is not read here; "
                                 "expected 'ascii 1.0' or 'binary_little_endian 1.0'.")
            fmt = words[1]
        elif words[0] == "element" and count is None and len(words) == 3 and words[1] == "vertex":
            if not words[2].isdigit():
                raise ValueError(f"{where}: 'element vertex' count is not a number: {words[2]!r}.")
            count = int(words[2])
        elif words[0] == "element":
            raise ValueError(f"{where}: found '{line.strip()}'; only one 'element vertex' (a point cloud, "
                             "no faces or other elements) is read here.")
        elif words[0] == "property" and count is not None:
            properties.append(" ".join(words[1:]))
        else:
            raise ValueError(f"{where}: unexpected PLY header line '{line.strip()}'.")
    if fmt is None or count is None:
        raise ValueError(f"{where}: the PLY header lacks a 'format' or an 'element vertex' line.")
    types = [p.split() for p in properties]
    names = tuple(t[-1] for t in types)
    xyz_ok = len(types) >= 3 and all(len(t) == 2 and t[0] in _FLOAT_NAMES for t in types[:3])
    rgb_ok = len(types) == 6 and all(len(t) == 2 and t[0] in _UCHAR_NAMES for t in types[3:])
    if names == ("x", "y", "z") and xyz_ok:
        with_colors = False
    elif names == ("x", "y", "z", "red", "green", "blue") and xyz_ok and rgb_ok:
        with_colors = True
    else:
        raise ValueError(f"{where}: vertex properties [{', '.join(properties)}] are not read here; expected "
                         "float x, y, z optionally followed by uchar red, green, blue.")
    return fmt, count, with_colors, newline + 1


def _ascii_vertices(body: bytes, count: int, width: int, where: str) -> np.ndarray:
    rows = body.decode("ascii", errors="replace").split("\n")
    rows = [r.split() for r in rows if r.strip()]
    if len(rows) != count or any(len(r) != width for r in rows):
        raise ValueError(f"{where}: expected {count} vertex line(s) of {width} numbers after the header, found "
                         f"{len(rows)} line(s)" + ("" if len(rows) != count else " of other lengths") + ".")
    try:
        return np.array(rows, dtype=np.float64).reshape(count, width)
    except ValueError:
        raise ValueError(f"{where}: a vertex line holds something that is not a number.") from None


def read_ply(path, *, name: str = "path") -> tuple[np.ndarray, np.ndarray | None]:
    """Read a vertex-only PLY point cloud as :func:`write_ply` writes it.

    Parameters
    ----------
    path : str or os.PathLike
        A PLY file in ``binary_little_endian 1.0`` or ``ascii 1.0`` format
        holding one ``element vertex`` with properties ``float x``,
        ``float y``, ``float z`` and optionally ``uchar red``,
        ``uchar green``, ``uchar blue`` in that order (``float32`` and
        ``uint8`` are accepted as type names too); ``comment`` and
        ``obj_info`` lines are skipped.
    name : str, optional
        Label of ``path`` in error messages.

    Returns
    -------
    points : (N, 3) ndarray of float32
    colors : (N, 3) ndarray of uint8 or None
        None when the file has no colour properties.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If it is not a regular file or not such a PLY file (another format,
        other elements such as faces, other properties, a data section
        shorter or longer than the header declares, colours outside
        [0, 255]); the message names what was found.
    """
    path = check_input_file(path, name=name)
    where = file_label(path, name)
    raw = read_bytes(path, where)
    fmt, count, with_colors, offset = _parse_header(raw, where)
    dtype = _vertex_dtype(with_colors)
    body = raw[offset:]
    if fmt == "binary_little_endian":
        if len(body) != count * dtype.itemsize:
            raise ValueError(f"{where}: the header declares {count} vertices of {dtype.itemsize} bytes "
                             f"({count * dtype.itemsize} bytes) but {len(body)} bytes follow it.")
        vertices = np.frombuffer(body, dtype=dtype, count=count)
        points = np.stack([vertices[f] for f, _ in _XYZ], axis=1).astype(np.float32)
        colors = np.stack([vertices[f] for f, _ in _RGB], axis=1) if with_colors else None
        return points, colors
    table = _ascii_vertices(body, count, dtype.names.__len__(), where)
    points = table[:, :3].astype(np.float32)
    if not with_colors:
        return points, None
    rgb = table[:, 3:]
    if np.any(rgb < 0) or np.any(rgb > 255) or not np.array_equal(rgb, np.rint(rgb)):
        raise ValueError(f"{where}: colours must be integers in [0, 255] (uchar).")
    return points, rgb.astype(np.uint8)
