"""Writing rendered images to disk.

Two formats are supported:

* OpenEXR (``.exr``): linear RGB as three 32-bit FLOAT channels ``R``, ``G``,
  ``B``, scanline, ZIP compression, written with the ``OpenEXR`` package
  (>= 3.3, the ``OpenEXR.File`` API).  Values are stored bit-exactly.
* PNG (``.png``): an 8-bit sRGB preview, tone mapped by exposure, clamping and
  the sRGB transfer function, encoded with Pillow.  Tone mapping runs over
  blocks of rows, so writing a preview needs little more memory than Pillow's
  own copy of the 8-bit picture.

Every writer is atomic: the image goes to a temporary file in the target's
directory which is then renamed onto the target, so a failure or an interrupt
never leaves a half-written file and never damages an existing one.
:func:`write_render` writes an EXR and its PNG preview as one pair: both
temporaries are written first, then renamed in a fixed order while holding a
lock on the directory, and both carry the same ``raysort.render_id`` (a digest
of pixels, metadata and exposure), so two
processes writing the same path never leave one's EXR next to the other's PNG.
Problems with the output path raise :class:`~raysort.errors.OutputError`
with a one-line message; :func:`check_writable` performs the same checks up
front (it creates and removes a probe file), so a renderer can fail before it
spends minutes rendering.

The readers :func:`read_exr` and :func:`read_png` exist for tests and tools.
"""

import contextlib
import hashlib
import io
import os
import tempfile

import numpy as np

from raysort.errors import ConfigError, OutputError

try:
    import fcntl
except ImportError:  # Windows: pairs are renamed without a lock
    fcntl = None

__all__ = [
    "shown",
    "write_image",
    "write_render",
    "write_exr",
    "read_exr",
    "read_exr_channels",
    "write_png",
    "png_bytes",
    "read_png",
    "check_writable",
    "make_parents",
    "remove_parents",
    "atomic_target",
    "write_json",
    "json_text",
    "tone_map",
    "SUPPORTED_SUFFIXES",
]

SUPPORTED_SUFFIXES = (".exr", ".png")

_EXR_MAGIC = b"\x76\x2f\x31\x01"
_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
#: float32 values tone mapped per block: a block's float64 temporaries stay a
#: few MiB whatever the image size
_TONE_MAP_BLOCK = 1 << 18

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


def _path_problem(path, parents=False, probe=True):
    """Return why `path` cannot be written, or None if it looks writable.

    With `parents`, a missing parent directory is no problem as long as its
    deepest existing ancestor is a directory.  With `probe`, a file is
    created and removed in the directory to be sure.
    """
    path = _final(path)
    if not path:
        return "the path is empty"
    if os.path.isdir(path):
        return "it is a directory"
    if path.endswith(os.sep) or os.altsep and path.endswith(os.altsep):
        return "it names a directory, not a file"
    if _special(path):      # written through (atomic_target), as a shell's > does
        return None if os.access(path, os.W_OK) else "it is not writable"
    parent = os.path.dirname(path) or os.curdir
    if not os.path.exists(parent):
        blocker = _first_non_directory(parent)
        if blocker is not None:
            return f"{_q(blocker)} is not a directory"
        if not parents:
            return f"directory {_q(parent)} does not exist"
        parent = _deepest_existing(parent)
    if not os.path.isdir(parent):
        return f"{_q(parent)} is not a directory"
    if not os.access(parent, os.W_OK | os.X_OK):
        return f"directory {_q(parent)} is not writable"
    return _probe(parent, os.path.basename(path)) if probe else None


def _final(path):
    """The file a write to `path` ends in: the target of a symbolic link (written
    through, not replaced), else `path` itself."""
    path = os.fspath(path)
    return os.path.realpath(path) if path and os.path.islink(path) else path


def _special(path):
    """Whether `path` exists and is neither a regular file nor a directory (a device
    such as /dev/null, a pipe)."""
    return os.path.exists(path) and not os.path.isfile(path) and not os.path.isdir(path)


def _deepest_existing(path):
    """The deepest ancestor of `path` (or `path` itself) that exists."""
    while path and not os.path.exists(path):
        head = os.path.dirname(path)
        if head == path:
            break
        path = head
    return path or os.curdir


def _first_non_directory(path):
    """Return the deepest existing ancestor of `path` if it is not a directory."""
    path = _deepest_existing(path)
    if os.path.exists(path) and not os.path.isdir(path):
        return path
    return None


