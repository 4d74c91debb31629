"""The configurations ``raysort bench`` measures, read from data.

:file:`configs.toml` (next to this module) holds the named configurations of the
paper's experiment, the rules that add every installed traversal or a named
sorter, the sorter x traversal ``[matrix]`` preset and the ``[kernels]``
layouts.  A user's TOML file with the same tables (``--configs``) and
``--add LABEL TRAVERSAL SORTER`` extend it; this module only expands the rules
against what is installed, so the bench's code names no plugin.
"""
from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

from raysort import registry
from raysort.errors import ConfigError

if sys.version_info >= (3, 11):
    import tomllib
else:                                   # pragma: no cover
    import tomli as tomllib

__all__ = ["Config", "Table", "load_table", "ALL"]

DEFAULT_FILE = Path(__file__).with_name("configs.toml")
#: the word that stands for every installed sorter or traversal
ALL = "all"


@dataclass
class Config:
    """One (traversal, sorter) configuration: a label, two plugin specs, the label
    of the configuration its speedup is taken over, and the paper's name for it."""

    label: str
    traversal: object
    sorter: object
    baseline: str = ""
    paper: str = ""
    row: str = ""        # the kernels table's row and column (traversal, packets)
    column: str = ""

    def as_dict(self):
        return {"label": self.label, "traversal": self.traversal, "sorter": self.sorter,
                "baseline": self.baseline, "paper": self.paper}


def _spec_name(spec):
    """The plugin name of a spec (a name, "name:k=v" or a dict with "type")."""
    if isinstance(spec, dict):
        return spec.get("type")
    return str(spec).split(":", 1)[0]


