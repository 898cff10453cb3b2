"""Settings by dotted path (deface/fit/config_values.py): values from params.json and from `--set PATH=VALUE`
checked against their field's type with one-line errors, on a small schema and through FitConfig's entry points
(deface.fit.config's from_dict, set_from_text and override bind them to FitConfig and its RENAMED paths)."""

from __future__ import annotations

from dataclasses import dataclass, field

import pytest

from deface.fit import config_values
from deface.fit.config import FitConfig, from_dict, set_from_text


@dataclass(frozen=True)
class Inner:
    size: int = 3
    """A size."""
    scale: float = 0.5
    """A scale."""


@dataclass(frozen=True)
class Outer:
    name: str = "a"
    """A name."""
    inner: Inner = field(default_factory=Inner)
    """A group."""
    widths: tuple[int, ...] = (1, 2)
    """Widths."""
    limit: int | None = None
    """A limit."""


def test_build_keeps_the_bases_values_for_what_the_dict_leaves_out():
    base = Outer(name="b", inner=Inner(size=7))
    assert config_values.build(base, {"inner": {"scale": 2}}) == Outer(name="b", inner=Inner(size=7, scale=2.0))
    assert config_values.build(base, {"widths": [4], "limit": None}) == Outer(name="b", inner=Inner(size=7),
                                                                               widths=(4,))
    with pytest.raises(ValueError, match="unknown config field 'inner.sise'"):
        config_values.build(base, {"inner": {"sise": 1}})


def test_values_by_dotted_path():
    config = Outer()
    assert config_values.replace_path(config, "inner.size", 9).inner.size == 9
    assert config_values.field_type(Outer, "inner.scale") is float
    assert config_values.flatten(config) == {"name": "a", "inner.size": 3, "inner.scale": 0.5, "widths": (1, 2),
                                             "limit": None}
    assert config_values.differences(Outer(inner=Inner(size=4)), config) == {"inner.size": (4, 3)}
    assert config_values.split_assignment(" inner.size =4") == ("inner.size", "4")
    assert [(path, doc) for path, _, doc in config_values.documentation(Outer)][:2] == [
        ("name", "A name."), ("inner.size", "A size.")]


def test_parse_and_check_by_type():
    assert config_values.parse_value("1, 2,3", tuple[int, ...], "w") == (1, 2, 3)
    assert config_values.parse_value("None", int | None, "x") is None
    assert config_values.parse_value("off", bool, "x") is False
    assert config_values.check_value(2, float, "x") == 2.0 and isinstance(config_values.check_value(2, float, "x"),
                                                                           float)
    assert config_values.check_value([1, 2], tuple[float, float], "x") == (1.0, 2.0)


@pytest.mark.parametrize(("data", "message"), [
    ({"lights": {"num_lightz": 3}}, "unknown config field 'lights.num_lightz'"),
    ({"lights": 3}, "'lights' is a group of settings"),
    ({"resolution": "big"}, "resolution must be an integer"),
    ({"resolution": True}, "resolution must be an integer"),
    ({"decouple": {"hidden": [16, "x"]}}, "decouple.hidden[1] must be an integer"),
    ({"lights": {"init": "mine"}}, "lights.init must be one of paper, code"),
    ({"tone": {"ita_range": [1.0]}}, "tone.ita_range must have 2 values"),
])
def test_a_bad_config_is_a_one_line_error(data, message):
    with pytest.raises(ValueError) as error:
        from_dict(data)
    assert message in str(error.value) and "\n" not in str(error.value)


def test_set_parses_by_the_fields_type():
    config = FitConfig()
    assert set_from_text(config, "decouple.epsilon=0.12").decouple.epsilon == 0.12
    assert set_from_text(config, "lights.num_lights=2").lights.num_lights == 2
    assert set_from_text(config, "render.shadows=off").render.shadows is False
    assert set_from_text(config, "lights.init=code").lights.init == "code"
    assert set_from_text(config, "decouple.hidden=8,8").decouple.hidden == (8, 8)
    assert set_from_text(config, "tone.ita_range=-40,60").tone.ita_range == (-40.0, 60.0)
    assert set_from_text(config, "stage1.rigid_iterations=10").stage1.rigid_iterations == 10
    assert set_from_text(config, "stage1.rigid_iterations=none").stage1.rigid_iterations is None
    assert set_from_text(config, "shadow_rays=16").render.shadow_rays == 16  # an old path
    assert set_from_text(config, "priors.local_prior_weights=1,2,3").priors.local_prior_weights == (1.0, 2.0, 3.0)


@pytest.mark.parametrize(("assignment", "message"), [
    ("decouple.epsilon", "takes PATH=VALUE"),
    ("nothing=1", "the config has no field 'nothing'"),
    ("decouple.nothing=1", "decouple has no field 'nothing'"),
    ("resolution.x=1", "'resolution' is a single value"),
    ("decouple=1", "'decouple' is a group of settings"),
    ("decouple.epsilon=abc", "decouple.epsilon must be a number, got 'abc'"),
    ("lights.num_lights=2.5", "lights.num_lights must be an integer"),
    ("render.shadows=maybe", "render.shadows must be true or false"),
    ("lights.init=mine", "lights.init must be one of paper, code"),
    ("decouple.hidden=", "decouple.hidden takes"),
    ("tone.ita_range=1,2,3", "tone.ita_range takes 2 comma-separated values"),
    ("resolution=none", "resolution must be an integer"),
    ("tone.illuminant.white=1,0,1", "tone.illuminant.white must be positive"),
    ("tone.illuminant.reference_box=0.5,0,0.4,1", "left,top,right,bottom, as fractions"),
    ("tone.illuminant.reference_box=-0.1,0,0.5,1", "left,top,right,bottom, as fractions"),
    ("tone.illuminant.reference_reflectance=0", "reference_reflectance must be in (0, 1]"),
])
def test_set_errors_are_one_line(assignment, message):
    with pytest.raises(ValueError) as error:
        set_from_text(FitConfig(), assignment)
    assert message in str(error.value) and "\n" not in str(error.value)

