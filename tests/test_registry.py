"""Registries of laws and integrators, and names accepted wherever objects are."""

from __future__ import annotations

import dataclasses
import warnings
from typing import ClassVar

import numpy as np
import pytest

import formationlab as fl
from formationlab.errors import IgnoredKeyWarning, ParameterError, UnknownNameError
from formationlab.registry import Registry, resolve

TRIANGLE = fl.Formation.from_distances(3, distances=1.0, diameters=0.2)
Q0 = [[-3.0, -3.0], [3.0, -3.0], [0.0, 3.0]]


@dataclasses.dataclass(frozen=True, kw_only=True)
class Slow:
    name: ClassVar[str] = "slow"
    rate: float = 1.0


@dataclasses.dataclass(frozen=True, kw_only=True)
class Fast:
    name: ClassVar[str] = "Fast-Mode"
    rate: float = 2.0
    boost: int = 3


def small_registry() -> Registry[object]:
    r: Registry[object] = Registry("mode")
    r.register(Slow)
    r.register(Fast)
    return r


def test_a_registry_is_a_read_only_mapping_with_case_insensitive_lookup():
    r = small_registry()
    assert sorted(r) == list(r) == ["Fast-Mode", "slow"] and r.names() == ("Fast-Mode", "slow")
    assert len(r) == 2 and dict(r) == {"Fast-Mode": Fast, "slow": Slow}
    assert r["fast-mode"] is Fast and r["SLOW"] is Slow and r.canonical("FAST-mode") == "Fast-Mode"
    assert "fast-MODE" in r and "medium" not in r and 3 not in r
    assert r.get("nope") is None  # Mapping.get: an unknown name is a KeyError inside
    assert r.owners("rate") == ("Fast-Mode", "slow") and r.owners("boost") == ("Fast-Mode",)
    del r["SLOW"]
    assert list(r) == ["Fast-Mode"]


def test_unknown_names_suggest_the_nearest_and_list_the_known():
    with pytest.raises(UnknownNameError) as info:
        fl.INTEGRATORS["rk5"]
    assert str(info.value) == (
        "unknown integrator 'rk5'; did you mean 'rk4'? Known: euler, filippov, implicit-euler, rk4"
    )
    assert isinstance(info.value, KeyError) and isinstance(info.value, ParameterError)
    with pytest.raises(
        UnknownNameError,
        match=r"'xyz'\. Known: angle-restricted, bearing, chirality-restricted, distance",
    ):
        fl.get_law("xyz")


def test_register_refuses_nameless_classes_and_names_that_differ_only_in_case():
    r = small_registry()

    class Nameless:
        pass

    with pytest.raises(TypeError, match="has no name"):
        r.register(Nameless)

    @dataclasses.dataclass(frozen=True)
    class Shouting:
        name: ClassVar[str] = "SLOW"

    with pytest.raises(TypeError, match="only in case"):
        r.register(Shouting)


def test_build_ignores_keys_of_other_entries_with_a_warning_and_refuses_unknown_ones():
    r = small_registry()
    with pytest.warns(IgnoredKeyWarning, match=r"^boost has no effect: it is not a parameter"):
        assert r.build("slow", rate=5.0, boost=1) == Slow(rate=5.0)
    with pytest.raises(ParameterError, match=r"takes no parameter 'rat'; did you mean 'rate'\?"):
        r.build("slow", rat=5.0)
    with pytest.raises(ParameterError) as info:
        r.build("fast-mode", zzz=1)
    assert info.value.key == "zzz" and "It takes: rate, boost" in str(info.value)


def test_get_integrator_filippov_with_dt_warns_instead_of_failing():
    with pytest.warns(IgnoredKeyWarning, match="dt has no effect.*'filippov'"):
        assert fl.get_integrator("Filippov", dt=1e-3, rtol=1e-8) == fl.Filippov(rtol=1e-8)
    with pytest.raises(ParameterError, match="did you mean 'rtol'"):
        fl.get_integrator("filippov", rtoll=1e-8)


def test_simulate_takes_names_wherever_it_takes_objects():
    by_name = fl.simulate(TRIANGLE, "distance", Q0, duration=0.2, integrator="RK4")
    by_object = fl.simulate(TRIANGLE, fl.DistanceLaw(), Q0, duration=0.2, integrator=fl.RK4())
    assert by_name.integrator == fl.RK4() and by_name.law == fl.DistanceLaw()
    np.testing.assert_array_equal(by_name.q, by_object.q)
    with pytest.raises(UnknownNameError, match="did you mean 'euler'"):
        fl.simulate(TRIANGLE, "distance", Q0, duration=0.2, integrator="eulr")


def test_resolve_passes_objects_through_and_builds_names():
    law = fl.DistanceLaw(k_c=3.0)
    assert resolve(fl.LAWS, law) is law
    assert resolve(fl.LAWS, "distance", k_c=3.0) == law
    with pytest.raises(ParameterError, match="already built"):
        resolve(fl.LAWS, law, k_c=1.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a name with its own parameters does not warn
        assert resolve(fl.INTEGRATORS, "euler", dt=0.5) == fl.Euler(dt=0.5)
