"""The shared parameter checks (raysort.params, also in the SDK)."""
import pytest

import raysort
from raysort.errors import ConfigError
from raysort.params import choice


def test_choice_takes_one_of_the_options():
    assert choice("order", "votes", ("votes", "direction")) == "votes"


@pytest.mark.parametrize("value", ["nope", "", [], {}, None, 3, b"votes"])
def test_choice_names_the_parameter_and_the_options(value):
    with pytest.raises(ConfigError, match=r"order must be one of votes, direction; got"):
        choice("order", value, ("votes", "direction"))


@pytest.mark.parametrize("kind, name, params", [
    ("traversals", "stream", {"order": []}),
    ("sorters", "origin_direction", {"layout": []}),
    ("sorters", "origin_direction", {"layout": {"a": 1}}),
])
def test_string_parameters_of_another_type_are_config_errors(kind, name, params):
    with pytest.raises(ConfigError, match="must be one of"):
        raysort.create(kind, {"type": name, **params})
