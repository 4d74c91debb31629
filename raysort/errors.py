"""Exceptions raised by raysort.

Every error a user can cause (a bad scene file, an unknown plugin name, an
unwritable output path, a plugin that breaks its contract) derives from
:class:`RaysortError`.  The command line prints such errors as one line,
without a traceback; anything else is a bug in raysort or in a plugin.
"""

__all__ = [
    "RaysortError",
    "ConfigError",
    "SceneError",
    "OutputError",
    "PluginError",
    "UnknownPluginError",
    "PluginLoadError",
    "PluginContractError",
    "ClusterError",
]


class RaysortError(Exception):
    """Base class of the errors a user can cause and fix."""


class ConfigError(RaysortError, ValueError):
    """A parameter or setting has a wrong name, type or value."""


class SceneError(RaysortError):
    """A scene file or mesh cannot be read or is not usable."""


class OutputError(RaysortError):
    """An output file cannot be written."""


class PluginError(RaysortError):
    """Base class of plugin problems; ``kind`` and ``name`` identify the plugin."""

    def __init__(self, message, *, kind=None, name=None, distribution=None):
        super().__init__(message)
        self.kind = kind
        self.name = name
        self.distribution = distribution


class UnknownPluginError(PluginError, KeyError):
    """No plugin of that kind has that name."""

    def __str__(self):  # KeyError would quote the message
        return self.args[0]


class PluginLoadError(PluginError):
    """A plugin was found but could not be imported."""


class PluginContractError(PluginError):
    """A plugin returned something that breaks its kind's contract."""


class ClusterError(RaysortError):
    """A Dask cluster cannot be reached, lost its workers, or keeps losing a task."""
