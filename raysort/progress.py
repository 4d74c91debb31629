"""Progress bars for the command-line apps, drawn by tqdm.

A :class:`Progress` is the ``progress`` callback of :meth:`raysort.Pipeline.render`
and of ``raysort bench``: called as ``progress(done, total)`` (and, by a render,
with ``rays=`` the rays traced so far), it shows a bar with the rate, the
elapsed and remaining time and, for renders, Mrays/s.  It draws only on a
terminal: piped or redirected output stays clean.
"""
from __future__ import annotations

import inspect
import sys
import time

__all__ = ["Progress", "with_rays"]


class Progress:
    """A tqdm bar on stderr, drawn only when the stream is a terminal.

    Parameters
    ----------
    label : str
        Text before the bar (e.g. ``"render sibenik"``).
    unit : str
        What ``done`` and ``total`` count (``"tile"``, ``"run"``; tqdm's ``"it"``).
    stream : file, optional
        Where to draw (default: ``sys.stderr`` when the bar is made).
    enabled : bool
        False draws nothing (``-q``).
    """

    def __init__(self, label, *, unit="it", stream=None, enabled=True):
        self.label, self.unit, self.enabled = label, unit, enabled
        self.stream = sys.stderr if stream is None else stream
        self.bar = None
        self.start = time.perf_counter()

    def __call__(self, done, total, rays=None):
        if self.bar is None:
            from tqdm import tqdm

            # disable=None: tqdm draws only if the stream is a terminal
            self.bar = tqdm(total=total, desc=self.label, unit=self.unit, file=self.stream,
                            disable=None if self.enabled else True, dynamic_ncols=True)
        if rays is not None:
            elapsed = max(time.perf_counter() - self.start, 1e-9)
            self.bar.set_postfix_str(f"{rays / elapsed / 1e6:.2f} Mrays/s", refresh=False)
        self.bar.update(done - self.bar.n)
        if done >= total:
            self.close()

    def close(self):
        """End the bar (a finished bar stays on screen)."""
        if self.bar is not None:
            self.bar.close()


def with_rays(callback, count):
    """``callback`` as a ``(done, total)`` callable that also passes ``rays=count()``
    when ``callback`` takes a ``rays`` argument (as :class:`Progress` does)."""
    if callback is None:
        return None
    try:
        takes_rays = "rays" in inspect.signature(callback).parameters
    except (TypeError, ValueError):  # a builtin without a signature
        takes_rays = False
    if not takes_rays:
        return callback
    return lambda done, total: callback(done, total, rays=count())
