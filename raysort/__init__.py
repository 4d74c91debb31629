"""raysort: ray sorting for fast incoherent packet ray tracing.

A Manta-style pipeline (generate -> sort -> traverse -> shade) whose parts are
plugins found through entry points, with Cython + SSE kernels.  Start with
:class:`Pipeline`::

    import raysort
    pipe = raysort.Pipeline("sibenik", sorter="nah", traversal="ranged")
    result = pipe.render(256, 256, spp=4)
    result.write("sibenik.exr")
"""
from pathlib import Path


def _require_compiled():
    """Fail clearly when Python imports the uncompiled source tree (``python -c "import
    raysort"`` from a checkout) instead of the installed package."""
    from importlib.machinery import EXTENSION_SUFFIXES

    here = Path(__file__).parent
    if not (here.parent / "setup.py").is_file():
        return                                   # an installed package
    if not any(any(here.rglob("*" + suffix)) for suffix in EXTENSION_SUFFIXES):
        raise ImportError(
            f"this is raysort's source tree ({here}), which has no compiled extensions: "
            f"install raysort with `pip install .` and run Python from another directory "
            f"(or build in place with `pip install -e .`)")


_require_compiled()

from raysort.bvh import BVH  # noqa: E402 (after the check above)
from raysort.camera import Camera
from raysort.errors import (ClusterError, ConfigError, OutputError, PluginContractError,
                            PluginError, PluginLoadError, RaysortError, SceneError,
                            UnknownPluginError)
from raysort.meshtrace import trace
from raysort.paths import Bounce, Paths, ShadowRays
from raysort.pipeline import Pipeline, RenderResult, RenderStats
from raysort.plugin import Generator, Shader, Sorter, Traversal
from raysort.rays import Hits, Packets, RayBatch, gather, scatter
from raysort.registry import available, create, list_plugins, load, refresh, register, unregister
from raysort.scene import Scene, load_scene, scene_names
from raysort.stats import Counters

__all__ = [
    "Pipeline", "RenderResult", "RenderStats", "Scene", "load_scene", "scene_names", "Camera",
    "BVH", "RayBatch", "Hits", "Packets", "gather", "scatter", "Paths", "Bounce",
    "ShadowRays", "Counters", "Generator", "Sorter", "Traversal", "Shader", "register",
    "unregister", "create", "load", "available", "list_plugins", "refresh", "get_include",
    "RaysortError", "ConfigError", "SceneError", "OutputError", "PluginError",
    "UnknownPluginError", "PluginLoadError", "PluginContractError", "ClusterError",
    "trace",
]


def get_include():
    """Directory to add to ``include_dirs`` to build a Cython plugin against raysort's headers."""
    return str(Path(__file__).parent / "include")


def __getattr__(name):
    if name == "__version__":
        from importlib.metadata import PackageNotFoundError, version
        try:
            return version("raysort")
        except PackageNotFoundError:
            return "0+unknown"
    raise AttributeError(f"module 'raysort' has no attribute {name!r}")
