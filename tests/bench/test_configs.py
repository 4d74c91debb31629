"""raysort.bench.configs: configurations are data, expanded against what is installed."""
import pytest

import raysort
from raysort.bench.configs import Config, Table, load_table, select
from raysort.errors import ConfigError, UnknownPluginError
from raysort.sdk import Counters, Traversal


class Extra(Traversal):
    """An in-process traversal standing in for an installed plugin."""

    def intersect(self, bvh, packets, any_hit=False):
        return Counters()


@pytest.fixture
def extra():
    raysort.register("traversals", "bench_extra", Extra)
    yield "bench_extra"
    raysort.unregister("traversals", "bench_extra")


def test_default_table_starts_with_the_papers_configurations():
    table = load_table()
    labels = [c.label for c in table.frame_configs()]
    assert labels[:3] == ["ranged (8x8)", "partition (32x32)", "ranged + nah"]
    assert {c.baseline for c in table.frame_configs()} == {"ranged (8x8)"}
    assert [c.paper for c in table.configs[:3]] == [
        "Ranged w/o sorting [2]", "Partition w/o sorting [7]", "Ranged w/ sorting (ours)"]


def test_every_installed_traversal_is_picked_up(extra):
    configs = load_table().frame_configs()
    used = {str(c.traversal) if not isinstance(c.traversal, dict) else c.traversal["type"]
            for c in configs}
    assert set(raysort.available("traversals")) <= used
    labels = [c.label for c in configs]
    assert "bench_extra" in labels and "bench_extra + nah" in labels


def test_named_traversals_only_and_named_sorters(extra):
    table = load_table()
    labels = [c.label for c in table.frame_configs(traversals=["bench_extra"])]
    assert "bench_extra" in labels and "single" not in labels
    labels = [c.label for c in table.frame_configs(sorters=["nah_numpy"])]
    assert "ranged + nah_numpy" in labels


def test_matrix_is_every_sorter_by_every_traversal_over_the_unsorted_one():
    configs = load_table().frame_configs(["all"], ["all"])
    sorters, travs = raysort.available("sorters"), raysort.available("traversals")
    assert len(configs) == len(sorters) * len(travs)
    by_label = {c.label: c for c in configs}
    for t in travs:
        for s in sorters:
            assert by_label[f"{t} + {s}"].baseline == f"{t} + none"
            assert (by_label[f"{t} + {s}"].row, by_label[f"{t} + {s}"].column) == (t, s)


def test_kernel_configs_are_traversals_by_packet_layouts(extra):
    configs = load_table().kernel_configs()
    cols = {c.column for c in configs}
    assert cols == {"8x8", "32x32", "nah"}
    assert {c.row for c in configs} == set(raysort.available("traversals"))
    assert configs[0].baseline == "ranged / 8x8"


def test_a_file_replaces_and_adds_configurations(tmp_path):
    path = tmp_path / "mine.toml"
    path.write_text('[[config]]\nlabel = "ranged + nah"\ntraversal = "masked"\n'
                    'sorter = "nah"\n\n[[config]]\nlabel = "mine"\ntraversal = "single"\n'
                    'sorter = "none:packet_size=16"\n')
    table = load_table([path], [("added", "wide", "nah")])
    by_label = {c.label: c for c in table.configs}
    assert by_label["ranged + nah"].traversal == "masked"
    assert by_label["mine"].sorter == "none:packet_size=16"
    assert by_label["added"].traversal == "wide"
    labels = [c.label for c in table.frame_configs()]
    assert labels.index("ranged + nah") == 2          # replaced in place


