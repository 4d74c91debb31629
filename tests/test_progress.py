"""raysort.progress: the tqdm bar of the command-line apps and the render callback protocol."""
import io

import raysort
from raysort.progress import Progress, with_rays


class Terminal(io.StringIO):
    """A stream that says it is a terminal."""

    def isatty(self):
        return True


def test_bar_on_a_terminal_shows_count_rate_and_mrays():
    stream = Terminal()
    progress = Progress("render plane", unit="tile", stream=stream)
    for done in (1, 2, 3):
        progress(done, 3, rays=done * 1_000_000)
    text = stream.getvalue()
    assert "render plane" in text and "3/3" in text and "tile/s" in text
    assert "Mrays/s" in text
    assert text.endswith("\n")          # a finished bar stays, on its own line


def test_quiet_when_not_a_terminal_or_disabled():
    piped = io.StringIO()
    Progress("render", stream=piped)(1, 1, rays=5)
    muted = Terminal()
    Progress("render", stream=muted, enabled=False)(1, 1)
    assert piped.getvalue() == "" and muted.getvalue() == ""


def test_with_rays_passes_rays_only_to_callbacks_that_take_them():
    seen = []
    plain = with_rays(lambda done, total: seen.append((done, total)), lambda: 7)
    plain(1, 2)
    counting = with_rays(lambda done, total, rays: seen.append((done, total, rays)), lambda: 7)
    counting(2, 2)
    assert seen == [(1, 2), (2, 2, 7)]
    assert with_rays(None, lambda: 0) is None
    assert with_rays(print, lambda: 0) is print


def test_render_reports_tiles_and_the_rays_traced():
    """A render calls back once per tile; the last call's rays are the render's total."""
    calls = []
    pipe = raysort.Pipeline("plane", tile=8)
    result = pipe.render(16, 12, spp=1, progress=lambda done, total, rays: calls.append(
        (done, total, rays)))
    assert [c[:2] for c in calls] == [(k, 4) for k in range(1, 5)]
    assert [c[2] for c in calls] == sorted(c[2] for c in calls)
    assert calls[-1][2] == result.stats.total_rays == 2 * 16 * 12
