"""The plugin registry: entry-point discovery, lazy loading, errors that name the culprit.

Third-party plugins are simulated the way xarray's test_plugins.py does it:
hand-made ``importlib.metadata.EntryPoint`` objects are added to what
``raysort.registry.metadata.entry_points`` returns (the real raysort entry
points stay visible), and ``raysort.refresh()`` runs before and after each test.
"""
import subprocess
import sys
import textwrap
import types
import uuid
from importlib import metadata

import numpy as np
import pytest

import raysort
from raysort import registry
from raysort.errors import ConfigError, PluginError, PluginLoadError, UnknownPluginError
from raysort.registry import parse_spec

BUILTINS = {
    "generators": {"pinhole"},
    "sorters": {"none", "nah", "nah_numpy", "origin_direction", "two_point", "termination",
                "garanzha"},
    "traversals": {"single", "masked", "ranged", "partition", "wide", "wide8", "wide16", "stream",
                   "frustum"},
    "shaders": {"lambert", "ao"},
}


# --------------------------------------------------------------------------
# fake plugins and fixtures
# --------------------------------------------------------------------------

class GoodSorter(raysort.Sorter):
    """A third-party test sorter."""

    def __init__(self, *, packet_size=64, flavour="plain"):
        self.packet_size = packet_size
        self.flavour = flavour

    def sort(self, rays, packets, bounds):
        return np.arange(len(rays), dtype=np.int32), np.asarray(packets, np.int32)


class AnotherSorter(raysort.Sorter):
    """A second test sorter (for duplicate names)."""


class RaisingSorter(raysort.Sorter):
    """Rejects its parameter with a plain ValueError."""

    def __init__(self, *, width=1):
        raise ValueError(f"width {width} is not a power of two")


class NotAPlugin:
    """A class that does not derive from raysort.plugin.Sorter."""


class FakeDist:
    """Just enough of ``importlib.metadata.Distribution`` for the registry."""

    def __init__(self, name, version="1.0"):
        self.metadata = {"Name": name}
        self.version = version


def make_ep(name, value, kind, dist=None):
    """An EntryPoint in group raysort.<kind>, optionally attached to a fake distribution."""
    ep = metadata.EntryPoint(name, value, f"raysort.{kind}")
    if dist is not None:
        if hasattr(ep, "_for"):          # Python 3.10 - 3.12
            ep = ep._for(dist)
        else:                            # EntryPoint forbids setattr; its __dict__ does not
            vars(ep)["dist"] = dist
        assert ep.dist is dist
    return ep


@pytest.fixture
def fresh():
    """A clean registry before and after; in-process registrations are undone."""
    saved = {kind: dict(plugins) for kind, plugins in registry._registry._inprocess.items()}
    raysort.refresh()
    yield
    for kind, plugins in registry._registry._inprocess.items():
        plugins.clear()
        plugins.update(saved[kind])
    raysort.refresh()


@pytest.fixture
def fake_eps(monkeypatch, fresh):
    """``add(ep)``: make ``ep`` visible next to the real entry points."""
    extra = []
    real = metadata.entry_points

    def entry_points(**selection):
        found = list(real(**selection))
        return found + [ep for ep in extra if ep.group == selection.get("group")]

    monkeypatch.setattr(registry.metadata, "entry_points", entry_points)
    raysort.refresh()

    def add(*eps):
        extra.extend(eps)
        raysort.refresh()

    yield add
    raysort.refresh()


@pytest.fixture
def fake_module(monkeypatch):
    """``fake_module(**attrs)`` -> name of a new importable module holding ``attrs``."""
    def make(**attrs):
        name = f"raysort_fake_plugin_{uuid.uuid4().hex}"
        module = types.ModuleType(name)
        for key, value in attrs.items():
            setattr(module, key, value)
        monkeypatch.setitem(sys.modules, name, module)
        return name
    return make