def _read(path):
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except OSError as exc:
        raise ConfigError(f"--configs {str(path)!r}: {exc.strerror or exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"--configs {str(path)!r}: not valid TOML ({exc})") from None


def _need(table, key, where):
    if key not in table:
        raise ConfigError(f"{where}: missing {key!r}")
    return table[key]


class Table:
    """The configuration data: explicit configurations, rules and presets."""

    def __init__(self, data, source="configs.toml"):
        self.source = source
        self.render = dict(data.get("render", {}))
        self.configs = []
        self.each_traversal = list(data.get("each_traversal", []))
        self.each_sorter = list(data.get("each_sorter", []))
        self.matrix = dict(data.get("matrix", {}))
        self.kernels = dict(data.get("kernels", {}))
        for entry in data.get("config", []):
            self.add(self._config(entry, f"{source} [[config]]"))

    @staticmethod
    def _config(entry, where):
        label = _need(entry, "label", where)
        return Config(str(label), _need(entry, "traversal", f"{where} {label!r}"),
                      _need(entry, "sorter", f"{where} {label!r}"),
                      baseline=str(entry.get("baseline", "")), paper=str(entry.get("paper", "")))

    def add(self, config):
        """Add a configuration; one with the same label is replaced in place."""
        for k, c in enumerate(self.configs):
            if c.label == config.label:
                self.configs[k] = config
                return
        self.configs.append(config)

    def extend(self, data, source):
        """Merge another file's tables: its configurations replace or follow ours, its
        rules are added, its render/matrix/kernels keys override ours."""
        for entry in data.get("config", []):
            self.add(self._config(entry, f"{source} [[config]]"))
        self.each_traversal += list(data.get("each_traversal", []))
        self.each_sorter += list(data.get("each_sorter", []))
        for name in ("render", "matrix", "kernels"):
            getattr(self, name).update(data.get(name, {}))

    # ------------------------------------------------------------------
    @property
    def baseline(self):
        return self.render.get("baseline", "")

    def frame_configs(self, sorters=(), traversals=()):
        """The configurations of the frame benchmark.

        With no names: the explicit configurations, then the ``each_traversal`` rules
        for every installed traversal none of them uses.  ``sorters`` alone: the
        ``each_sorter`` rules for those sorters too.  ``traversals`` alone: only the
        ``each_traversal`` rules for those.  Both: the ``[matrix]`` preset.  ``"all"``
        in either stands for every installed plugin of that kind.
        """
        sorters = _expand("sorters", sorters)
        traversals = _expand("traversals", traversals)
        if sorters and traversals:
            return self.matrix_configs(sorters, traversals)
        configs = list(self.configs)
        used = {_spec_name(c.traversal) for c in configs}
        wanted = traversals or [t for t in registry.available("traversals") if t not in used]
        for trav in wanted:
            for rule in self.each_traversal:
                configs.append(self._from_rule(rule, traversal=trav))
        for sorter in sorters:
            for rule in self.each_sorter:
                configs.append(self._from_rule(rule, sorter=sorter))
        return _unique(configs, self.baseline)

    def matrix_configs(self, sorters, traversals):
        base_sorter = self.matrix.get("baseline_sorter", "")
        template = self.matrix.get("label", "{traversal} + {sorter}")
        if base_sorter and base_sorter not in sorters:
            sorters = [base_sorter] + list(sorters)
        configs = []
        for trav in traversals:
            base = template.format(traversal=trav, sorter=base_sorter) if base_sorter else ""
            for sorter in sorters:
                configs.append(Config(template.format(traversal=trav, sorter=sorter), trav,
                                      sorter, baseline=base, row=trav, column=sorter))
        return _unique(configs, configs[0].label if configs else "")

    def kernel_configs(self, traversals=()):
        """Every installed traversal (or those named) with each ``[kernels.packets]``
        layout; the kernels table's rows are traversals and its columns layouts."""
        traversals = _expand("traversals", traversals) or registry.available("traversals")
        packets = self.kernels.get("packets", {})
        if not packets:
            raise ConfigError(f"{self.source}: [kernels.packets] names no packet layout")
        template = self.kernels.get("label", "{traversal} / {packets}")
        configs = [Config(template.format(traversal=t, packets=p), t, spec, row=t, column=p)
                   for t in traversals for p, spec in packets.items()]
        return _unique(configs, self.kernels.get("baseline", ""))

    @staticmethod
    def _from_rule(rule, **names):
        where = "configs.toml rule"
        label = str(_need(rule, "label", where)).format(**names)
        trav = names.get("traversal", rule.get("traversal"))
        sorter = names.get("sorter", rule.get("sorter"))
        if trav is None or sorter is None:
            raise ConfigError(f"{where} {label!r}: needs a traversal and a sorter")
        return Config(label, trav, sorter, baseline=str(rule.get("baseline", "")))


def _expand(kind, names):
    names = [n for n in names if n]
    if ALL in names:
        return registry.available(kind)
    for name in names:
        registry.load(kind, name)               # unknown or broken: a clear error now
    return names


def _unique(configs, baseline):
    """Drop repeated labels (the first stays); fill in the default baseline."""
    seen, out = set(), []
    for c in configs:
        if c.label not in seen:
            seen.add(c.label)
            if not c.baseline:
                c.baseline = baseline
            out.append(c)
    return out


def load_table(files=(), added=()):
    """The packaged table, extended by ``files`` (paths) and ``added`` configurations
    (``(label, traversal, sorter)`` triples, plugin specs as strings)."""
    table = Table(_read(DEFAULT_FILE))
    for path in files:
        table.extend(_read(path), str(path))
    for label, trav, sorter in added:
        table.add(Config(label, trav, sorter))
    return table


def select(configs, only):
    """The configurations whose labels are in ``only`` (in that order); ConfigError
    naming an unknown label and listing the known ones."""
    by_label = {c.label: c for c in configs}
    missing = [w for w in only if w not in by_label]
    if missing:
        raise ConfigError(f"unknown configuration {missing[0]!r}; known: {', '.join(by_label)}")
    return [by_label[w] for w in only]
