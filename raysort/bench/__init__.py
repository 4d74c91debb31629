"""``raysort bench``: the paper's experiment and the traversal kernels, measured honestly.

================  ===========================================================
module            what it holds
================  ===========================================================
``rounds``        the timing method: warm-up, shuffled rounds, medians, ratios
``configs``       the configurations, read from ``configs.toml`` (data)
``frame``         whole frames (the paper's Fig. 2 and Table I)
``kernels``       traversal alone on the rays of a render (``--kernels``)
``report``        the JSON record, text tables and charts
``command``       the command line
================  ===========================================================
"""
from raysort.bench.command import PAPER_SCENES, add_parser, cmd_bench
from raysort.bench.configs import Config, load_table
from raysort.bench.report import machine_info

__all__ = ["add_parser", "cmd_bench", "Config", "load_table", "machine_info", "PAPER_SCENES"]
