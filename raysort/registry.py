"""Find, load and configure plugins by name.

Plugins come from four entry-point groups, ``raysort.generators``,
``raysort.sorters``, ``raysort.traversals`` and ``raysort.shaders``; raysort's
own built-ins are registered there by its ``pyproject.toml``, exactly as a
third-party package registers its plugins.  :func:`register` adds a plugin in
process (for scripts and tests).

Discovery is lazy: listing names imports nothing, and a plugin module is
imported the first time its name is used.  A plugin that fails to import is
reported with its name and distribution when it is used (or listed with
``load=True``); every other plugin keeps working.  Two distributions claiming
the same name make that name an error until one is uninstalled; an in-process
registration never silently replaces a name (pass ``replace=True``).

Set ``RAYSORT_DISABLE_PLUGIN_AUTOLOAD=1`` to ignore every distribution but
raysort itself.
"""
from __future__ import annotations

import ast
import os
from dataclasses import dataclass
from importlib import metadata

from raysort.errors import (ConfigError, PluginError, PluginLoadError, UnknownPluginError)
from raysort.plugin import KINDS

__all__ = ["PluginInfo", "available", "load", "create", "register", "unregister",
           "list_plugins", "refresh", "parse_spec", "KIND_NAMES"]

KIND_NAMES = tuple(KINDS)
_GROUP = "raysort.{}"
_SELF = "raysort"


def _singular(kind):
    return kind[:-1]


def _check_kind(kind):
    if kind not in KINDS:
        raise ConfigError(f"unknown plugin kind {kind!r}; kinds are: {', '.join(KIND_NAMES)}")


@dataclass
class PluginInfo:
    """What is known about one registered plugin."""

    kind: str
    name: str
    target: str             # "module:attribute", or the class for in-process plugins
    distribution: str
    version: str
    status: str = "not loaded"  # "ok", "not loaded", "broken: ...", "duplicate: ..."
    description: str = ""


class _Registry:
    def __init__(self):
        self._inprocess = {kind: {} for kind in KINDS}
        self._loaded = {}
        self._scanned = None

    # -- discovery --------------------------------------------------------
    def _scan(self):
        """Entry points per kind and name: a list of (entry point, dist name, version)."""
        if self._scanned is None:
            autoload = os.environ.get("RAYSORT_DISABLE_PLUGIN_AUTOLOAD", "") in ("", "0")
            found = {kind: {} for kind in KINDS}
            for kind in KINDS:
                seen = set()
                for ep in metadata.entry_points(group=_GROUP.format(kind)):
                    dist = getattr(ep, "dist", None)
                    dname = dist.metadata["Name"] if dist is not None else "?"
                    version = dist.version if dist is not None else "?"
                    if not autoload and dname != _SELF:
                        continue
                    if (ep.name, ep.value, dname) in seen:
                        continue
                    seen.add((ep.name, ep.value, dname))
                    found[kind].setdefault(ep.name, []).append((ep, dname, version))
            self._scanned = found
        return self._scanned

    def refresh(self):
        self._scanned = None
        self._loaded.clear()

    def names(self, kind):
        _check_kind(kind)
        return sorted(set(self._scan()[kind]) | set(self._inprocess[kind]))

    # -- loading ----------------------------------------------------------
    def load(self, kind, name):
        _check_kind(kind)
        if name in self._inprocess[kind]:
            return self._inprocess[kind][name]
        key = (kind, name)
        if key in self._loaded:
            return self._loaded[key]
        candidates = self._scan()[kind].get(name)
        if not candidates:
            names = self.names(kind)
            raise UnknownPluginError(
                f"unknown {_singular(kind)} {name!r}; available {kind}: "
                f"{', '.join(names) if names else '(none installed)'}",
                kind=kind, name=name)
        if len(candidates) > 1:
            claim = "; ".join(f"{d} {v} ({ep.value})" for ep, d, v in candidates)
            raise PluginLoadError(
                f"{_singular(kind)} name {name!r} is claimed by more than one "
                f"distribution: {claim}; uninstall all but one", kind=kind, name=name)
        ep, dname, version = candidates[0]
        try:
            obj = ep.load()
        except Exception as exc:  # any import failure of a third-party module
            raise PluginLoadError(
                f"{_singular(kind)} {name!r} from distribution '{dname}' {version} failed "
                f"to load ({ep.value}): {type(exc).__name__}: {exc}",
                kind=kind, name=name, distribution=dname) from exc
        self._validate(kind, name, obj, dname)
        self._loaded[key] = obj
        return obj

    @staticmethod
    def _validate(kind, name, obj, dname):
        base = KINDS[kind]
        if not (isinstance(obj, type) and issubclass(obj, base)):
            raise PluginLoadError(
                f"{_singular(kind)} {name!r} from distribution '{dname}' is {obj!r}, "
                f"not a subclass of raysort.plugin.{base.__name__}",
                kind=kind, name=name, distribution=dname)

    # -- in-process plugins -------------------------------------------------
    def register(self, kind, name, cls, replace=False):
        _check_kind(kind)
        if not isinstance(name, str) or not name.isidentifier():
            raise ConfigError(f"a plugin name must be an identifier, got {name!r}")
        self._validate(kind, name, cls, "<in-process>")
        if not replace and (name in self._inprocess[kind] or name in self._scan()[kind]):
            raise PluginError(
                f"a {_singular(kind)} named {name!r} is already registered; pass "
                f"replace=True to replace it", kind=kind, name=name)
        self._inprocess[kind][name] = cls

    def unregister(self, kind, name):
        _check_kind(kind)
        if self._inprocess[kind].pop(name, None) is None:
            raise UnknownPluginError(
                f"no in-process {_singular(kind)} named {name!r} is registered",
                kind=kind, name=name)

    # -- listing ----------------------------------------------------------
    def infos(self, kind=None, load=False):
        out = []
        for k in ([kind] if kind else KIND_NAMES):
            _check_kind(k)
            for name in self.names(k):
                out.append(self._info(k, name, load))
        return out

    def _info(self, kind, name, load):
        if name in self._inprocess[kind]:
            cls = self._inprocess[kind][name]
            return PluginInfo(kind, name, f"{cls.__module__}:{cls.__qualname__}",
                              "<in-process>", "", "ok", _summary(cls))
        candidates = self._scan()[kind][name]
        ep, dname, version = candidates[0]
        info = PluginInfo(kind, name, ep.value, dname, version)
        if len(candidates) > 1:
            others = ", ".join(d for _, d, _ in candidates)
            info.status = f"duplicate: claimed by {others}"
        elif load:
            try:
                info.description = _summary(self.load(kind, name))
                info.status = "ok"
            except PluginError as exc:
                cause = exc.__cause__
                info.status = "broken: " + (f"{type(cause).__name__}: {cause}" if cause
                                            else str(exc))
        return info


