"""Hypothesis profiles for the fuzz tests.

The default run is short and repeatable (``raysort``: a few dozen examples per
test, derandomised, no example database).  For a long search:

    pytest tests/fuzz --hypothesis-profile=long

(``long``: 2,000 examples per test, random, failures kept in .hypothesis/).
"""
from hypothesis import HealthCheck, settings

settings.register_profile("raysort", max_examples=30, deadline=None, derandomize=True,
                          database=None, suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("long", max_examples=2000, deadline=None,
                          suppress_health_check=[HealthCheck.too_slow])


def pytest_configure(config):
    if not config.getoption("hypothesis_profile", None):
        settings.load_profile("raysort")
