"""How RenderResult and RenderStats show themselves: Jupyter's PNG and HTML, and repr."""
import io
from html.parser import HTMLParser

import numpy as np
import pytest
from PIL import Image

import raysort
from raysort import output
from raysort.pipeline import RenderStats
from raysort.stats import COUNTER_LABELS, Counters


@pytest.fixture(scope="module")
def result():
    return raysort.Pipeline("cornell", traversal="ranged").render(24, 16, spp=1)


def test_result_displays_as_its_tone_mapped_png(result):
    data = result._repr_png_()
    with Image.open(io.BytesIO(data)) as picture:
        assert picture.format == "PNG" and picture.size == (24, 16)
        pixels = np.asarray(picture.convert("RGB"))
    assert np.array_equal(pixels, output.tone_map(result.image))
    assert pixels.any()


def test_result_repr_is_one_line_without_pixels(result):
    text = repr(result)
    assert "\n" not in text and "cornell" in text and "24x16" in text and "1 spp" in text
    assert f"{result.stats.mrays_per_second:.3f} Mrays/s" in text


def test_stats_repr_shows_time_rate_stage_shares_and_counters(result):
    stats = result.stats
    text = repr(stats)
    assert f"{stats.wall_seconds:.3f} s wall" in text
    assert f"{stats.mrays_per_second:.3f} Mrays/s" in text
    assert f"{stats.total_rays:,}" in text
    shares = stats.stage_shares()
    assert abs(sum(shares.values()) - 1) < 1e-9 and list(shares.values()) == sorted(
        shares.values(), reverse=True)
    for stage, share in shares.items():
        assert f"{stage} {share:.0%}" in text
    per_ray = stats.closest_hit_counters().per_ray()
    for key, label in COUNTER_LABELS.items():
        assert f"{label} {per_ray[key]:.2f}" in text


class _Table(HTMLParser):
    def __init__(self):
        super().__init__()
        self.cells, self.tags = [], []

    def handle_starttag(self, tag, attrs):
        self.tags.append(tag)

    def handle_data(self, data):
        self.cells.append(data)


def test_stats_html_is_a_table_of_the_same_rows(result):
    html = result.stats._repr_html_()
    parser = _Table()
    parser.feed(html)
    assert parser.tags.count("table") == 1 and parser.tags.count("tr") == 5
    rows = dict(zip(parser.cells[1::2], parser.cells[2::2]))
    assert rows["throughput"] == f"{result.stats.mrays_per_second:.3f} Mrays/s"
    assert set(rows) == {"time", "throughput", "rays", "stages", "work per ray"}


def test_stats_without_counters_or_stages():
    stats = RenderStats(wall_seconds=1.0, rays={0: 10}, counters={0: Counters(
        rays=10, available=False)})
    text = repr(stats)
    assert "not counted" in text and "stages:       none" in text