@pytest.fixture
def exploding_module(tmp_path, monkeypatch):
    """Name of a module on sys.path whose import raises ImportError."""
    name = f"raysort_exploding_{uuid.uuid4().hex}"
    (tmp_path / f"{name}.py").write_text(
        'raise ImportError("libfoo.so.3: cannot open shared object file")\n')
    monkeypatch.syspath_prepend(str(tmp_path))
    yield name
    sys.modules.pop(name, None)


# --------------------------------------------------------------------------
# discovery of the built-ins
# --------------------------------------------------------------------------

@pytest.mark.parametrize("kind", sorted(BUILTINS))
def test_builtins_are_discovered_from_entry_points(kind, fresh):
    """raysort's own plugins come from its entry points, with distribution 'raysort'."""
    assert BUILTINS[kind] <= set(raysort.available(kind))
    eps = {ep.name: ep.value for ep in metadata.entry_points(group=f"raysort.{kind}")}
    infos = {i.name: i for i in raysort.list_plugins(kind)}
    for name in BUILTINS[kind]:
        assert infos[name].kind == kind
        assert infos[name].distribution == "raysort"
        assert infos[name].target == eps[name]
        assert infos[name].status in ("not loaded", "ok")
        cls = raysort.load(kind, name)
        assert issubclass(cls, registry.KINDS[kind])
        assert f"{cls.__module__}:{cls.__qualname__}" == eps[name]


def test_available_is_sorted_and_rejects_unknown_kinds(fresh):
    """Names come sorted; a misspelt kind is a ConfigError listing the four kinds."""
    names = raysort.available("traversals")
    assert names == sorted(names)
    assert BUILTINS["traversals"] <= set(names)     # and any installed outside plugins
    with pytest.raises(ConfigError, match="kinds are: generators, sorters, traversals, shaders"):
        raysort.available("sorter")