def _probe(directory, name):
    """Create and remove a file in `directory`; return why that fails, or None.

    Permission bits do not tell everything: root may write anywhere they say
    no, and file systems such as /proc or a read-only mount refuse whatever
    they say.
    """
    try:
        fd, probe = tempfile.mkstemp(dir=directory, prefix="." + name + ".",
                                     suffix=".probe")
    except OSError as exc:
        return f"cannot create a file in {_q(directory)}: {exc.strerror or exc}"
    os.close(fd)
    with contextlib.suppress(OSError):
        os.unlink(probe)
    return None


def check_writable(path, *, parents=False):
    """Check that an image can be written to `path`, leaving nothing behind.

    A probe file is created and removed in the target directory, so a
    directory that only looks writable (``/proc``, a read-only mount) fails
    here rather than after a render.

    Parameters
    ----------
    path : str or os.PathLike
        The output file.
    parents : bool
        Accept a missing parent directory if it can be created (see
        :func:`make_parents`); the probe then runs in its deepest existing
        ancestor.

    Raises
    ------
    OutputError
        If the parent directory is missing (unless `parents`), is not a
        directory or is not writable, or if `path` is a directory.
    """
    problem = _path_problem(path, parents)
    if problem is not None:
        raise OutputError(f"cannot write {_q(path)}: {problem}")


def shown(text):
    """``text`` as any output takes it (a terminal, a CSV, EXR metadata, a chart): the
    bytes of a file name that are not UTF-8, which POSIX allows and Python holds as
    lone surrogates (as in ``sys.argv``), become ``\\xNN`` escapes."""
    try:
        raw = text.encode("utf-8", "surrogateescape")
    except UnicodeEncodeError:                   # a lone surrogate of no byte
        raw = text.encode("utf-8", "backslashreplace")
    return raw.decode("utf-8", "backslashreplace")


def check_distinct(outputs, inputs=()):
    """ConfigError if two of a command's outputs are one file, or an output is one of the
    files it reads: each output an ``(option, what, path)`` (a path None or empty is not
    written), each input a ``(what, path)``.  The message names the later output's option
    and the other's ``what``: ``--csv 's.json' is the results file 's.json'``."""
    seen = {os.path.realpath(p): (what, p) for what, p in inputs if p and os.path.isfile(p)}
    for option, what, path in outputs:
        if not path:
            continue
        key = os.path.realpath(path)
        if key in seen:
            other, known = seen[key]
            raise ConfigError(f"{option} {path!r} is {other} {known!r}; give it another name")
        seen[key] = (what, path)


def make_parents(path):
    """Create the missing parent directories of `path`.

    Returns
    -------
    str or None
        The outermost directory created, or None if the parent existed.

    Raises
    ------
    OutputError
        If a directory cannot be created.
    """
    parent = os.path.dirname(os.fspath(path))
    if not parent or os.path.isdir(parent):
        return None
    created = parent
    while os.path.dirname(created) and not os.path.exists(os.path.dirname(created)):
        created = os.path.dirname(created)
    try:
        os.makedirs(parent, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot write {_q(path)}: cannot create directory "
                          f"{_q(parent)}: {exc.strerror or exc}") from exc
    return created


def remove_parents(path, created):
    """Undo :func:`make_parents`: remove the directories from `path`'s parent up to
    `created` (what it returned; None: nothing) while they are empty."""
    if created is None:
        return
    parent, top = os.path.dirname(os.fspath(path)), os.path.normpath(created)
    while parent:
        try:
            os.rmdir(parent)
        except OSError:
            return
        if os.path.normpath(parent) == top:
            return
        parent = os.path.dirname(parent)


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


def _os_error(path, exc):
    return OutputError(f"cannot write {_q(path)}: {exc.strerror or exc}")


@contextlib.contextmanager
def _temporary(path):
    """Yield a complete, flushed temporary file next to `path` (see atomic_target).

    The body writes the file; afterwards it gets the usual permission bits
    and is flushed to disk.  It is removed if anything raises, including
    after the body (the caller renames it).
    """
    problem = _path_problem(path, probe=False)  # mkstemp below is the probe
    if problem is not None:
        raise OutputError(f"cannot write {_q(path)}: {problem}")
    path = _final(path)
    directory, name = os.path.split(path)
    try:
        fd, tmp = tempfile.mkstemp(dir=directory or os.curdir,
                                   prefix="." + name + ".", suffix=".tmp")
    except OSError as exc:
        raise _os_error(path, exc) from exc
    try:
        os.close(fd)
        yield tmp
    except BaseException as exc:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if isinstance(exc, OSError):
            raise _os_error(path, exc) from exc
        raise


