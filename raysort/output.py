"""Writing rendered images to disk.

Two formats are supported:

* OpenEXR (``.exr``): linear RGB as three 32-bit FLOAT channels ``R``, ``G``,
  ``B``, scanline, ZIP compression, written with the ``OpenEXR`` package
  (>= 3.3, the ``OpenEXR.File`` API).  Values are stored bit-exactly.
* PNG (``.png``): an 8-bit sRGB preview, tone mapped by exposure, clamping and
  the sRGB transfer function, encoded by hand with :mod:`zlib` and
  :mod:`struct` (no image library needed).

Both writers are atomic: the image goes to a temporary file in the target's
directory which is then renamed onto the target, so a failure or an interrupt
never leaves a half-written file and never damages an existing one.  Problems
with the output path raise :class:`~raysort.errors.OutputError` with a
one-line message; :func:`check_writable` performs the same checks up front, so
a renderer can fail before it spends minutes rendering.

The readers :func:`read_exr` and :func:`read_png` exist for tests and tools.
"""

import contextlib
import io
import os
import struct
import tempfile
import zlib

import numpy as np

from raysort.errors import OutputError

__all__ = [
    "write_image",
    "write_exr",
    "read_exr",
    "read_exr_channels",
    "write_png",
    "read_png",
    "check_writable",
    "atomic_target",
    "write_json",
    "tone_map",
    "SUPPORTED_SUFFIXES",
]

SUPPORTED_SUFFIXES = (".exr", ".png")

_EXR_MAGIC = b"\x76\x2f\x31\x01"
_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_IDAT_SIZE = 1 << 20  # bytes of compressed data per IDAT chunk

# Header attributes that describe the file's structure; metadata must not
# replace them.
_RESERVED_EXR_ATTRIBUTES = frozenset({
    "channels", "compression", "dataWindow", "displayWindow", "lineOrder",
    "pixelAspectRatio", "screenWindowCenter", "screenWindowWidth", "type",
    "name", "tiles", "version", "chunkCount", "maxSamplesPerPixel",
})
_MAX_EXR_NAME = 255  # longer attribute names are silently truncated by OpenEXR


# --------------------------------------------------------------------------
# Paths and atomic writes
# --------------------------------------------------------------------------

def _q(path):
    """Quote a path for a message."""
    return repr(os.fspath(path))


def _path_problem(path):
    """Return why `path` cannot be written, or None if it looks writable."""
    path = os.fspath(path)
    if not path:
        return "the path is empty"
    if os.path.isdir(path):
        return "it is a directory"
    parent = os.path.dirname(path) or os.curdir
    if not os.path.exists(parent):
        blocker = _first_non_directory(parent)
        if blocker is not None:
            return f"{_q(blocker)} is not a directory"
        return f"directory {_q(parent)} does not exist"
    if not os.path.isdir(parent):
        return f"{_q(parent)} is not a directory"
    if not os.access(parent, os.W_OK | os.X_OK):
        return f"directory {_q(parent)} is not writable"
    return None


def _first_non_directory(path):
    """Return the deepest existing ancestor of `path` if it is not a directory."""
    while path and not os.path.exists(path):
        head = os.path.dirname(path)
        if head == path:
            return None
        path = head
    if path and not os.path.isdir(path):
        return path
    return None


def check_writable(path):
    """Check that an image can be written to `path`, without creating anything.

    Parameters
    ----------
    path : str or os.PathLike
        The output file.

    Raises
    ------
    OutputError
        If the parent directory is missing, is not a directory or is not
        writable, or if `path` is a directory.
    """
    problem = _path_problem(path)
    if problem is not None:
        raise OutputError(f"cannot write {_q(path)}: {problem}")


def _file_mode():
    """Permission bits of a newly created file (0o666 minus the umask)."""
    try:
        with open("/proc/self/status") as status:
            for line in status:
                if line.startswith("Umask:"):
                    return 0o666 & ~int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    umask = os.umask(0o022)
    os.umask(umask)
    return 0o666 & ~umask


