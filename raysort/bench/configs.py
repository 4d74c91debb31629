"""The configurations ``raysort bench`` measures, read from data.

:file:`configs.toml` (next to this module) holds the named configurations of the
paper's experiment, the rules that add every installed traversal or a named
sorter, the sorter x traversal ``[matrix]`` preset and the ``[kernels]``
layouts.  A user's TOML file with the same tables (``--configs``) and
``--add LABEL TRAVERSAL SORTER`` extend it; this module only expands the rules
against what is installed, so the bench's code names no plugin.  Every file is
checked as it is read (its tables, keys, types and label templates), so a mistake
in one is a ConfigError naming the file before anything runs.
"""
from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

from raysort import registry
from raysort.errors import ConfigError
from raysort.registry import parse_spec

if sys.version_info >= (3, 11):
    import tomllib
else:                                   # pragma: no cover
    import tomli as tomllib

__all__ = ["ALL", "Config", "Table", "load_table"]

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
    where = f"--configs {str(path)!r}"
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except OSError as exc:
        raise ConfigError(f"{where}: {exc.strerror or exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{where}: not valid TOML ({exc})") from None
    except UnicodeDecodeError:
        raise ConfigError(f"{where}: not valid TOML (not UTF-8 text)") from None
    except RecursionError:
        raise ConfigError(f"{where}: not valid TOML (nested too deeply)") from None


# --------------------------------------------------------------------------
# checking a file's tables (before anything runs)
# --------------------------------------------------------------------------

#: the keys of each table ("": the file's top level)
KEYS = {
    "": ("render", "config", "each_traversal", "each_sorter", "matrix", "kernels"),
    "render": ("shader", "depth_parameter", "baseline", "compare"),
    "config": ("label", "traversal", "sorter", "baseline", "paper"),
    "each_traversal": ("label", "sorter", "baseline"),
    "each_sorter": ("label", "traversal", "baseline"),
    "matrix": ("label", "baseline_sorter"),
    "kernels": ("workloads", "baseline", "label", "packets"),
}
#: the placeholders a label template may use, by table
PLACEHOLDERS = {"each_traversal": ("traversal",), "each_sorter": ("sorter",),
                "matrix": ("traversal", "sorter"), "kernels": ("traversal", "packets")}
SPEC = "a name, 'name:key=value,...' or a table with a 'type' key"


def _brief(value, limit=60):
    """``repr(value)``, shortened for a one-line message."""
    text = repr(value)
    return text if len(text) <= limit else text[:limit - 3] + "..."


def _need(table, key, where):
    if key not in table:
        raise ConfigError(f"{where}: missing {key!r}")
    return table[key]


def _keys(table, name, where):
    unknown = [k for k in table if k not in KEYS[name]]
    if unknown:
        raise ConfigError(f"{where}: unknown key {unknown[0]!r} (known: "
                          f"{', '.join(KEYS[name])})")


def _table(parent, key, where):
    """``parent[key]``: a table ({} if absent), its keys checked."""
    value = parent.get(key, {})
    if not isinstance(value, dict):
        raise ConfigError(f"{where}: {key!r} must be a table ([{key}]), got {_brief(value)}")
    _keys(value, key, f"{where} [{key}]")
    return value


def _tables(parent, key, where):
    """``parent[key]``: an array of tables ([] if absent)."""
    value = parent.get(key, [])
    if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
        raise ConfigError(f"{where}: {key!r} must be an array of tables ([[{key}]]), got "
                          f"{_brief(value)}")
    return value


def _string(table, key, where, default=""):
    value = table.get(key, default)
    if not isinstance(value, str):
        raise ConfigError(f"{where}: {key!r} must be a string, got {_brief(value)}")
    return value


def _label(table, where):
    _need(table, "label", where)
    return _string(table, "label", where)


def _spec(value, what, where):
    """A plugin spec: a name, "name:key=value,..." (its syntax checked) or a table
    with a "type" name."""
    if isinstance(value, str):
        try:
            parse_spec(value)
        except ConfigError as exc:
            raise ConfigError(f"{where}: {what}: {exc}") from None
        return value
    if isinstance(value, dict) and isinstance(value.get("type"), str) and value["type"]:
        return value
    raise ConfigError(f"{where}: {what} must be {SPEC}, got {_brief(value)}")


def _template(text, name, where):
    """A label template of table ``name``, checked by filling in its placeholders."""
    names = PLACEHOLDERS[name]
    try:
        text.format(**{n: n for n in names})
    except KeyError as exc:
        problem = f"unknown placeholder {{{exc.args[0]}}}"
    except IndexError:
        problem = "a placeholder without a name"
    except (ValueError, AttributeError, TypeError) as exc:
        problem = str(exc)
    else:
        return text
    raise ConfigError(f"{where}: label {text!r} is not a valid template ({problem}); it may "
                      f"use {' and '.join('{' + n + '}' for n in names)}")


def _render(data, source):
    where = f"{source} [render]"
    render = _table(data, "render", source)
    out = {k: _string(render, k, where) for k in ("depth_parameter", "baseline") if k in render}
    if "shader" in render:
        shader = _spec(render["shader"], "'shader'", where)
        out["shader"] = dict(parse_spec(shader) if isinstance(shader, str) else shader)
    if "compare" in render:
        pairs = render["compare"]
        if not isinstance(pairs, list) or not all(
                isinstance(p, list) and len(p) == 2 and all(isinstance(w, str) for w in p)
                for p in pairs):
            raise ConfigError(f"{where}: 'compare' must be an array of [label, over label] "
                              f"pairs, got {_brief(pairs)}")
        out["compare"] = [tuple(p) for p in pairs]
    return out


