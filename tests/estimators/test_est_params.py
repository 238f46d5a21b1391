"""Declared estimator settings: checks, command-line parsing, scikit-learn's get/set_params and clone."""

from __future__ import annotations

import math

import pytest
from click.testing import CliRunner
from hypothesis import given
from hypothesis import strategies as st
from sklearn.base import clone

from psg_data.errors import EstimatorError
from psg_data.estimators import Integral, Options, Pair, Real, get_estimator, get_factory, list_estimators
from psg_data.estimators._params import declared, parse_setting

BUILTINS = [n for n in list_estimators() if get_factory(n).__module__.startswith("psg_data.")]


@pytest.mark.parametrize("name", BUILTINS)
def test_every_builtin_declares_every_setting(name: str) -> None:
    factory = get_factory(name)
    names = factory._param_names()
    assert set(declared(factory)) == set(names), f"{name}: undeclared {set(names) - set(declared(factory))}"
    est = factory()
    est.validate_params()  # the defaults are allowed


@pytest.mark.parametrize("name", BUILTINS)
def test_clone_and_params_round_trip(name: str) -> None:
    est = get_estimator(name)
    params = est.get_params(deep=True)
    twin = clone(est)
    assert type(twin) is type(est) and twin is not est
    assert twin.get_params(deep=False).keys() == params.keys()
    for k, v in params.items():
        assert twin.get_params()[k] == v or (isinstance(v, float) and math.isnan(v))


def test_set_params_checks_and_returns_self() -> None:
    est = get_estimator("perpetua_star")
    assert est.set_params(gamma=0.5, prior="none") is est
    assert est.gamma == 0.5 and est.prior == "none"
    assert repr(est) == "PerpetuaStarEstimator(prior='none', gamma=0.5)"
    with pytest.raises(EstimatorError, match=r"gamma must be a number in \[0, 1\] or none, got 1.5"):
        est.set_params(gamma=1.5)
    assert est.gamma == 0.5  # unchanged after a refused call
    with pytest.raises(EstimatorError, match="unknown setting 'gama'; valid settings: prior, gamma"):
        est.set_params(gama=0.5)
    with pytest.raises(EstimatorError, match="max_components must be an integer in"):
        get_estimator("perpetua_star", max_components=2.5)


def test_params_validated_at_construction_through_the_registry() -> None:
    with pytest.raises(EstimatorError, match="delta_low must be a number in"):
        get_estimator("perpetua", delta_low=0.0)
    with pytest.raises(EstimatorError, match="survival must be one of exponential"):
        get_estimator("persistence_filter", survival="gamma")


@given(st.floats(allow_nan=True, allow_infinity=True), st.floats(-10, 10), st.floats(-10, 10),
       st.sampled_from(["both", "left", "right", "neither"]))
def test_real_check_equals_interval_arithmetic(v: float, a: float, b: float, closed: str) -> None:
    lo, hi = min(a, b), max(a, b)
    p = Real(lo, hi, closed=closed)
    lo_ok = v > lo or (v == lo and closed in ("both", "left"))
    hi_ok = v < hi or (v == hi and closed in ("both", "right"))
    assert p.is_valid(v) == (not math.isnan(v) and lo_ok and hi_ok)
    text_ok = p.is_valid(float(repr(v))) if not math.isnan(v) else False
    if text_ok:
        assert p.parse("e", "x", repr(v)) == v
    else:
        with pytest.raises(EstimatorError, match="x must be a number"):
            p.parse("e", "x", repr(v))


def test_parse_kinds() -> None:
    assert Integral(1, None).parse("e", "k", "3") == 3
    with pytest.raises(EstimatorError, match="k must be an integer >= 1, got '2.5'"):
        Integral(1, None).parse("e", "k", "2.5")
    assert Real(0, 1, none_ok=True).parse("e", "p", "none") is None
    assert Options("a", "b").parse("e", "o", "b") == "b"
    assert Pair().parse("e", "s", "1.5/2") == (1.5, 2.0)
    with pytest.raises(EstimatorError, match="unknown setting 'z'; valid settings: a"):
        parse_setting("e", {}, "z", "1", ["a"])
    assert parse_setting("plugin", {}, "z", "[1, 2]", None) == [1, 2]  # undeclared: Python literal
    assert parse_setting("plugin", {}, "z", "abc", None) == "abc"


@pytest.mark.parametrize("spec, message", [
    ("perpetua_star:gamma=abc", "gamma must be a number in [0, 1] or none, got 'abc'"),
    ("perpetua_star:gamma=1.5", "gamma must be a number in [0, 1] or none, got 1.5"),
    ("perpetua_star:", "no settings after ':'"),
    ("perpetua_star:bogus=1", "unknown setting 'bogus'"),
])
def test_cli_rejects_bad_settings_before_any_work(tmp_path, monkeypatch, spec: str, message: str) -> None:
    import psg_data.datasets
    from psg_data.cli.psg_eval_cmd import main

    def no_data(*args: object, **kwargs: object) -> None:
        raise AssertionError("the dataset was touched before the settings were checked")

    monkeypatch.setattr(psg_data.datasets, "demo", no_data)
    monkeypatch.chdir(tmp_path)
    r = CliRunner().invoke(main, ["-e", spec, "--out", str(tmp_path / "res")])
    assert r.exit_code == 1, r.output
    lines = r.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and message in lines[0], r.output
    assert list(tmp_path.iterdir()) == [], "nothing may be written"
