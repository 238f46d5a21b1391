"""Tests written by the audit of bench/mutation_equivalent.txt (docs/TESTING.md, "Audit of the
equivalents"): each pins behaviour that a mutant listed as equivalent changed, against an
independent reference (zoneinfo, a brute-force emission table, the documented state format).
"""

from __future__ import annotations

import datetime as dt
import json
import math
import warnings
import zoneinfo
from typing import Any

import numpy as np
import pytest

import psg_data.estimators._fremen as fremen
from psg_data.estimators import EdgeStream, MixtureFilter, get_estimator
from psg_data.estimators._hmm import _batch, _log_emissions
from psg_data.estimators._survival import SurvivalMixture
from tests.estimators.test_process_oracle import _streams
from tests.synth.test_process_exact import tiny_process

# pandas' datetime64[ns] range ends at 2262-04-11 23:47:16.854775807 UTC
_PANDAS_END_S = 9223372036.854775807


@pytest.mark.parametrize("days_before_end", [400.25, 400.5, 400.875])
@pytest.mark.parametrize("zone", ["Europe/Berlin", "Asia/Kolkata"])
def test_wall_seconds_near_the_end_of_pandas_range_match_zoneinfo(monkeypatch: pytest.MonkeyPatch,
                                                                  days_before_end: float, zone: str) -> None:
    """A time 400-401 days before the end of pandas' range (March 2261), on an empty offset cache:
    t + the zone's UTC offset from zoneinfo (the offset table's end margin must stay inside the range).
    """
    monkeypatch.setattr(fremen, "_OFFSET_TABLES", {})
    t = math.floor(_PANDAS_END_S - days_before_end * 86400.0)
    ref = dt.datetime.fromtimestamp(t, zoneinfo.ZoneInfo(zone)).utcoffset()
    assert ref is not None
    got = fremen.wall_seconds(np.array([t, t - 86400.0 * 30]), zone)
    ref_early = dt.datetime.fromtimestamp(t - 86400.0 * 30, zoneinfo.ZoneInfo(zone)).utcoffset()
    assert ref_early is not None
    np.testing.assert_array_equal(got, [t + ref.total_seconds(), t - 86400.0 * 30 + ref_early.total_seconds()])


@pytest.mark.parametrize("family", ["lognormal", "exponential", "loglogistic"])
def test_mixture_step_returns_a_probability_for_a_nan_time(family: str) -> None:
    """MixtureFilter does not validate times (the estimators' filters do): a NaN time makes the
    log evidence NaN, but p_own, a probability, stays in [0, 1] (min(exp(p), 1) with p NaN -> 1).
    """
    p1 = {"lognormal": [math.log(600.0)], "exponential": [1 / 900.0], "loglogistic": [2.0]}[family]
    p2 = {"lognormal": [1.0], "exponential": [1.0], "loglogistic": [1500.0]}[family]
    f = MixtureFilter(SurvivalMixture(family, np.array([1.0]), np.array(p1), np.array(p2)), 0.1, 0.2)
    f.step(0.0, 1)
    f.step(100.0, 1)
    ev, p_own = f.step(float("nan"), 1)
    assert math.isnan(ev)
    assert 0.0 <= p_own <= 1.0


def test_log_emissions_of_padded_states_are_minus_inf() -> None:
    """(O, T, S) table against its definition, per cell: state 0 = every observed edge "not here",
    state k = edge k "here", the others "not here"; states beyond an object's own are -inf.
    """
    p_m, p_f = 0.1, 0.05
    t = np.array([0.0, 3600.0, 7200.0])
    streams = [EdgeStream(("a", "r1"), t, np.array([1, 0, 1], np.int8)),
               EdgeStream(("a", "r2"), t[:2], np.array([0, 1], np.int8)),
               EdgeStream(("a", "r3"), t[1:], np.array([1, 1], np.int8)),
               EdgeStream(("b", "r1"), t, np.array([0, 0, 1], np.int8))]  # b: one edge, states 2 and 3 padded
    b = _batch(streams, long_gap_s=math.inf)
    le = _log_emissions(b, p_m, p_f)
    obs: dict[tuple[str, int], dict[str, int]] = {}
    for s in streams:
        for ti, yi in zip(s.t_s.tolist(), s.y.tolist()):
            obs.setdefault((s.edge[0], int(np.searchsorted(t, ti))), {})[s.edge[1]] = int(yi)
    for o, obj in enumerate(b.objects):
        labels = [e[1] for e in b.edges[o]]
        for j in range(t.size):
            seen = obs.get((obj, j), {})
            for s in range(le.shape[2]):
                if s >= len(labels) + 1:
                    assert le[o, j, s] == -np.inf
                    continue
                here = None if s == 0 else labels[s - 1]
                ref = 0.0
                for lab, y in seen.items():
                    p1 = (1 - p_m) if lab == here else p_f  # P(y = 1 | state)
                    ref += math.log(p1 if y == 1 else 1 - p1)
                assert le[o, j, s] == pytest.approx(ref, rel=1e-14, abs=1e-14)


def test_process_oracle_state_from_json_integers_is_normalised() -> None:
    """A state whose own_t holds JSON integers and own_y JSON booleans restores a filter whose
    get_state() gives float seconds and 0/1 integers, the same JSON as a filter updated with them.
    """
    proc = tiny_process(11, K=2, S=4)
    proc.days = 30
    train = _streams(proc, 6, 5)
    est = get_estimator("process_oracle", process=proc.to_dict(), p_m=0.1, p_f=0.1).fit(train)
    edge = train[0].edge
    t0 = int(train[0].t_s[-1]) + 3600
    ts, ys = [t0, t0 + 3600, t0 + 7200], [True, False, True]
    f = est.filter_from_state({"estimator": "process_oracle", "edge": list(edge), "own_t": ts, "own_y": ys})
    state = f.get_state()
    assert [type(v) for v in state["own_t"]] == [float] * 3 and [type(v) for v in state["own_y"]] == [int] * 3
    fresh = est.make_filter(edge)
    fresh.update_many(np.array([float(v) for v in ts]), np.array([int(v) for v in ys], np.int8))
    assert json.dumps(state, sort_keys=True) == json.dumps(fresh.get_state(), sort_keys=True)


