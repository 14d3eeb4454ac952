"""The validation layer: number checks, TOML lines, pydantic errors as one message."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from pydantic import ValidationError

import formationlab as fl
from formationlab.errors import ParameterError, ScenarioError
from formationlab.validation import (
    build_dataclass,
    check_fields,
    fraction,
    line_of,
    nonnegative,
    number,
    one_of,
    positive,
    seed,
    whole,
)


@pytest.mark.parametrize("good", [2, 2.5, np.float64(1e-300), np.int64(7)])
def test_positive_accepts_finite_numbers_above_zero(good):
    assert positive(good, "k") == float(good) and isinstance(positive(good, "k"), float)


@pytest.mark.parametrize("bad", [0, -1.0, float("nan"), float("inf"), True, "2", None])
def test_positive_refuses_with_the_key_and_the_value(bad):
    with pytest.raises(ParameterError) as info:
        positive(bad, "k_c", owner="DistanceLaw")
    assert str(info.value) == f"DistanceLaw.k_c must be a finite number > 0, got {bad!r}"
    assert info.value.key == "k_c"


def test_nonnegative_whole_fraction_one_of():
    assert nonnegative(0, "k_a") == 0.0
    with pytest.raises(ParameterError, match=r"k_a must be a finite number >= 0, got -1e-09"):
        nonnegative(-1e-9, "k_a")
    assert whole(np.int32(3), "n") == 3 and whole(0, "n", minimum=0) == 0
    for bad in (0, 2.0, True):
        with pytest.raises(ParameterError, match="must be an integer >= 1"):
            whole(bad, "n")
    assert fraction(1, "p") == 1.0
    with pytest.raises(ParameterError, match=r"must be in \[0, 1\], got 1.5"):
        fraction(1.5, "p")
    assert one_of("RK45", "method", ("RK45", "DOP853")) == "RK45"
    with pytest.raises(ParameterError, match=r"got 'DOP835'; did you mean 'DOP853'\?"):
        one_of("DOP835", "method", ("RK45", "DOP853"))


def test_check_fields_names_the_class():
    @dataclasses.dataclass(frozen=True)
    class Gains:
        a: float = 1.0
        b: float = 0.0
        n: int = 1

        def __post_init__(self) -> None:
            check_fields(self, positive=("a",), nonnegative=("b",), whole=("n",))

    Gains()
    with pytest.raises(ParameterError, match=r"^Gains\.b must be a finite number >= 0"):
        Gains(b=-1.0)
    with pytest.raises(ParameterError, match=r"^Gains\.n must be an integer >= 1, got 0$"):
        Gains(n=0)


TOML = """\
name = "x"
simulation.dt = 1e-3
[controller]
law = "distance"
repulsion = { eta = 1.0, s0 = 0.5 }
[study]
trials = 10
[study.sweep]
kA = [1.0, 2.0]
"""


@pytest.mark.parametrize(
    ("key", "line"),
    [
        ("name", 1),
        ("simulation.dt", 2),
        ("controller", 3),
        ("controller.law", 4),
        ("controller.repulsion.s0", 5),
        ("study.trials", 7),
        ("study.sweep", 8),
        ("study.sweep.kA", 9),
        ("study.nope", 6),
        ("equilibria", None),
    ],
)
def test_line_of_finds_the_deepest_match(key, line):
    assert line_of(TOML, key) == line


def test_build_dataclass_is_strict_and_builds_nested_tables():
    law = build_dataclass(fl.AngleRestrictedLaw, {"k_c": 4, "repulsion": {"eta": 2.5}})
    assert law == fl.AngleRestrictedLaw(k_c=4.0, repulsion=fl.Repulsion(eta=2.5))
    assert isinstance(law.k_c, float)
    for bad, kind in (({"k_c": "2"}, "float_type"), ({"k_c": True}, "float_type"),
                      ({"k_c": float("nan")}, "finite_number"),
                      ({"repulsion": 3}, "model_type")):  # fmt: skip
        with pytest.raises(ValidationError) as info:
            build_dataclass(fl.AngleRestrictedLaw, bad)
        assert info.value.errors()[0]["type"] == kind
    with pytest.raises(ValidationError, match="int_type"):
        build_dataclass(fl.ImplicitEuler, {"max_surfaces": 3.0})
    with pytest.raises(ParameterError) as err:  # the class's own check, key made dotted
        build_dataclass(fl.DistanceLaw, {"repulsion": {"eta": -1.0}})
    assert err.value.key == "repulsion.eta"


def test_number_bounds_infinity_and_seed():
    assert number(float("inf"), "range", low=0.0, strict=True, allow_inf=True) == float("inf")
    assert number(0.0, "drop", low=0.0, strict=False, below=1.0) == 0.0
    cases = [
        (dict(low=0.0, strict=True, allow_inf=True), float("nan"), "r must be a number > 0"),
        (dict(low=0.0, strict=True), float("inf"), "r must be a finite number > 0"),
        (dict(low=0.0, strict=False, below=1.0), 1.0, r"r must be a finite number in \[0, 1\)"),
        (dict(low=2.0, strict=False), 1.5, "r must be a finite number >= 2"),
    ]
    for kw, bad, msg in cases:
        with pytest.raises(ParameterError, match=msg) as info:
            number(bad, "r", **kw)
        assert info.value.key == "r"
    assert seed(np.uint32(7)) == 7 and seed(2**63 - 1) == 2**63 - 1
    for bad in (-1, 2**63, 1.0, True, None):
        with pytest.raises(ParameterError, match=r"s must be a whole number in \[0, 2\*\*63\)"):
            seed(bad, "s")


@pytest.mark.parametrize(
    ("line", "key"),
    [
        ("gamma = -1.0", "safety.gamma"),
        ("max_speed = 0.0", "safety.max_speed"),
        ("speed_sides = 3", "safety.speed_sides"),
        ("sensing_radius = 0.25", "safety.sensing_radius"),
        ("distance = 0.1", "safety.distance"),
        ("obstacle_distance = 0.05", "safety.obstacle_distance"),
    ],
)
def test_safety_errors_carry_their_key(line, key):
    from formationlab.scenario import parse_scenario

    text = (
        "[robots]\npositions = [[-3.0, -3.0], [3.0, -3.0], [0.0, 3.0]]\ndiameters = 0.2\n"
        "[formation]\ndistances = 1.0\n"
        '[controller]\nlaw = "distance"\n'
        "[simulation]\nduration = 1.0\n"
        '[safety]\nfilter = "barrier"\n'
        + ("" if line.startswith("distance") else "distance = 0.3\n")
        + line
        + "\n"
    )
    with pytest.raises(ScenarioError) as info:
        parse_scenario(text, source="t.toml")
    assert info.value.key == key
    assert str(info.value).startswith(f"t.toml: {key} (line ")


def test_scenario_errors_carry_their_key_and_line():
    from formationlab.scenario import parse_scenario

    text = (
        "[robots]\npositions = [[-3.0, -3.0], [3.0, -3.0], [0.0, 3.0]]\n"
        "[formation]\ndistances = 1.0\n"
        '[controller]\nlaw = "distance"\nk_c = -2.0\nrepulsion = { eta = "1" }\n'
        "[simulation]\nduration = 1.0\n"
    )
    with pytest.raises(ScenarioError) as info:
        parse_scenario(text, source="t.toml")
    assert info.value.key == "controller.repulsion.eta"
    assert str(info.value) == (
        "t.toml: controller.repulsion.eta (line 8): expected a number, got '1'"
    )
    with pytest.raises(ScenarioError) as info:
        parse_scenario(text.replace('eta = "1"', "eta = 1"), source="t.toml")
    assert info.value.key == "controller.k_c"
    assert str(info.value).startswith("t.toml: controller.k_c (line 7): DistanceLaw.k_c must be")
