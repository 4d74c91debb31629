"""AOV layers: what each pixel's first primary ray hit, whatever the shader.

``Pipeline.render(..., aov=["depth", "normal", "albedo", "prim"])`` (or
``raysort render --aov depth,normal,albedo,prim``) fills ``result.aov`` and writes the
layers into the same EXR as extra channels, named as renderers name them:

=======  ===============================  =======  =============================  ========
layer    EXR channels                     type     value                          on a miss
=======  ===============================  =======  =============================  ========
depth    ``depth.Z``                      FLOAT    distance from the ray origin   +inf
                                                   to the hit (``t * |d|``)
normal   ``normal.X``, ``.Y``, ``.Z``     FLOAT    the face's unit geometric      0
                                                   normal, world space, turned
                                                   toward the camera
albedo   ``albedo.R``, ``.G``, ``.B``     FLOAT    the face's diffuse albedo      0
prim     ``prim``                         UINT     the face index (an int32 seen  2^32 - 1
                                                   as uint32)                     (-1)
=======  ===============================  =======  =============================  ========

Every layer comes from the pixel's **first sample** (sample 0), not an average over the
samples: then all layers describe one and the same surface point, exactly (an average
of depths or normals across an edge describes no surface, and a face index cannot be
averaged at all), and they do not change with ``spp``.  They are taken from the primary
hits the pipeline traces for any shader, so they are bit-identical for every sorter,
traversal and thread count.  :func:`read_aov` reads them back.
"""
from __future__ import annotations

import numpy as np

from raysort.errors import ConfigError

__all__ = ["LAYERS", "AovCollector", "exr_channels", "read_aov", "parse_names"]

#: layer -> its EXR channel names, in order (``prim`` is one channel, no layer prefix)
LAYERS = {
    "depth": ("depth.Z",),
    "normal": ("normal.X", "normal.Y", "normal.Z"),
    "albedo": ("albedo.R", "albedo.G", "albedo.B"),
    "prim": ("prim",),
}
_MISS = {"depth": np.inf, "normal": 0.0, "albedo": 0.0, "prim": -1}


def parse_names(names):
    """AOV layer names from a list or a comma-separated string; ConfigError on an unknown
    or repeated one."""
    if isinstance(names, str):
        text, names = names, [n.strip() for n in names.split(",") if n.strip()]
        if not names:
            raise ConfigError(f"expected AOV names such as depth,normal, got {text!r}")
    names = list(names)
    for name in names:
        if name not in LAYERS:
            raise ConfigError(f"unknown AOV {name!r}; AOVs: {', '.join(LAYERS)}")
    if len(set(names)) != len(names):
        raise ConfigError(f"AOV list {','.join(names)!r} names a layer twice")
    return names


class AovCollector:
    """A render tap that keeps the AOVs of each pixel's first primary hit.

    Tiles write disjoint pixels, so worker threads may call it at once.
    """

    def __init__(self, names, scene, width, height):
        self.names = parse_names(names)
        self.scene, self.shape = scene, (height, width)
        n = width * height
        self._normals = scene.face_normals() if "normal" in self.names else None
        self._data = {}
        for name in self.names:
            dtype = np.int32 if name == "prim" else np.float32
            self._data[name] = np.full((n, len(LAYERS[name])), _MISS[name], dtype=dtype)

    def __call__(self, record):
        if record.shadow or record.depth != 0:
            return
        first = np.flatnonzero(record.paths.sample == 0)
        prim = record.hits.prim[first]
        hit = prim >= 0
        pixel, face, ray = record.paths.pixel[first][hit], prim[hit], first[hit]
        d = record.rays.directions[:, ray].T.astype(np.float64)
        for name in self.names:
            out = self._data[name]
            if name == "depth":
                out[pixel, 0] = record.hits.t[ray] * np.linalg.norm(d, axis=1)
            elif name == "normal":
                nrm = self._normals[face]
                flip = (nrm * d).sum(axis=1) > 0            # turn it toward the camera
                out[pixel] = np.where(flip[:, None], -nrm, nrm)
            elif name == "albedo":
                out[pixel] = self.scene.albedo[face]
            else:
                out[pixel, 0] = face

    def layers(self):
        """Layer name -> ``(height, width)`` array (``depth`` float32, ``prim`` int32) or
        ``(height, width, 3)`` float32 (``normal``, ``albedo``)."""
        out = {}
        for name, data in self._data.items():
            shape = self.shape if data.shape[1] == 1 else self.shape + (data.shape[1],)
            out[name] = data.reshape(shape)
        return out


def exr_channels(aov):
    """``{channel name: (height, width) array}`` of AOV layers, as the EXR writer takes
    them: float32 channels, and ``prim`` as uint32 (a UINT channel)."""
    channels = {}
    for name, data in aov.items():
        data = np.asarray(data)
        if name == "prim":
            channels["prim"] = np.ascontiguousarray(data.astype(np.int32).view(np.uint32))
            continue
        planes = data[..., None] if data.ndim == 2 else data
        for k, channel in enumerate(LAYERS[name]):
            channels[channel] = np.ascontiguousarray(planes[..., k], dtype=np.float32)
    return channels


def read_aov(path):
    """The AOV layers of an EXR written by raysort: layer name -> array, shaped as
    :meth:`AovCollector.layers` returns them (layers the file lacks are left out)."""
    from raysort.output import read_exr_channels

    channels = read_exr_channels(path)
    out = {}
    for name, names in LAYERS.items():
        if all(c in channels for c in names):
            if name == "prim":
                out[name] = np.asarray(channels["prim"]).astype(np.uint32).view(np.int32)
            elif len(names) == 1:
                out[name] = np.asarray(channels[names[0]], dtype=np.float32)
            else:
                out[name] = np.stack([np.asarray(channels[c], np.float32) for c in names], -1)
    return out