def _config(entry, where):
    label = _label(entry, where)
    where = f"{where} {label!r}"
    _keys(entry, "config", where)
    return Config(label, _spec(_need(entry, "traversal", where), "'traversal'", where),
                  _spec(_need(entry, "sorter", where), "'sorter'", where),
                  baseline=_string(entry, "baseline", where), paper=_string(entry, "paper", where))


def _rule(rule, name, where):
    """An ``each_traversal`` or ``each_sorter`` rule: its label template, the plugin
    it fixes (the sorter, or the traversal) and its baseline."""
    label = _template(_label(rule, where), name, where)
    where = f"{where} {label!r}"
    _keys(rule, name, where)
    fixed = "sorter" if name == "each_traversal" else "traversal"
    return {"label": label, fixed: _spec(_need(rule, fixed, where), repr(fixed), where),
            "baseline": _string(rule, "baseline", where)}


def _labelled(data, name, source, keys):
    """Table ``[name]`` of ``data``, its ``label`` template and its string ``keys``
    checked: ``(table, {key: value}, where)``, ``where`` naming it for errors."""
    where = f"{source} [{name}]"
    table = _table(data, name, source)
    out = {}
    if "label" in table:
        out["label"] = _template(_string(table, "label", where), name, where)
    out.update({k: _string(table, k, where) for k in keys if k in table})
    return table, out, where


def _matrix(data, source):
    return _labelled(data, "matrix", source, ("baseline_sorter",))[1]


def _kernels(data, source):
    kernels, out, where = _labelled(data, "kernels", source, ("baseline",))
    if "workloads" in kernels:
        kinds = kernels["workloads"]
        if not isinstance(kinds, list) or not kinds:
            raise ConfigError(f"{where}: 'workloads' must be an array of workload kinds, "
                              f"got {_brief(kinds)}")
        out["workloads"] = [_spec(k, "each of 'workloads'", where) for k in kinds]
    if "packets" in kernels:
        out["packets"] = _packets(kernels["packets"], source)
    return out


def _packets(packets, source):
    """``[kernels.packets]``: layout name -> sorter spec, at least one."""
    if not isinstance(packets, dict):
        raise ConfigError(f"{source} [kernels]: 'packets' must be a table "
                          f"([kernels.packets]), got {_brief(packets)}")
    if not packets:
        raise ConfigError(f"{source}: [kernels.packets] names no packet layout")
    return {p: _spec(spec, repr(p), f"{source} [kernels.packets]") for p, spec in packets.items()}


def _check(data, source):
    """One file's tables with every key, type and label template checked, as
    :class:`Table` merges them; ConfigError naming ``source`` and the table, key or
    value that is wrong."""
    _keys(data, "", source)
    return {"render": _render(data, source),
            "config": [_config(e, f"{source} [[config]]")
                       for e in _tables(data, "config", source)],
            "each_traversal": [_rule(r, "each_traversal", f"{source} [[each_traversal]]")
                               for r in _tables(data, "each_traversal", source)],
            "each_sorter": [_rule(r, "each_sorter", f"{source} [[each_sorter]]")
                            for r in _tables(data, "each_sorter", source)],
            "matrix": _matrix(data, source), "kernels": _kernels(data, source)}


# --------------------------------------------------------------------------

class Table:
    """The configuration data: explicit configurations, rules and presets."""

    def __init__(self, data, source="configs.toml"):
        self.source = source
        self.render, self.matrix, self.kernels = {}, {}, {}
        self.configs, self.each_traversal, self.each_sorter = [], [], []
        self.origin = {}        # "table.key" -> the file its value came from
        self.extend(data, source)

    def add(self, config):
        """Add a configuration; one with the same label is replaced in place."""
        for k, c in enumerate(self.configs):
            if c.label == config.label:
                self.configs[k] = config
                return
        self.configs.append(config)

    def extend(self, data, source):
        """Merge another file's tables (checked first, see :func:`_check`): its
        configurations replace or follow ours, its rules are added, its
        render/matrix/kernels keys override ours."""
        data = _check(data, source)
        for config in data["config"]:
            self.add(config)
        self.each_traversal += data["each_traversal"]
        self.each_sorter += data["each_sorter"]
        for name in ("render", "matrix", "kernels"):
            getattr(self, name).update(data[name])
            self.origin.update({f"{name}.{key}": source for key in data[name]})

    def where(self, key):
        """The file the value of ``key`` ("table.key") came from."""
        return self.origin.get(key, self.source)

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
            raise ConfigError(f"{self.where('kernels.packets')}: [kernels.packets] names no "
                              f"packet layout")
        template = self.kernels.get("label", "{traversal} / {packets}")
        configs = [Config(template.format(traversal=t, packets=p), t, spec, row=t, column=p)
                   for t in traversals for p, spec in packets.items()]
        return _unique(configs, self.kernels.get("baseline", ""))

    @staticmethod
    def _from_rule(rule, **names):
        """The configuration a (checked) rule makes for the plugin ``names`` gives."""
        return Config(rule["label"].format(**names), names.get("traversal", rule.get("traversal")),
                      names.get("sorter", rule.get("sorter")), baseline=rule["baseline"])


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
        table.extend(_read(path), f"--configs {str(path)!r}")
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