def _finish(tmp, path):
    """Give the temporary file its final mode and flush it to disk."""
    try:
        os.chmod(tmp, _file_mode())
        _fsync(tmp)
    except OSError as exc:
        raise _os_error(path, exc) from exc


def _rename(tmp, path):
    try:
        os.replace(tmp, path)
    except OSError as exc:
        raise _os_error(path, exc) from exc


@contextlib.contextmanager
def _directory_lock(directory):
    """Hold an exclusive advisory lock on `directory` (no lock file is left)."""
    if fcntl is None:
        yield
        return
    fd = os.open(directory or os.curdir, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # closing releases the lock


@contextlib.contextmanager
def atomic_target(path):
    """Yield a temporary file name next to `path`; rename it onto `path` on success.

    The temporary file is created in the same directory as `path` (so the
    final :func:`os.replace` is atomic) and is removed if the body raises
    anything, including :class:`KeyboardInterrupt`; `path` is then untouched.
    A symbolic link is written through (its target is replaced, the link kept);
    a device or a pipe (``/dev/null``) is written to directly.

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
    if _special(_final(path)):     # no file to replace: the output goes straight in
        try:
            yield _final(path)
        except OSError as exc:
            raise _os_error(path, exc) from exc
        return
    with _temporary(path) as tmp:
        yield tmp
        _finish(tmp, path)
        _rename(tmp, _final(path))
    with contextlib.suppress(OSError):
        _fsync(os.path.dirname(_final(path)) or os.curdir)


# --------------------------------------------------------------------------
# Image validation
# --------------------------------------------------------------------------

def _rgb(image):
    """Return `image` as an array after checking it is a float (H, W, 3) image.

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
    return image


def _as_rgb_float32(image):
    """Return `image` as a checked, C-contiguous float32 (H, W, 3) array."""
    return np.ascontiguousarray(_rgb(image), dtype=np.float32)


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
    exr = _prepared_exr(image, metadata, channels)
    with atomic_target(path) as tmp:
        _write_exr_file(exr, tmp, path)


def _prepared_exr(image, metadata, channels=None):
    """An OpenEXR.File of `image` with `metadata` and extra `channels`, checked before
    any file exists."""
    image = _as_rgb_float32(image)
    extra = _check_channels(channels or {}, image.shape[:2])
    OpenEXR = _openexr()
    return _exr_file(OpenEXR, image, _exr_header(OpenEXR, metadata), extra)


def _write_exr_file(exr, tmp, path):
    """Write `exr` to the file `tmp`; errors name the final `path`."""
    try:
        if _utf8(tmp):
            exr.write(tmp)
        else:       # OpenEXR takes only UTF-8 names; a file object any the OS has
            with open(tmp, "wb") as stream:
                exr.write(stream)
    except RuntimeError as exc:
        raise OutputError(f"cannot write {_q(path)}: OpenEXR: {exc}") from exc


def _utf8(path):
    """Whether the name `path` is valid UTF-8 (a POSIX name need not be)."""
    try:
        os.fspath(path).encode("utf-8")
    except UnicodeEncodeError:
        return False
    return True


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
        if _utf8(path):
            channels = OpenEXR.File(os.fspath(path), separate_channels=True).channels()
        else:       # OpenEXR takes only UTF-8 names; a file object any the OS has
            with open(path, "rb") as stream:
                channels = OpenEXR.File(stream, separate_channels=True).channels()
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


def _check_exposure(exposure):
    exposure = float(exposure)
    if not np.isfinite(exposure):
        raise ValueError(f"exposure must be finite, got {exposure}")
    return exposure


def tone_map(image, exposure=0.0):
    """Map linear RGB to 8-bit sRGB.

    Multiplies by ``2**exposure``, clamps to [0, 1] (NaN becomes 0), applies
    the sRGB transfer function and rounds to the nearest integer.  The float64
    arithmetic runs over blocks of values, so memory beyond the result stays
    a few MiB whatever the size of `image`.

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
    scale = 2.0 ** _check_exposure(exposure)
    image = np.asarray(image)
    flat = image.reshape(-1)  # a view when `image` is contiguous
    out = np.empty(flat.shape, dtype=np.uint8)
    for start in range(0, len(flat), _TONE_MAP_BLOCK):
        block = flat[start:start + _TONE_MAP_BLOCK].astype(np.float64) * scale
        block = np.clip(np.nan_to_num(block, nan=0.0), 0.0, 1.0)
        out[start:start + _TONE_MAP_BLOCK] = np.rint(_srgb_encode(block) * 255.0)
    return out.reshape(image.shape)


def _pillow():
    from PIL import Image, PngImagePlugin

    return Image, PngImagePlugin


def _png_picture(image, exposure):
    """A Pillow RGB picture of the tone-mapped image, filled a block of rows at a time.

    Only the picture (4 bytes per pixel inside Pillow) and one block of rows
    are in memory at once, never a float64 copy of the whole image.
    """
    Image, _ = _pillow()
    height, width, _ = image.shape
    picture = Image.new("RGB", (width, height))
    rows = max(1, _TONE_MAP_BLOCK // (3 * width))
    for y in range(0, height, rows):
        block = np.ascontiguousarray(image[y:y + rows], dtype=np.float32)
        picture.paste(Image.fromarray(tone_map(block, exposure)), (0, y))
    return picture


def _png_text(text):
    """PNG text chunks (tEXt) from a dict of str -> str."""
    _, PngImagePlugin = _pillow()
    info = PngImagePlugin.PngInfo()
    for key, value in (text or {}).items():
        info.add_text(key, value)
    return info


def _write_picture(picture, tmp, text):
    """Encode `picture` as PNG into the file `tmp`."""
    picture.save(tmp, format="PNG", pnginfo=_png_text(text))


def write_png(path, image, *, exposure=0.0, text=None):
    """Write a tone-mapped 8-bit sRGB PNG preview of a linear image, atomically.

    Parameters
    ----------
    path : str or os.PathLike
        The output file.
    image : numpy.ndarray
        float32 or float64 linear RGB array of shape (H, W, 3); float64
        values are rounded to float32 first, as in the EXR.
    exposure : float
        Exposure adjustment in stops: values are multiplied by
        ``2**exposure`` before clamping to [0, 1].
    text : dict of str -> str, optional
        PNG text chunks (e.g. ``raysort.render_id``).

    Raises
    ------
    ValueError
        If `image` has a wrong shape or dtype or `exposure` is not finite.
    OutputError
        If the file cannot be written.
    """
    picture = _png_picture(_rgb(image), _check_exposure(exposure))
    with atomic_target(path) as tmp:
        _write_picture(picture, tmp, text)


def png_bytes(image, *, exposure=0.0):
    """The tone-mapped 8-bit sRGB PNG of a linear image, as bytes (e.g. for Jupyter)."""
    buffer = io.BytesIO()
    _write_picture(_png_picture(_rgb(image), _check_exposure(exposure)), buffer, None)
    return buffer.getvalue()


def read_png(path):
    """Read an 8-bit RGB PNG (with Pillow).

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
        If the file is missing, corrupt or not an 8-bit RGB PNG.
    """
    _check_readable(path, _PNG_SIGNATURE, "a PNG")
    Image, _ = _pillow()
    try:
        with Image.open(os.fspath(path), formats=["PNG"]) as picture:
            picture.load()
            if picture.mode != "RGB":
                raise OutputError(f"cannot read {_q(path)}: a {picture.mode} PNG, "
                                  f"not 8-bit RGB")
            return np.asarray(picture)
    except (OSError, SyntaxError, ValueError) as exc:  # Pillow's errors for bad data
        raise OutputError(f"cannot read {_q(path)}: bad PNG: {exc}") from exc


# --------------------------------------------------------------------------
# An EXR and its PNG preview, as one pair
# --------------------------------------------------------------------------

def write_render(path, image, *, metadata=None, exposure=0.0, png=True, channels=None,
                 sidecars=None):
    """Write a render as an EXR and (with `png`) its PNG preview next to it.

    Both files are complete temporaries before either is renamed; the two
    renames then happen, EXR first, while this process holds a lock on the
    directory, so concurrent writers of the same path leave the EXR and PNG
    of one render.  Files in `sidecars` (such as the render's settings as
    JSON: :func:`json_text`) are written the same way, so a failure in any
    file leaves none of them; one naming a device (``/dev/null``) is written
    into before any file is renamed.  Both files record the same ``raysort.render_id`` (an
    EXR header attribute and a PNG text chunk): a digest of the pixels, the
    metadata and the exposure, so the same render always gives the same bytes.

    Parameters
    ----------
    path : str or os.PathLike
        The ``.exr`` file; the preview is the same name with ``.png``.
    image : numpy.ndarray
        float32 or float64 linear RGB array of shape (H, W, 3).
    metadata : dict of str -> str, optional
        Extra EXR header attributes.
    exposure : float
        PNG exposure in stops.
    png : bool
        Also write the PNG preview.
    channels : dict of str -> numpy.ndarray, optional
        Extra EXR channels (AOV layers), as :func:`write_exr` takes them.
    sidecars : dict of path -> str, optional
        Other files written with the render, all or none, as UTF-8 text.

    Returns
    -------
    str
        The render id written into both files.

    Raises
    ------
    ValueError, TypeError
        As :func:`write_exr` and :func:`write_png`.
    OutputError
        If a file cannot be written; no target is then changed.
    ConfigError
        If a sidecar is the image, its preview or another sidecar.
    """
    path = os.fspath(path)
    if os.path.splitext(path)[1].lower() != ".exr":
        raise OutputError(f"cannot write {_q(path)}: a render is written to an .exr file")
    sidecars = {os.fspath(p): text for p, text in (sidecars or {}).items()}
    for side, text in sidecars.items():
        if not isinstance(text, str):
            raise TypeError(f"sidecar {_q(side)}: text (str) expected, got {type(text).__name__}")
    png_path = os.path.splitext(path)[0] + ".png"
    check_distinct([("write_render", "the image", path),
                    ("write_render", "the preview", png_path if png else None)]
                   + [("a sidecar", "a sidecar", side) for side in sidecars])
    image, exposure, metadata = _as_rgb_float32(image), _check_exposure(exposure), metadata or {}
    _check_metadata(metadata)
    extra = _check_channels(channels or {}, image.shape[:2])
    render_id = _render_id(image, metadata, exposure if png else None, extra)
    stamp = {"raysort.render_id": render_id}
    exr = _prepared_exr(image, dict(metadata, **stamp), extra)
    picture = _png_picture(image, exposure) if png else None
    with contextlib.ExitStack() as temporaries:
        renames = [(temporaries.enter_context(_temporary(path)), path)]
        _write_exr_file(exr, renames[0][0], path)
        if png:
            renames.append((temporaries.enter_context(_temporary(png_path)), png_path))
            _write_picture(picture, renames[1][0], stamp)
        devices = []
        for side, text in sidecars.items():
            if _special(_final(side)):
                devices.append((_final(side), text, side))
                continue
            renames.append((temporaries.enter_context(_temporary(side)), side))
            _write_text(renames[-1][0], text, side)
        for tmp, target in renames:
            _finish(tmp, target)
        for device, text, side in devices:
            _write_text(device, text, side)
        with _directory_lock(os.path.dirname(path)):
            for tmp, target in renames:
                _rename(tmp, _final(target))
    with contextlib.suppress(OSError):
        _fsync(os.path.dirname(path) or os.curdir)
    return render_id


def _render_id(image, metadata, exposure, channels=None):
    """A digest of what the pair shows: pixels, metadata, the preview's exposure and the
    extra EXR channels.

    Identical renders get identical ids (so their files stay byte-identical);
    any difference in pixels, settings or exposure gives another id.
    """
    digest = hashlib.blake2b(digest_size=16)
    digest.update(repr((image.shape, sorted(metadata.items()), exposure)).encode())
    digest.update(memoryview(image).cast("B"))
    for name, data in sorted((channels or {}).items()):
        digest.update(name.encode() + b"\0")
        digest.update(memoryview(data).cast("B"))
    return digest.hexdigest()


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


def json_text(data):
    """``data`` as indented JSON text, as :func:`write_json` writes it (a value JSON has
    no type for is written as its ``str``)."""
    import json

    return json.dumps(data, indent=2, default=str) + "\n"


def _write_text(target, text, path):
    """Write ``text`` as UTF-8 into ``target`` (a temporary of ``path``, or a device)."""
    try:
        with open(target, "w", encoding="utf-8") as fh:
            fh.write(text)
    except OSError as exc:
        raise _os_error(path, exc) from exc


def write_json(path, data):
    """Write ``data`` as indented JSON (:func:`json_text`), atomically like the image
    writers."""
    with atomic_target(path) as tmp:
        _write_text(tmp, json_text(data), path)