def test_bad_files_and_entries_are_config_errors(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[[config]\n")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_table([bad])
    with pytest.raises(ConfigError, match="missing 'sorter'"):
        Table({"config": [{"label": "x", "traversal": "single"}]})
    with pytest.raises(ConfigError, match="bad.toml"):
        load_table([tmp_path / "missing" / "bad.toml"])
    with pytest.raises(UnknownPluginError, match="no_such_traversal"):
        load_table().frame_configs(traversals=["no_such_traversal"])


def test_select_keeps_the_given_order_and_names_unknown_labels():
    configs = [Config("a", "single", "none"), Config("b", "single", "nah")]
    assert [c.label for c in select(configs, ["b", "a"])] == ["b", "a"]
    with pytest.raises(ConfigError, match="unknown configuration 'c'; known: a, b"):
        select(configs, ["c"])


def write(tmp_path, text):
    path = tmp_path / "mine.toml"
    path.write_text(text)
    return path


@pytest.mark.parametrize("text, problem", [
    ("config = [1]\n", "'config' must be an array of tables"),
    ("config = 'x'\n", "'config' must be an array of tables"),
    ("each_traversal = 3\n", "'each_traversal' must be an array of tables"),
    ("render = 3\n", "'render' must be a table"),
    ("render = 'abc'\n", "'render' must be a table"),
    ("matrix = 3\n", "'matrix' must be a table"),
    ("[render]\nshader = 3\n", "[render]: 'shader' must be a name"),
    ("[render]\ndepth_parameter = 3\n", "[render]: 'depth_parameter' must be a string"),
    ("[render]\ncompare = 'xy'\n", "[render]: 'compare' must be an array of [label, over"),
    ("[render]\ncompare = [['a', 'b', 'c']]\n", "'compare' must be an array of [label, over"),
    ("[kernels]\npackets = 3\n", "[kernels]: 'packets' must be a table"),
    ("[kernels.packets]\nx = 3\n", "[kernels.packets]: 'x' must be a name"),
    ("[kernels]\nworkloads = 'primary'\n", "'workloads' must be an array of workload kinds"),
    ("[[config]]\nlabel = {a = 1}\ntraversal = 'ranged'\nsorter = 'none'\n",
     "[[config]]: 'label' must be a string"),
    ("[[config]]\nlabel = 'a'\ntraversal = 3\nsorter = 'none'\n",
     "[[config]] 'a': 'traversal' must be a name"),
    ("[[config]]\nlabel = 'a'\ntraversal = 'ranged'\nsorter = {packet_size = 3}\n",
     "[[config]] 'a': 'sorter' must be a name"),
    ("[[config]]\nlabel = 'a'\ntraversal = 'ranged'\nsorter = 'none:packet_size'\n",
     "[[config]] 'a': 'sorter': cannot read 'packet_size'"),
    ("[[each_traversal]]\nlabel = '{traversal} x'\n",
     "[[each_traversal]] '{traversal} x': missing 'sorter'"),
    ("[[configs]]\nlabel = 'a'\n", "unknown key 'configs'"),
    ("[render]\nbasline = 'a'\n", "[render]: unknown key 'basline'"),
])
def test_wrongly_typed_tables_are_config_errors_naming_the_file(tmp_path, text, problem):
    with pytest.raises(ConfigError) as info:
        load_table([write(tmp_path, text)])
    message = str(info.value)
    assert message.startswith(f"--configs {str(tmp_path / 'mine.toml')!r}")
    assert problem in message and "\n" not in message


@pytest.mark.parametrize("text, problem", [
    ("[[each_traversal]]\nlabel = '{foo}'\nsorter = 'none'\n",
     "[[each_traversal]]: label '{foo}' is not a valid template (unknown placeholder {foo})"),
    ("[[each_traversal]]\nlabel = '{'\nsorter = 'none'\n",
     ("label '{' is not a valid template (Single '{' encountered in format string); it may "
      "use {traversal}")),
    ("[[each_sorter]]\nlabel = 'x + {traversal}'\ntraversal = 'ranged'\n",
     "unknown placeholder {traversal}); it may use {sorter}"),
    ("[matrix]\nlabel = '{foo}'\n", "[matrix]: label '{foo}' is not a valid template"),
    ("[matrix]\nlabel = '{0}'\n", "(a placeholder without a name); it may use {traversal}"),
    ("[matrix]\nlabel = '{traversal.x}'\n", "[matrix]: label '{traversal.x}' is not a valid"),
    ("[kernels]\nlabel = '{x}'\n", "it may use {traversal} and {packets}"),
])
def test_label_templates_are_checked_when_the_file_is_read(tmp_path, text, problem):
    with pytest.raises(ConfigError, match="mine.toml") as info:
        load_table([write(tmp_path, text)])
    assert problem in str(info.value)


def test_kernels_packets_error_names_the_file_it_came_from(tmp_path):
    with pytest.raises(ConfigError, match=r"mine\.toml'?: \[kernels.packets\] names no packet"):
        load_table([write(tmp_path, "[kernels]\npackets = {}\n")]).kernel_configs()


def test_shader_may_be_a_spec_string(tmp_path):
    table = load_table([write(tmp_path, "[render]\nshader = 'ao:samples=2'\n")])
    assert table.render["shader"] == {"type": "ao", "samples": 2}
    assert table.where("render.shader") == f"--configs {str(tmp_path / 'mine.toml')!r}"
    assert table.where("render.baseline") == "configs.toml"


def test_unreadable_toml_is_a_config_error(tmp_path):
    path = tmp_path / "mine.toml"
    path.write_bytes(b"label = '\xff'\n")
    with pytest.raises(ConfigError, match="not valid TOML .not UTF-8 text."):
        load_table([path])
    path.write_text("a = " + "[" * 5000 + "]" * 5000 + "\n")
    with pytest.raises(ConfigError, match="not valid TOML .nested too deeply."):
        load_table([path])