_COMPONENTS = {"mean": 0.5, "k": [1, 3], "re": [0.1, -0.2], "im": [0.05, 0.0], "base_period_s": 604800.0}


def test_fremen_components_from_json_floats_give_integer_periods() -> None:
    """k written as JSON floats (1.0, 3.0, as another writer may) is read as the format's integers:
    to_dict gives the canonical document (JSON integers) back."""
    c = fremen.FremenComponents.from_dict(dict(_COMPONENTS, k=[1.0, 3.0]))
    assert json.dumps(c.to_dict(), sort_keys=True) == json.dumps(_COMPONENTS, sort_keys=True)


def _complex_calls() -> dict[str, Any]:
    surv = SurvivalMixture("lognormal", np.array([0.5, 0.5]), np.log([600.0, 6000.0]), np.array([1.0, 1.0]))
    week = np.arange(0.0, 7 * 86400.0, 3600.0)
    model = fremen.FremenModel(n_periods=4).add(week, (np.arange(week.size) % 24 < 12).astype(np.float64))
    return {
        "MixtureFilter.update_many t": lambda: MixtureFilter(surv, 0.1, 0.2).update_many([0.0, 100.0 + 5j], [1, 1]),
        "MixtureFilter log_prior": lambda: MixtureFilter(surv, 0.1, 0.2, log_prior=[-0.7 + 0j, -0.7 + 1j]),
        "fourier_sums weights (direct)": lambda: fremen.fourier_sums([0.0, 3600.0], [1.0, 1j], 2, method="direct"),
        "fourier_sums weights (fft)": lambda: fremen.fourier_sums([0.0, 3600.0], [1.0, 1j], 2, method="fft"),
        "FremenModel.order_scores y": lambda: model.order_scores(week[:24], [1 + 1j] * 24),
        "FremenModel.add tau": lambda: fremen.FremenModel(n_periods=4).add([0.0, 3600.0 + 1j], [1.0, 0.0]),
        "FremenComponents.from_dict re": lambda: fremen.FremenComponents.from_dict(dict(_COMPONENTS, re=[0.1 + 1j, -0.2])),
        "FremenComponents.from_dict im": lambda: fremen.FremenComponents.from_dict(dict(_COMPONENTS, im=[0.05j, 0.0])),
    }


@pytest.mark.parametrize("what", sorted(_complex_calls()))
def test_complex_numbers_are_refused_as_float64_conversion_refuses_them(what: str) -> None:
    """Times, weights, observations and log priors are real: numpy's float64 conversion of a list
    with a Python complex number raises TypeError (the reference), and so does each entry point,
    instead of dropping the imaginary part (ComplexWarning) or computing complex sums.
    """
    with pytest.raises(TypeError):
        np.asarray([1.0, 1j], dtype=np.float64)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(TypeError, match="complex"):
            _complex_calls()[what]()


@pytest.mark.parametrize(("t", "zone"), [(9.19e9, "Europe/Berlin"), (-9.2e9, "America/New_York"),
                                         (math.floor(_PANDAS_END_S) - 1.0, "Europe/Berlin")])
def test_wall_seconds_within_400_days_of_pandas_range_ends_match_zoneinfo(monkeypatch: pytest.MonkeyPatch,
                                                                         t: float, zone: str) -> None:
    """Times inside pandas' range but within the offset table's 400-day margin of its ends (2261-03,
    1678-06, the last second): t + the zone's offset from zoneinfo, not pandas' OutOfBoundsDatetime
    (the audit's bug: the table's grid was padded past the range).
    """
    monkeypatch.setattr(fremen, "_OFFSET_TABLES", {})
    ref = dt.datetime(1970, 1, 1, tzinfo=dt.timezone.utc) + dt.timedelta(seconds=t)
    off = ref.astimezone(zoneinfo.ZoneInfo(zone)).utcoffset()
    assert off is not None
    np.testing.assert_array_equal(fremen.wall_seconds(np.array([t]), zone), [t + off.total_seconds()])


@pytest.mark.parametrize(("t", "zone"), [(9.3e9, "Europe/Berlin"), (-9.3e9, "America/New_York"), (1e12, "Europe/Berlin")])
def test_wall_seconds_beyond_pandas_range_take_the_offset_at_its_end(monkeypatch: pytest.MonkeyPatch,
                                                                   t: float, zone: str) -> None:
    """Times beyond pandas' range (the second audit: IndexError on an empty cache, a value after an
    earlier call): the zone's offset at the range's nearer end (from zoneinfo), whatever was asked before.
    """
    end = _PANDAS_END_S - 3 * 86400.0 if t > 0 else -_PANDAS_END_S + 3 * 86400.0
    when = dt.datetime(1970, 1, 1, tzinfo=dt.timezone.utc) + dt.timedelta(seconds=end)
    off = when.astimezone(zoneinfo.ZoneInfo(zone)).utcoffset()
    assert off is not None
    for earlier in ([], [math.copysign(9.25e9, t)]):
        monkeypatch.setattr(fremen, "_OFFSET_TABLES", {})
        for e in earlier:
            fremen.wall_seconds(np.array([e]), zone)
        np.testing.assert_array_equal(fremen.wall_seconds(np.array([t]), zone), [t + off.total_seconds()])