def test_listing_imports_no_builtin_plugin_module(tmp_path):
    """In a fresh interpreter, available() and list_plugins() import no plugin module.
    (Run outside the repository, so that the installed package is the one imported.)"""
    code = textwrap.dedent("""
        import sys, raysort
        for kind in ("generators", "sorters", "traversals", "shaders"):
            assert raysort.available(kind), kind
        assert len(raysort.list_plugins()) >= 9
        prefixes = ("raysort.generators.", "raysort.sorters.", "raysort.traversals.",
                    "raysort.shaders.")
        print(sorted(m for m in sys.modules if m.startswith(prefixes)))
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, timeout=120, cwd=tmp_path)
    assert out.stdout.strip() == "[]"


def test_listing_does_not_import_a_third_party_module(fake_eps, exploding_module):
    """A third-party entry point is listed by name without importing its module."""
    fake_eps(make_ep("boom", f"{exploding_module}:Sorter", "sorters", FakeDist("boom-dist")))
    assert exploding_module not in sys.modules
    assert "boom" in raysort.available("sorters")
    (info,) = [i for i in raysort.list_plugins("sorters") if i.name == "boom"]
    assert (info.distribution, info.version, info.status) == ("boom-dist", "1.0", "not loaded")
    assert exploding_module not in sys.modules


# --------------------------------------------------------------------------
# unknown and broken plugins
# --------------------------------------------------------------------------

def test_unknown_name_lists_available_names(fresh):
    """An unknown name raises UnknownPluginError (a KeyError) listing what exists."""
    with pytest.raises(UnknownPluginError) as info:
        raysort.load("sorters", "nha")
    msg = str(info.value)
    assert "'nha'" in msg
    for name in BUILTINS["sorters"]:
        assert name in msg
    assert isinstance(info.value, KeyError)
    assert (info.value.kind, info.value.name) == ("sorters", "nha")
    with pytest.raises(UnknownPluginError, match="single"):
        raysort.create("traversals", "singel")


def _broken_cases(exploding_module, fake_module):
    missing_attr = fake_module(Other=GoodSorter)
    wrong_base = fake_module(NotAPlugin=NotAPlugin)
    instance = fake_module(obj=GoodSorter())
    return {
        "import_error": (f"{exploding_module}:Sorter", "libfoo.so.3"),
        "missing_module": (f"raysort_no_such_module_{uuid.uuid4().hex}:Sorter",
                           "ModuleNotFoundError"),
        "missing_attribute": (f"{missing_attr}:Sorter", "AttributeError"),
        "not_a_subclass": (f"{wrong_base}:NotAPlugin", "not a subclass of raysort.plugin.Sorter"),
        "an_instance": (f"{instance}:obj", "not a subclass"),
    }


@pytest.mark.parametrize("case", ["import_error", "missing_module", "missing_attribute",
                                  "not_a_subclass", "an_instance"])
def test_broken_plugin_is_named_and_others_keep_working(case, fake_eps, exploding_module,
                                                        fake_module):
    """A plugin that cannot be loaded raises PluginLoadError naming it and its
    distribution; the built-ins and a healthy third-party plugin still load."""
    value, reason = _broken_cases(exploding_module, fake_module)[case]
    good = fake_module(GoodSorter=GoodSorter)
    fake_eps(make_ep("broken", value, "sorters", FakeDist("acme-raysort", "2.3")),
             make_ep("good", f"{good}:GoodSorter", "sorters", FakeDist("good-dist")))
    with pytest.raises(PluginLoadError) as info:
        raysort.load("sorters", "broken")
    msg = str(info.value)
    assert "'broken'" in msg and "acme-raysort" in msg and reason in msg
    assert (info.value.kind, info.value.name, info.value.distribution) == (
        "sorters", "broken", "acme-raysort")
    with pytest.raises(PluginLoadError, match="acme-raysort"):
        raysort.create("sorters", "broken")
    # everything else is unaffected
    assert {"broken", "good"} | BUILTINS["sorters"] <= set(raysort.available("sorters"))
    assert raysort.load("sorters", "good") is GoodSorter
    assert raysort.create("sorters", "none:packet_size=8").packet_size == 8
    assert type(raysort.create("sorters", "nah")).__name__ == "NahSorter"


def test_broken_plugin_without_distribution_says_so(fake_eps, exploding_module):
    """A hand-made entry point has no distribution: the error shows '?'."""
    fake_eps(make_ep("orphan", f"{exploding_module}:X", "traversals"))
    with pytest.raises(PluginLoadError, match=r"'orphan' from distribution '\?'"):
        raysort.load("traversals", "orphan")


def test_list_plugins_load_marks_broken_without_raising(fake_eps, exploding_module,
                                                        fake_module):
    """list_plugins(load=True) reports every plugin: ok ones with their docstring
    summary, broken ones as 'broken: <reason>'."""
    wrong = fake_module(NotAPlugin=NotAPlugin)
    good = fake_module(GoodSorter=GoodSorter)
    fake_eps(make_ep("boom", f"{exploding_module}:S", "sorters", FakeDist("boom-dist")),
             make_ep("wrong", f"{wrong}:NotAPlugin", "sorters", FakeDist("wrong-dist")),
             make_ep("good", f"{good}:GoodSorter", "sorters", FakeDist("good-dist", "0.4")))
    infos = {i.name: i for i in raysort.list_plugins("sorters", load=True)}
    assert infos["boom"].status.startswith("broken: ImportError: libfoo.so.3")
    assert infos["wrong"].status.startswith("broken: ")
    assert "not a subclass" in infos["wrong"].status
    assert (infos["good"].status, infos["good"].distribution, infos["good"].version) == (
        "ok", "good-dist", "0.4")
    assert infos["good"].description == "A third-party test sorter."
    for name in BUILTINS["sorters"]:
        assert infos[name].status == "ok" and infos[name].distribution == "raysort"
    # all kinds at once also survives the broken ones
    kinds = {i.kind for i in raysort.list_plugins(load=True)}
    assert kinds == set(BUILTINS)


def test_name_claimed_by_two_distributions(fake_eps, fake_module):
    """Two distributions claiming one name make it an error naming both; the
    listing marks it duplicate; other names are unaffected."""
    m1, m2 = fake_module(S=GoodSorter), fake_module(S=AnotherSorter)
    fake_eps(make_ep("twin", f"{m1}:S", "sorters", FakeDist("alpha-sort", "1.0")),
             make_ep("twin", f"{m2}:S", "sorters", FakeDist("beta-sort", "2.0")))
    assert raysort.available("sorters").count("twin") == 1
    with pytest.raises(PluginLoadError) as info:
        raysort.load("sorters", "twin")
    msg = str(info.value)
    assert "alpha-sort" in msg and "beta-sort" in msg and "'twin'" in msg
    for load in (False, True):
        (twin,) = [i for i in raysort.list_plugins("sorters", load=load) if i.name == "twin"]
        assert twin.status.startswith("duplicate")
        assert "alpha-sort" in twin.status and "beta-sort" in twin.status
    assert raysort.create("sorters", "none").packet_size == 64


def test_builtin_name_claimed_by_a_third_party(fake_eps, fake_module):
    """A third-party 'nah' next to raysort's own is also a duplicate, not a silent override."""
    m = fake_module(S=GoodSorter)
    fake_eps(make_ep("nah", f"{m}:S", "sorters", FakeDist("evil-nah")))
    with pytest.raises(PluginLoadError, match="raysort.*evil-nah|evil-nah.*raysort"):
        raysort.load("sorters", "nah")


def test_same_entry_point_seen_twice_is_not_a_duplicate(fake_eps, fake_module):
    """The same (name, target, distribution) listed twice (e.g. two path entries) is one plugin."""
    m = fake_module(S=GoodSorter)
    dist = FakeDist("once-dist")
    fake_eps(make_ep("once", f"{m}:S", "sorters", dist), make_ep("once", f"{m}:S", "sorters", dist))
    assert raysort.load("sorters", "once") is GoodSorter


# --------------------------------------------------------------------------
# RAYSORT_DISABLE_PLUGIN_AUTOLOAD
# --------------------------------------------------------------------------

def test_disable_autoload_hides_third_party_plugins(fake_eps, fake_module, monkeypatch):
    """RAYSORT_DISABLE_PLUGIN_AUTOLOAD=1 keeps raysort's own plugins and hides the rest
    (including entry points without a distribution); '0' or empty autoloads."""
    m = fake_module(S=GoodSorter)
    fake_eps(make_ep("thirdparty", f"{m}:S", "sorters", FakeDist("other-dist")),
             make_ep("nodist", f"{m}:S", "sorters"))
    assert {"thirdparty", "nodist"} <= set(raysort.available("sorters"))

    monkeypatch.setenv("RAYSORT_DISABLE_PLUGIN_AUTOLOAD", "1")
    raysort.refresh()
    assert set(raysort.available("sorters")) == BUILTINS["sorters"]
    for kind in BUILTINS:
        assert set(raysort.available(kind)) == BUILTINS[kind]
    with pytest.raises(UnknownPluginError):
        raysort.load("sorters", "thirdparty")
    assert raysort.create("sorters", "none").packet_size == 64

    # an in-process registration is still possible (it is not a distribution)
    raysort.register("sorters", "local", GoodSorter)
    assert "local" in raysort.available("sorters")

    for value in ("0", ""):
        monkeypatch.setenv("RAYSORT_DISABLE_PLUGIN_AUTOLOAD", value)
        raysort.refresh()
        assert "thirdparty" in raysort.available("sorters")


# --------------------------------------------------------------------------
# in-process registration
# --------------------------------------------------------------------------

def test_register_unregister_round_trip(fresh):
    """register makes a name available, loadable and creatable; unregister removes it."""
    assert "mine" not in raysort.available("sorters")
    raysort.register("sorters", "mine", GoodSorter)
    assert "mine" in raysort.available("sorters")
    assert raysort.load("sorters", "mine") is GoodSorter
    obj = raysort.create("sorters", {"type": "mine", "flavour": "spicy"})
    assert isinstance(obj, GoodSorter) and obj.flavour == "spicy" and obj.name == "mine"
    (info,) = [i for i in raysort.list_plugins("sorters") if i.name == "mine"]
    assert info.distribution == "<in-process>" and info.status == "ok"
    assert info.target == f"{__name__}:GoodSorter"
    raysort.unregister("sorters", "mine")
    assert "mine" not in raysort.available("sorters")
    with pytest.raises(UnknownPluginError):
        raysort.load("sorters", "mine")
    with pytest.raises(UnknownPluginError):
        raysort.unregister("sorters", "mine")


def test_duplicate_register_needs_replace(fresh):
    """A second registration of a name (in-process or built-in) is a PluginError
    unless replace=True; unregistering the replacement restores the built-in."""
    raysort.register("sorters", "mine", GoodSorter)
    with pytest.raises(PluginError, match="'mine' is already registered"):
        raysort.register("sorters", "mine", AnotherSorter)
    assert raysort.load("sorters", "mine") is GoodSorter
    raysort.register("sorters", "mine", AnotherSorter, replace=True)
    assert raysort.load("sorters", "mine") is AnotherSorter

    builtin = raysort.load("sorters", "none")
    with pytest.raises(PluginError, match="replace=True"):
        raysort.register("sorters", "none", GoodSorter)
    assert raysort.load("sorters", "none") is builtin
    raysort.register("sorters", "none", GoodSorter, replace=True)
    assert raysort.load("sorters", "none") is GoodSorter
    raysort.unregister("sorters", "none")
    assert raysort.load("sorters", "none") is builtin


@pytest.mark.parametrize("cls", [NotAPlugin, GoodSorter(), "GoodSorter", raysort.Traversal])
def test_register_rejects_non_subclasses(cls, fresh):
    """Only a subclass of the kind's base class can be registered (a Traversal is not a Sorter)."""
    with pytest.raises(PluginError, match="not a subclass of raysort.plugin.Sorter"):
        raysort.register("sorters", "bad", cls)
    assert "bad" not in raysort.available("sorters")


@pytest.mark.parametrize("name", ["", "two words", "1st", None, "a-b"])
def test_register_rejects_bad_names(name, fresh):
    """A plugin name must be an identifier (it appears in spec strings)."""
    with pytest.raises(ConfigError):
        raysort.register("sorters", name, GoodSorter)


# --------------------------------------------------------------------------
# create: configs, parameters
# --------------------------------------------------------------------------

def test_create_from_name_spec_dict_and_instance(fresh):
    """create accepts a name, a spec string, a dict and an instance (returned as is)."""
    by_name = raysort.create("sorters", "none")
    assert by_name.packet_size == 64 and by_name.name == "none"
    by_spec = raysort.create("sorters", "none:packet_size=1024")
    assert type(by_spec) is type(by_name) and by_spec.packet_size == 1024
    by_dict = raysort.create("sorters", {"type": "none", "packet_size": 16})
    assert by_dict.packet_size == 16
    assert raysort.create("sorters", by_dict) is by_dict
    assert raysort.create("traversals", "ranged").name == "ranged"


def test_create_does_not_modify_the_config_dict(fresh):
    """The caller's dict is left alone (it may be reused)."""
    config = {"type": "none", "packet_size": 32}
    raysort.create("sorters", config)
    assert config == {"type": "none", "packet_size": 32}


@pytest.mark.parametrize("config", [{"type": "none", "packet_size": 64, "bogus": 1},
                                    "none:bogus=1"])
def test_unread_parameter_names_plugin_and_accepted_parameters(config, fresh):
    """A parameter the plugin does not take is a ConfigError naming the plugin,
    the parameter and the parameters it does take."""
    with pytest.raises(ConfigError) as info:
        raysort.create("sorters", config)
    msg = str(info.value)
    assert "'none'" in msg and "'bogus'" in msg and "packet_size" in msg


def test_unread_parameters_all_listed(fresh):
    """Several unread parameters are all named, along with every accepted one."""
    with pytest.raises(ConfigError) as info:
        raysort.create("sorters", {"type": "nah", "zeta": 1, "alpha": 2})
    msg = str(info.value)
    assert "'alpha'" in msg and "'zeta'" in msg
    for accepted in ("threshold", "max_cells", "packet_size", "large_packet"):
        assert accepted in msg


def test_plugin_without_parameters_says_so(fresh):
    """A plugin whose __init__ takes nothing reports 'no parameters'."""
    raysort.register("sorters", "bare", AnotherSorter)
    with pytest.raises(ConfigError, match="no parameters"):
        raysort.create("sorters", "bare:x=1")


def test_init_value_error_becomes_config_error(fresh):
    """A ValueError from a plugin's __init__ becomes a ConfigError naming the plugin."""
    raysort.register("sorters", "picky", RaisingSorter)
    with pytest.raises(ConfigError) as info:
        raysort.create("sorters", "picky:width=3")
    assert "'picky'" in str(info.value) and "width 3 is not a power of two" in str(info.value)


def test_init_config_error_names_the_plugin(fresh):
    """A built-in's own ConfigError (bad value) is prefixed with the plugin's name."""
    with pytest.raises(ConfigError, match=r"^sorter 'none': packet_size must be"):
        raysort.create("sorters", "none:packet_size=0")


@pytest.mark.parametrize("config", [42, None, ["none"], {"packet_size": 4}, {"type": 3}])
def test_create_rejects_malformed_configs(config, fresh):
    """A config that is not a name, spec, dict with a 'type' or an instance is a ConfigError."""
    with pytest.raises(ConfigError):
        raysort.create("sorters", config)


def test_create_rejects_an_instance_of_another_kind(fresh):
    """A sorter instance is not a traversal config."""
    sorter = raysort.create("sorters", "none")
    with pytest.raises(ConfigError):
        raysort.create("traversals", sorter)


# --------------------------------------------------------------------------
# parse_spec
# --------------------------------------------------------------------------

@pytest.mark.parametrize("spec, expected", [
    ("nah", {"type": "nah"}),
    ("nah:", {"type": "nah"}),
    (" nah : threshold = 0.5 ", {"type": "nah", "threshold": 0.5}),
    ("none:packet_size=1024", {"type": "none", "packet_size": 1024}),
    ("nah:threshold=0.25,max_cells=4,large_packet=None",
     {"type": "nah", "threshold": 0.25, "max_cells": 4, "large_packet": None}),
    ("pinhole:jitter=False", {"type": "pinhole", "jitter": False}),
    ("x:mode=fast", {"type": "x", "mode": "fast"}),
    ("x:mode='fast'", {"type": "x", "mode": "fast"}),
    ("x:a=1, b = 2 ", {"type": "x", "a": 1, "b": 2}),
    ("lambert:russian_roulette=true,shadow_rays=none",
     {"type": "lambert", "russian_roulette": True, "shadow_rays": None}),
    ("x:a=FALSE,b=True,c=Null", {"type": "x", "a": False, "b": True, "c": None}),
    ("x:a=-3e-2", {"type": "x", "a": -0.03}),
    ("x:a=", {"type": "x", "a": ""}),
])
def test_parse_spec(spec, expected):
    """Specs split into a name and key=value items; values are Python literals or strings."""
    got = parse_spec(spec)
    assert got == expected
    assert [type(v) for v in got.values()] == [type(v) for v in expected.values()]


@pytest.mark.parametrize("spec", ["nah:threshold", "nah:=1", "nah:1x=2", "nah:a b=1",
                                  "nah:threshold=0.5,max_cells", "nah:threshold=0.5,,max_cells=2",
                                  "nah:threshold=0.5,", "nah:,threshold=0.5"])
def test_parse_spec_rejects_bad_items(spec):
    """An item that is not identifier=value (an empty one too) is a ConfigError quoting
    the item and the spec."""
    with pytest.raises(ConfigError, match="expected key=value") as info:
        parse_spec(spec)
    assert repr(spec) in str(info.value)


@pytest.mark.parametrize("spec, match", [
    ("nah:max_cells=2,max_cells=4", "'max_cells' is given twice"),
    (":threshold=0.5", "expected a plugin name"),
    ("", "expected a plugin name"),
    (None, "is a string"),
])
def test_parse_spec_rejects_repeats_and_missing_names(spec, match):
    with pytest.raises(ConfigError, match=match):
        parse_spec(spec)
