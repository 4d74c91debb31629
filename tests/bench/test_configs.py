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