def _fsync(path):
    """Flush `path` (a file or directory) to disk; best effort for directories."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


@contextlib.contextmanager
def atomic_target(path):
    """Yield a temporary file name next to `path`; rename it onto `path` on success.

    The temporary file is created in the same directory as `path` (so the
    final :func:`os.replace` is atomic) and is removed if the body raises
    anything, including :class:`KeyboardInterrupt`; `path` is then untouched.

    Parameters
    ----------
    path : str or os.PathLike
        The final output file.

    Yields
    ------
    str
        Name of the temporary file to write the complete output to.

    Raises
    ------
    OutputError
        If `path` cannot be written or an operating-system call fails.
    """
    check_writable(path)
    path = os.fspath(path)
    directory, name = os.path.split(path)
    try:
        fd, tmp = tempfile.mkstemp(dir=directory or os.curdir,
                                   prefix="." + name + ".", suffix=".tmp")
    except OSError as exc:
        raise OutputError(
            f"cannot write {_q(path)}: {exc.strerror or exc}") from exc
    try:
        os.close(fd)
        yield tmp
        os.chmod(tmp, _file_mode())
        _fsync(tmp)
        os.replace(tmp, path)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if isinstance(exc, OSError):
            raise OutputError(
                f"cannot write {_q(path)}: {exc.strerror or exc}") from exc
        raise
    with contextlib.suppress(OSError):
        _fsync(directory or os.curdir)


# --------------------------------------------------------------------------
# Image validation
# --------------------------------------------------------------------------

def _as_rgb_float32(image):
    """Return `image` as a C-contiguous float32 (H, W, 3) array.

    Raises
    ------
    ValueError
        If `image` is not a non-empty float32 or float64 (H, W, 3) array.
    """
    image = np.asarray(image)
    if image.ndim != 3 or image.shape[2] != 3 or 0 in image.shape:
        raise ValueError(f"image must have shape (H, W, 3) with H, W >= 1, "
                         f"got shape {image.shape}")
    if image.dtype not in (np.float32, np.float64):
        raise ValueError(f"image must be float32 or float64, got {image.dtype} "
                         f"(shape {image.shape})")
    return np.ascontiguousarray(image, dtype=np.float32)


# --------------------------------------------------------------------------
# OpenEXR
# --------------------------------------------------------------------------

def _openexr():
    """Import the OpenEXR package, with a clear error if it is missing."""
    try:
        import OpenEXR
    except ImportError as exc:
        raise OutputError("cannot write EXR files: the 'OpenEXR' package "
                          "(>= 3.3) is not installed") from exc
    if not hasattr(OpenEXR, "File"):
        raise OutputError("cannot write EXR files: the 'OpenEXR' package is "
                          "too old (need >= 3.3 with OpenEXR.File)")
    return OpenEXR


def _check_metadata(metadata):
    """Validate EXR metadata: a dict of str -> str with usable names."""
    if not isinstance(metadata, dict):
        raise TypeError(f"metadata must be a dict of str -> str, "
                        f"got {type(metadata).__name__}")
    for key, value in metadata.items():
        if not isinstance(key, str) or not isinstance(value, str):
            raise TypeError(f"metadata must map str -> str, got "
                            f"{type(key).__name__} {key!r} -> "
                            f"{type(value).__name__}")
        if not key or "\0" in key or len(key) > _MAX_EXR_NAME:
            raise ValueError(f"invalid EXR attribute name {key!r}: it must be "
                             f"1 to {_MAX_EXR_NAME} characters without NUL")
        if key in _RESERVED_EXR_ATTRIBUTES:
            raise ValueError(f"metadata must not set the EXR attribute {key!r}")


def _exr_header(OpenEXR, metadata):
    """Build the EXR header dict and verify that OpenEXR accepts it.

    OpenEXR only checks attribute types when writing (e.g. a string for the
    standard attribute 'chromaticities' fails then), so the header is tried
    on a 1x1 image in memory before any file is created.
    """
    metadata = {} if metadata is None else metadata
    _check_metadata(metadata)
    header = {"compression": OpenEXR.ZIP_COMPRESSION,
              "type": OpenEXR.scanlineimage}
    header.update(metadata)
    pixel = np.zeros((1, 1), dtype=np.float32)
    try:
        OpenEXR.File(dict(header), {"R": pixel}).write(io.BytesIO())
    except (RuntimeError, ValueError, TypeError) as exc:
        raise ValueError(f"OpenEXR rejects the metadata: {exc}") from exc
    return header


def _exr_file(OpenEXR, image, header, extra=None):
    """Build an OpenEXR.File with FLOAT channels R, G, B of `image`, plus `extra`."""
    # OpenEXR ignores numpy strides: each channel must be its own
    # C-contiguous array (a view like image[..., 0] is written garbled).
    channels = {name: np.ascontiguousarray(image[..., i])
                for i, name in enumerate("RGB")}
    channels.update(extra or {})
    return OpenEXR.File(header, channels)


def _check_channels(channels, size):
    """Extra EXR channels as {name: C-contiguous (H, W) float32 or uint32 array}."""
    if not isinstance(channels, dict):
        raise TypeError(f"channels must be a dict of name -> array, "
                        f"got {type(channels).__name__}")
    out = {}
    for name, data in channels.items():
        if not isinstance(name, str) or not name or "\0" in name or name in ("R", "G", "B"):
            raise ValueError(f"invalid extra EXR channel name {name!r}")
        data = np.asarray(data)
        if data.shape != size:
            raise ValueError(f"channel {name!r} has shape {data.shape}, the image {size}")
        if data.dtype == np.float64:
            data = data.astype(np.float32)
        if data.dtype not in (np.float32, np.uint32):
            raise ValueError(f"channel {name!r} must be float32 (FLOAT) or uint32 (UINT), "
                             f"got {data.dtype}")
        out[name] = np.ascontiguousarray(data)
    return out


def write_exr(path, image, *, metadata=None, channels=None):
    """Write a linear RGB image as an OpenEXR file, atomically.

    Parameters
    ----------
    path : str or os.PathLike
        The output file.
    image : numpy.ndarray
        float32 or float64 array of shape (H, W, 3); stored as float32.
    metadata : dict of str -> str, optional
        Extra string attributes for the EXR header (e.g. version, settings).
    channels : dict of str -> numpy.ndarray, optional
        Extra channels next to R, G, B, e.g. AOV layers (``"depth.Z"``,
        ``"normal.X"``): (H, W) arrays, float32 (FLOAT) or uint32 (UINT).

    Raises
    ------
    ValueError
        If `image` has a wrong shape or dtype, or `metadata` or `channels` is
        not accepted.
    TypeError
        If `metadata` is not a dict of str -> str.
    OutputError
        If the file cannot be written.
    """
    image = _as_rgb_float32(image)
    extra = _check_channels(channels or {}, image.shape[:2])
    OpenEXR = _openexr()
    exr = _exr_file(OpenEXR, image, _exr_header(OpenEXR, metadata), extra)
    with atomic_target(path) as tmp:
        _write_exr_file(exr, tmp, path)


def _write_exr_file(exr, tmp, path):
    """Write `exr` to the file `tmp`; errors name the final `path`."""
    try:
        exr.write(tmp)
    except RuntimeError as exc:
        raise OutputError(f"cannot write {_q(path)}: OpenEXR: {exc}") from exc


def _check_readable(path, magic, kind):
    """Raise OutputError unless `path` is a file starting with `magic`."""
    if os.path.isdir(path):
        raise OutputError(f"cannot read {_q(path)}: it is a directory")
    try:
        with open(path, "rb") as file:
            head = file.read(len(magic))
    except FileNotFoundError:
        raise OutputError(f"cannot read {_q(path)}: file does not exist") from None
    except OSError as exc:
        raise OutputError(f"cannot read {_q(path)}: {exc.strerror or exc}") from exc
    if head != magic:
        raise OutputError(f"cannot read {_q(path)}: not {kind} file")


def read_exr(path):
    """Read the R, G, B channels of an OpenEXR file.

    Parameters
    ----------
    path : str or os.PathLike
        The EXR file.

    Returns
    -------
    numpy.ndarray
        float32 array of shape (H, W, 3).

    Raises
    ------
    OutputError
        If the file is missing, is not a readable EXR file or lacks R, G or B.
    """
    channels = read_exr_channels(path)
    missing = [name for name in "RGB" if name not in channels]
    if missing:
        raise OutputError(f"cannot read {_q(path)}: no channel(s) "
                          f"{', '.join(missing)} (has {', '.join(sorted(channels))})")
    return np.stack([np.asarray(channels[name], dtype=np.float32)
                     for name in "RGB"], axis=-1)


def read_exr_channels(path):
    """Read every channel of an OpenEXR file: {name: (H, W) array} in the
    stored type (float32 for FLOAT, float16 for HALF, uint32 for UINT).

    Raises
    ------
    OutputError
        If the file is missing or is not a readable EXR file.
    """
    _check_readable(path, _EXR_MAGIC, "an OpenEXR")
    OpenEXR = _openexr()
    try:
        channels = OpenEXR.File(os.fspath(path), separate_channels=True).channels()
    except (RuntimeError, ValueError) as exc:
        raise OutputError(f"cannot read {_q(path)}: OpenEXR: {exc}") from exc
    return {name: np.asarray(channel.pixels) for name, channel in channels.items()}


# --------------------------------------------------------------------------
# PNG
# --------------------------------------------------------------------------

def _srgb_encode(linear):
    """Apply the sRGB transfer function to values in [0, 1]."""
    return np.where(linear <= 0.0031308,
                    12.92 * linear,
                    1.055 * np.power(linear, 1.0 / 2.4) - 0.055)


def tone_map(image, exposure=0.0):
    """Map linear RGB to 8-bit sRGB.

    Multiplies by ``2**exposure``, clamps to [0, 1] (NaN becomes 0), applies
    the sRGB transfer function and rounds to the nearest integer.

    Parameters
    ----------
    image : numpy.ndarray
        Linear RGB values, any shape.
    exposure : float
        Exposure adjustment in stops.

    Returns
    -------
    numpy.ndarray
        uint8 array of the same shape.
    """
    exposure = float(exposure)
    if not np.isfinite(exposure):
        raise ValueError(f"exposure must be finite, got {exposure}")
    linear = np.asarray(image, dtype=np.float64) * 2.0 ** exposure
    linear = np.clip(np.nan_to_num(linear, nan=0.0), 0.0, 1.0)
    return np.rint(_srgb_encode(linear) * 255.0).astype(np.uint8)


def _png_chunk(kind, data):
    """Return one PNG chunk: length, type, data and CRC."""
    return (struct.pack(">I", len(data)) + kind + data
            + struct.pack(">I", zlib.crc32(kind + data)))


def _encode_png(rgb):
    """Encode a uint8 (H, W, 3) array as an 8-bit RGB PNG (filter 0)."""
    height, width, _ = rgb.shape
    rows = np.zeros((height, 1 + 3 * width), dtype=np.uint8)  # filter byte 0
    rows[:, 1:] = rgb.reshape(height, 3 * width)
    compressed = zlib.compress(rows.tobytes(), 6)
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    idats = [_png_chunk(b"IDAT", compressed[i:i + _IDAT_SIZE])
             for i in range(0, len(compressed), _IDAT_SIZE)]
    return b"".join([_PNG_SIGNATURE, _png_chunk(b"IHDR", ihdr), *idats,
                     _png_chunk(b"IEND", b"")])


def _write_bytes(path, data):
    """Write `data` to the file `path`."""
    with open(path, "wb") as file:
        file.write(data)


def write_png(path, image, *, exposure=0.0):
    """Write a tone-mapped 8-bit sRGB PNG preview of a linear image, atomically.

    Parameters
    ----------
    path : str or os.PathLike
        The output file.
    image : numpy.ndarray
        float32 or float64 linear RGB array of shape (H, W, 3).
    exposure : float
        Exposure adjustment in stops: values are multiplied by
        ``2**exposure`` before clamping to [0, 1].

    Raises
    ------
    ValueError
        If `image` has a wrong shape or dtype or `exposure` is not finite.
    OutputError
        If the file cannot be written.
    """
    data = _encode_png(tone_map(_as_rgb_float32(image), exposure))
    with atomic_target(path) as tmp:
        _write_bytes(tmp, data)


def _png_chunks(data, path):
    """Yield (type, payload) of each chunk after the signature, checking CRCs."""
    pos = len(_PNG_SIGNATURE)
    while pos < len(data):
        if pos + 8 > len(data):
            raise OutputError(f"cannot read {_q(path)}: truncated PNG chunk")
        length, kind = struct.unpack(">I4s", data[pos:pos + 8])
        end = pos + 8 + length
        if end + 4 > len(data):
            raise OutputError(f"cannot read {_q(path)}: truncated PNG chunk "
                              f"{kind!r}")
        payload = data[pos + 8:end]
        (crc,) = struct.unpack(">I", data[end:end + 4])
        if crc != zlib.crc32(kind + payload):
            raise OutputError(f"cannot read {_q(path)}: bad CRC in PNG "
                              f"chunk {kind!r}")
        yield kind, payload
        pos = end + 4


def _parse_ihdr(payload, path):
    """Return (width, height) from an IHDR payload of a supported PNG."""
    if len(payload) != 13:
        raise OutputError(f"cannot read {_q(path)}: bad PNG IHDR chunk")
    width, height, depth, color, comp, filt, interlace = struct.unpack(
        ">IIBBBBB", payload)
    if (depth, color, comp, filt, interlace) != (8, 2, 0, 0, 0) or not (
            width and height):
        raise OutputError(f"cannot read {_q(path)}: unsupported PNG (only "
                          f"non-interlaced 8-bit RGB is read)")
    return width, height


def _decode_png(data, path):
    """Decode the bytes of a PNG as written by write_png."""
    if not data.startswith(_PNG_SIGNATURE):
        raise OutputError(f"cannot read {_q(path)}: not a PNG file")
    size, idat, ended = None, [], False
    for kind, payload in _png_chunks(data, path):
        if size is None and kind != b"IHDR":
            raise OutputError(f"cannot read {_q(path)}: PNG does not start "
                              f"with IHDR")
        if kind == b"IHDR":
            size = _parse_ihdr(payload, path)
        elif kind == b"IDAT":
            idat.append(payload)
        elif kind == b"IEND":
            ended = True
            break
    if not ended:
        raise OutputError(f"cannot read {_q(path)}: PNG has no IEND chunk")
    return _unfilter(b"".join(idat), size, path)


def _unfilter(compressed, size, path):
    """Decompress PNG image data with filter type 0 into (H, W, 3) uint8."""
    width, height = size
    try:
        raw = zlib.decompress(compressed)
    except zlib.error as exc:
        raise OutputError(f"cannot read {_q(path)}: bad PNG data: {exc}") from exc
    if len(raw) != height * (1 + 3 * width):
        raise OutputError(f"cannot read {_q(path)}: PNG data has {len(raw)} "
                          f"bytes, expected {height * (1 + 3 * width)}")
    rows = np.frombuffer(raw, dtype=np.uint8).reshape(height, 1 + 3 * width)
    if rows[:, 0].any():
        raise OutputError(f"cannot read {_q(path)}: unsupported PNG row "
                          f"filter (only filter type 0 is read)")
    return rows[:, 1:].reshape(height, width, 3).copy()


def read_png(path):
    """Read an 8-bit RGB PNG as written by :func:`write_png`.

    Verifies the signature and every chunk's CRC; supports only
    non-interlaced 8-bit RGB with row filter type 0.

    Parameters
    ----------
    path : str or os.PathLike
        The PNG file.

    Returns
    -------
    numpy.ndarray
        uint8 array of shape (H, W, 3).

    Raises
    ------
    OutputError
        If the file is missing, corrupt or not a supported PNG.
    """
    _check_readable(path, _PNG_SIGNATURE, "a PNG")
    try:
        with open(path, "rb") as file:
            data = file.read()
    except OSError as exc:
        raise OutputError(f"cannot read {_q(path)}: {exc.strerror or exc}") from exc
    return _decode_png(data, path)


# --------------------------------------------------------------------------
# Dispatch
# --------------------------------------------------------------------------

_WRITERS = {".exr": write_exr, ".png": write_png}


def write_image(path, image, **kw):
    """Write `image` in the format given by the suffix of `path`.

    Parameters
    ----------
    path : str or os.PathLike
        The output file; its suffix (``.exr`` or ``.png``, any case) selects
        :func:`write_exr` or :func:`write_png`.
    image : numpy.ndarray
        float32 or float64 linear RGB array of shape (H, W, 3).
    **kw
        Keyword arguments of the selected writer (``metadata`` or
        ``exposure``).

    Raises
    ------
    OutputError
        If the suffix is not supported or the file cannot be written.
    """
    suffix = os.path.splitext(os.fspath(path))[1].lower()
    writer = _WRITERS.get(suffix)
    if writer is None:
        raise OutputError(f"cannot write {_q(path)}: unsupported file type "
                          f"{suffix or '(no suffix)'!r}; supported: "
                          f"{', '.join(SUPPORTED_SUFFIXES)}")
    writer(path, image, **kw)


def write_json(path, data):
    """Write ``data`` as indented JSON, atomically like the image writers."""
    import json

    with atomic_target(path) as tmp:
        with open(tmp, "w", encoding="utf-8") as fh:
            json.dump(data, fh, indent=2, default=str)
            fh.write("\n")