def _summary(cls):
    doc = (cls.__doc__ or "").strip()
    return doc.splitlines()[0] if doc else ""


_registry = _Registry()


def available(kind):
    """Sorted names of the plugins of ``kind`` ("sorters", ...); imports nothing."""
    return _registry.names(kind)


def load(kind, name):
    """The plugin class registered as ``name`` (imports its module on first use)."""
    return _registry.load(kind, name)


def register(kind, name, cls, *, replace=False):
    """Register ``cls`` (a subclass of the kind's base class) under ``name`` in process."""
    _registry.register(kind, name, cls, replace=replace)


def unregister(kind, name):
    """Remove an in-process registration."""
    _registry.unregister(kind, name)


def refresh():
    """Forget what was discovered and loaded (after installing a plugin package)."""
    _registry.refresh()


def list_plugins(kind=None, *, load=False):
    """:class:`PluginInfo` for every plugin; ``load=True`` imports each to check it."""
    return _registry.infos(kind, load)


def create(kind, config):
    """A configured plugin instance.

    ``config`` is a name (``"nah"``), a spec string (``"none:packet_size=1024"``),
    a dict with a ``"type"`` key and the plugin's parameters
    (``{"type": "none", "packet_size": 1024}``), or an existing instance.  A
    parameter the plugin does not take is an error that lists the ones it does.
    """
    _check_kind(kind)
    base = KINDS[kind]
    if isinstance(config, base):
        return config
    if isinstance(config, str):
        config = parse_spec(config)
    if not isinstance(config, dict):
        raise ConfigError(f"a {_singular(kind)} is chosen by a name or a dict with a "
                          f"'type' key, got {config!r}")
    params = dict(config)
    name = params.pop("type", None)
    if not isinstance(name, str):
        raise ConfigError(f"the {_singular(kind)} config {config!r} has no 'type' name")
    cls = load(kind, name)
    accepted = cls.parameter_names()
    unread = sorted(set(params) - set(accepted))
    if unread:
        takes = ", ".join(accepted) if accepted else "no parameters"
        raise ConfigError(
            f"{_singular(kind)} {name!r} does not read parameter"
            f"{'s' if len(unread) > 1 else ''} {', '.join(map(repr, unread))} "
            f"(it takes: {takes})")
    try:
        obj = cls(**params)
    except ConfigError as exc:
        raise ConfigError(f"{_singular(kind)} {name!r}: {exc}") from None
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"{_singular(kind)} {name!r}: {exc}") from exc
    obj.name = name
    return obj


_WORDS = {"true": True, "false": False, "none": None, "null": None}


def parse_spec(spec):
    """``"name:key=value,key=value"`` -> ``{"type": name, key: value, ...}``.

    Values are Python literals where they parse as one (``1024``, ``0.25``,
    ``True``), the words ``true``, ``false`` and ``none`` in any case (as in
    TOML and on the command line), else strings.  An empty item (``a=1,,b=2``),
    a repeated key or a missing name is an error.
    """
    if not isinstance(spec, str):
        raise ConfigError(f"a plugin spec is a string 'name:key=value,...', got {spec!r}")
    name, colon, rest = spec.partition(":")
    config = {"type": name.strip()}
    if not config["type"]:
        raise ConfigError(f"cannot read {spec!r}: expected a plugin name before ':'")
    items = rest.split(",") if colon and rest.strip() else []
    for item in (s.strip() for s in items):
        key, eq, value = item.partition("=")
        key = key.strip()
        if not eq or not key.isidentifier():
            raise ConfigError(f"cannot read {item!r} in {spec!r}: expected key=value"
                              + (" (an empty item between commas)" if not item else ""))
        if key in config:
            raise ConfigError(f"cannot read {spec!r}: {key!r} is given twice")
        config[key] = _value(value.strip())
    return config


def _value(text):
    if text.lower() in _WORDS:
        return _WORDS[text.lower()]
    try:
        return ast.literal_eval(text)
    except (ValueError, TypeError, SyntaxError, MemoryError, RecursionError):
        return text
