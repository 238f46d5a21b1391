"""Perpetua*: model selection equations, forgetting, annealing, priors, multi-receptacle belief."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from psg_data.errors import EstimatorError
from psg_data.estimators import (
    ConstantPrior,
    EdgeStream,
    SchedulePrior,
    SurvivalMixture,
    conformance_streams,
    get_estimator,
    map_receptacle,
    parse_llm_schedule,
    receptacle_belief,
    render_llm_prompt,
)
from psg_data.estimators._mixture import MixtureFilter
from psg_data.estimators._perpetua_star import PerpetuaStarFilter, _edge_key_of, discounted_cumsum
from psg_data.estimators._priors import OraclePrior
from psg_data.estimators._survival_training import mixture_median_s

PER = SurvivalMixture("lognormal", np.array([0.5, 0.5]), np.log([3600.0, 8 * 3600.0]), np.array([0.3, 0.5]))
EMG = SurvivalMixture.lognormal_median(4 * 3600.0, 0.6)


def _filter(prior=ConstantPrior(0.5), gamma=0.99, alpha0=0.01 / 60) -> PerpetuaStarFilter:
    return PerpetuaStarFilter(("o", "r"), PER, EMG, 0.1, 0.1, prior, gamma=gamma, alpha0_per_s=alpha0,
                              prior_floor=1e-3)


@settings(max_examples=30, deadline=None)
@given(inc=st.lists(st.floats(-20, 5), min_size=1, max_size=200), gamma=st.sampled_from([0.0, 0.5, 0.9, 0.99, 1.0]),
       l0=st.floats(-50, 0))
def test_discounted_cumsum_matches_loop(inc, gamma, l0) -> None:
    inc = np.array(inc)
    want, cur = [], l0
    for v in inc:
        cur = gamma * cur + v
        want.append(cur)
    np.testing.assert_allclose(discounted_cumsum(l0, inc, gamma), want, rtol=1e-9, atol=1e-9)


def test_gamma_one_without_changes_gives_the_mixture_evidences() -> None:
    rng = np.random.default_rng(0)
    t = 1.7e9 + np.cumsum(rng.uniform(300, 900, 40))
    y = np.ones(40, dtype=np.int8)
    y[1] = 0  # one false negative, not enough to change the filtered state
    f = _filter(gamma=1.0)
    f.update_many(t, y)
    assert f.n_restarts == 0 and f.phase == 1
    per = MixtureFilter(PER, 0.1, 0.1)
    emg = MixtureFilter(EMG, 0.1, 0.1, emergence=True)
    per.update_many(t, y)
    emg.update_many(t, y)
    np.testing.assert_allclose(f.L, [per.log_evidence(), emg.log_evidence()], rtol=1e-10)
    # eq. 13-14 at t_N (alpha = 1) with a flat prior
    w = 1 / (1 + np.exp(per.log_evidence() - emg.log_evidence()))
    want = w * emg.predict(t[-1:]) + (1 - w) * per.predict(t[-1:])
    np.testing.assert_allclose(f.predict(t[-1:]), want, rtol=1e-10)


def test_annealing_defers_to_the_prior() -> None:
    t = 1.7e9 + np.arange(30) * 600.0
    f = _filter(prior=ConstantPrior(0.8))
    f.update_many(t, np.ones(30, dtype=np.int8))
    w_now = f.model_posterior(t[-1:])[0]
    w_far = f.model_posterior(t[-1:] + 10 * 86400)[0]
    assert w_far == pytest.approx(0.8, abs=1e-9)  # alpha ~ 0: the switching prior alone
    assert abs(w_now - 0.8) > 1e-3
    # far from the data: persistence -> 0, emergence -> 1, so the prediction is the prior
    assert f.predict(t[-1:] + 30 * 86400)[0] == pytest.approx(0.8, abs=1e-3)


def test_adapts_to_a_change_and_restarts_clocks() -> None:
    t = 1.7e9 + np.arange(60) * 900.0
    y = np.concatenate([np.ones(30), np.zeros(30)]).astype(np.int8)
    f = _filter()
    f.update_many(t[:30], y[:30])
    assert f.predict(t[29:30])[0] > 0.9
    f.update_many(t[30:], y[30:])
    assert f.phase == 0 and f.n_restarts >= 1
    assert f.emg.origin is not None and f.emg.origin > t[29]  # emergence clock restarted at the disappearance
    assert f.predict(t[-1:])[0] < 0.1


def test_batch_equals_one_at_a_time_with_many_changes() -> None:
    rng = np.random.default_rng(1)
    t = 1.7e9 + np.cumsum(rng.uniform(60, 3600, 3000))
    x = (np.mod(t, 86400) < 40000).astype(np.int8)
    y = np.where(rng.random(t.size) < 0.1, 1 - x, x).astype(np.int8)
    a, b = _filter(), _filter()
    a.update_many(t, y)
    for ti, yi in zip(t, y):
        b.update(float(ti), int(yi))
    assert a.n_restarts == b.n_restarts > 10
    q = t[-1] + np.linspace(0, 3 * 86400, 50)
    np.testing.assert_allclose(a.predict(q), b.predict(q), atol=1e-9)
    c = PerpetuaStarFilter.from_state(json.loads(json.dumps(a.get_state())))
    np.testing.assert_array_equal(c.predict(q), a.predict(q))


def test_predictions_in_range_for_extreme_streams() -> None:
    for y in (np.zeros(5000), np.ones(5000), np.arange(5000) % 2):
        f = _filter(gamma=0.99)
        f.update_many(1.7e9 + np.arange(5000) * 30.0, y.astype(np.int8))
        p = f.predict(1.7e9 + 5000 * 30.0 + np.logspace(0, 8, 40))
        assert np.all(np.isfinite(p)) and p.min() >= 0 and p.max() <= 1


def test_llm_schedule_parse_and_prompt() -> None:
    text = "Schedule: ['Mon: 19:00 - Mon: 19:30', 'Sun: 23:00 - Mon: 01:00', 'Fri: 08:00 - Fri: 24:00']"
    iv = parse_llm_schedule(text)
    assert iv == ((19 * 3600.0, 19.5 * 3600.0), (6 * 86400 + 23 * 3600.0, 3600.0), (4 * 86400 + 8 * 3600.0, 5 * 86400.0))
    prior = SchedulePrior(iv, 1.0, 0.0, "America/Toronto")
    mon = 1_704_085_200.0  # Monday 00:00 local
    got = prior(np.array([mon + 19.25 * 3600, mon + 20 * 3600, mon + 0.5 * 3600, mon + 6 * 86400 + 23.5 * 3600,
                          mon + 4 * 86400 + 12 * 3600]))
    np.testing.assert_array_equal(got, [1, 0, 1, 1, 1])
    for bad in ("no list here", "['Mon 19:00 - Mon: 19:30']", "['Mon: 25:00 - Mon: 19:30']", "[1, 2]"):
        with pytest.raises(EstimatorError, match="LLM schedule"):
            parse_llm_schedule(bad)
    p = render_llm_prompt("Keys", "On Hallway Hook", "Storage Location")
    assert "Object: Keys" in p and "Location: On Hallway Hook" in p and "['Day: HH:MM - Day: HH:MM'" in p
    assert "{" not in p


def test_multi_receptacle_map_and_absence() -> None:
    streams = conformance_streams(days=4)
    est = get_estimator("perpetua_star", n_periods=50).fit(streams, timezone="America/Toronto")
    filters = {}
    for s in streams:
        f = est.make_filter(s.edge)
        f.update_many(s.t_s, s.y)
        filters[s.edge[1]] = f
    t = float(max(s.t_s[-1] for s in streams))
    b = receptacle_belief(filters, t)
    assert set(b) == {"rec_1", "rec_2"}
    best = max(b, key=lambda k: float(b[k]))
    assert map_receptacle({k: float(v) for k, v in b.items()}, delta=0.0) == best
    assert map_receptacle({"a": 0.1, "b": 0.15}, delta=0.2) is None
    assert map_receptacle({"a": 0.1, "b": 0.65, "c": 0.3}) == "b"


def test_oracle_prior_from_ground_truth_meta() -> None:
    streams = conformance_streams(days=7)
    est = get_estimator("perpetua_star_oracle").fit(streams, timezone="America/Toronto")
    f = est.make_filter(("obj_a", "rec_1"))  # present 08:00-18:00 every day
    f.update_many(streams[0].t_s, streams[0].y)
    mon = 1_704_085_200.0 + 14 * 86400
    p = f.predict(np.array([mon + 12 * 3600, mon + 2 * 3600]))
    assert p[0] > 0.9 and p[1] < 0.1
    with pytest.raises(EstimatorError, match="earlier than the last"):
        f.update(float(streams[0].t_s[0]), 1)
    with pytest.raises(EstimatorError, match="non-decreasing"):
        EdgeStream(("a", "b"), np.array([2.0, 1.0]), np.array([1, 0]))


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n=st.integers(1, 1500), flip=st.floats(0.0, 0.4),
       gamma=st.sampled_from([0.9, 0.99, 1.0]), cuts=st.lists(st.integers(0, 1500), max_size=6))
def test_chunked_batches_equal_one_at_a_time(seed, n, flip, gamma, cuts) -> None:
    """Any split of a noisy stream into update_many batches gives the scalar path's state."""
    rng = np.random.default_rng(seed)
    t = 1.7e9 + np.cumsum(rng.uniform(1, 7200, n))
    x = (np.mod(t, 86400) < rng.uniform(20000, 60000)).astype(np.int8)
    y = np.where(rng.random(n) < flip, 1 - x, x).astype(np.int8)
    a, b = _filter(gamma=gamma), _filter(gamma=gamma)
    edges = [0, *sorted(c for c in cuts if 0 < c < n), n]
    for lo, hi in zip(edges[:-1], edges[1:]):
        if hi > lo:
            a.update_many(t[lo:hi], y[lo:hi])
    for ti, yi in zip(t.tolist(), y.tolist()):
        b.update(ti, yi)
    assert a.n_restarts == b.n_restarts and a.phase == b.phase
    q = t[-1] + np.linspace(0, 2 * 86400, 20)
    np.testing.assert_allclose(a.predict(q), b.predict(q), atol=1e-7)


def test_segmentation_settings_for_sparse_scans() -> None:
    """Short visits seen in 1-2 scans: the reference segmentation (5 obs, 3 nats) calls them noise."""
    rng = np.random.default_rng(4)
    t = 1.7e9 + np.sort(np.concatenate([d * 86400.0 + np.array([9, 11, 13, 15]) * 3600.0 for d in range(14)]))
    y = np.zeros(t.size, np.int8)
    for start in rng.choice(np.arange(2, t.size - 2), 8, replace=False):  # visits of one or two scans
        y[start:start + int(rng.integers(1, 3))] = 1
    streams = [EdgeStream(("o", "r"), t, y)]
    ref = get_estimator("perpetua_star", prior="none", segmentation="bernoulli").fit(streams)
    fine = get_estimator("perpetua_star", prior="none", segmentation="observations").fit(streams)
    med = mixture_median_s
    per_ref, emg_ref = ref.survivals_[("o", "r")]
    per_fine, emg_fine = fine.survivals_[("o", "r")]
    # the Bernoulli PELT finds at most one change point: every short visit counted as a false
    # positive and a long absence run; the observations as states see every visit
    assert med(emg_fine) < med(emg_ref) and med(emg_fine) < 7 * 86400
    assert fine.p_f_ < ref.p_f_
    r, f = ref.fit_summary_["edges"]["o/r"], fine.fit_summary_["edges"]["o/r"]
    assert r["present_runs"] + r["absent_runs"] <= 3 and f["present_runs"] >= 6
    with pytest.raises(EstimatorError, match="min_segment"):
        get_estimator("perpetua_star", min_segment=0).fit(streams)


# ---------------------------------------------------------------- issue 33: state, keys, priors


def test_state_round_trip_keeps_every_setting() -> None:
    f = PerpetuaStarFilter(("obj", "rec"), PER, EMG, 0.1, 0.2, ConstantPrior(0.3), gamma=None, half_life_s=7200.0,
                           alpha0_per_s=1e-4, prior_floor=1e-2, escape=2e-4, escape_first=5e-4,
                           anneal_prediction=True, name="perpetua_star_annealed")
    rng = np.random.default_rng(0)
    t = 1.7e9 + np.cumsum(rng.uniform(600, 3600, 60))
    f.update_many(t, (np.arange(60) // 7 % 2).astype(np.int8))
    assert f.n_restarts > 0
    state = f.get_state()
    g = PerpetuaStarFilter.from_state(state)
    assert g.get_state() == state
    assert g.edge == ("obj", "rec") and g.phase == f.phase and g.n_restarts == f.n_restarts
    q = t[-1] + np.linspace(0.0, 86400.0, 7)
    np.testing.assert_array_equal(g.predict(q), f.predict(q))


def test_edge_keys_in_every_spelling() -> None:
    for k in ("obj/rec", "obj|rec", "obj@rec", " obj / rec ", ("obj", "rec")):
        assert _edge_key_of(k) == ("obj", "rec")
    assert _edge_key_of("a/b/c") == ("a", "b/c")  # the first separator splits
    with pytest.raises(EstimatorError, match=r"^schedule key 'objrec': expected \(object, receptacle\) or "
                                             r"'object/receptacle'$"):
        _edge_key_of("objrec")


def test_oracle_prior_from_the_ground_truth_argument_of_its_own_edge() -> None:
    streams = [s for s in conformance_streams(days=7) if s.edge == ("obj_a", "rec_1")]
    plain = [EdgeStream(s.edge, s.t_s, s.y) for s in streams]  # no ground truth in meta
    gt_t = np.asarray(streams[0].meta["gt_t_s"], dtype=np.float64)
    gt_x = np.asarray(streams[0].meta["gt_state"], dtype=np.float64)
    other = (gt_t, 1.0 - gt_x)  # another edge's ground truth, listed first
    est = get_estimator("perpetua_star_oracle", ground_truth={"obj_b/rec_1": other, "obj_a/rec_1": (gt_t, gt_x)})
    est.fit(plain, timezone="America/Toronto")
    want = OraclePrior.from_ground_truth(gt_t, gt_x, est.clock_)
    q = gt_t[::97]
    np.testing.assert_array_equal(est.priors_[("obj_a", "rec_1")](q), want(q))
    with pytest.raises(EstimatorError, match=r"prior='oracle' needs ground truth for edge \('obj_a', 'rec_1'\)"):
        get_estimator("perpetua_star_oracle").fit(plain)


def test_schedule_prior_per_edge_also_for_edges_without_training_streams() -> None:
    streams = conformance_streams(days=4)
    text = "Schedule: ['Mon: 08:00 - Mon: 18:00', 'Wed: 08:00 - Wed: 18:00']"
    listed = ["Tue: 09:00 - Tue: 10:00"]
    est = get_estimator("perpetua_star_schedule", schedule_inside=0.8, schedule_outside=0.3,
                        schedules={"obj_a/rec_1": text, ("ghost", "rec_9"): listed})
    assert est.get_params()["prior"] == "schedule"
    est.fit(streams, timezone="America/Toronto")
    q = float(streams[0].t_s[0]) + np.arange(0.0, 7 * 86400.0, 3600.0)
    want = SchedulePrior(parse_llm_schedule(text), 0.8, 0.3, "America/Toronto")(q)
    np.testing.assert_array_equal(est.priors_[("obj_a", "rec_1")](q), want)
    assert set(np.unique(want)) == {0.3, 0.8}
    ghost = SchedulePrior(parse_llm_schedule(repr(listed)), 0.8, 0.3, "America/Toronto")(q)
    np.testing.assert_array_equal(est.priors_[("ghost", "rec_9")](q), ghost)
    unscheduled = next(s.edge for s in streams if s.edge != ("obj_a", "rec_1"))
    assert est.priors_[unscheduled](q).tolist() == [0.5] * q.size
    # a filter restored through the estimator predicts as the one it came from
    f = est.make_filter(("obj_a", "rec_1"))
    f.update_many(streams[0].t_s, streams[0].y)
    g = est.filter_from_state(f.get_state())
    np.testing.assert_array_equal(g.predict(q), f.predict(q))
    with pytest.raises(EstimatorError, match=r"^perpetua_star_schedule: prior='schedule' needs schedules="):
        get_estimator("perpetua_star_schedule").fit(streams)


def _half_life_filter(prior=None) -> PerpetuaStarFilter:
    return PerpetuaStarFilter(("o", "r"), PER, EMG, 0.1, 0.1, ConstantPrior(0.5) if prior is None else prior,
                              gamma=None, half_life_s=3600.0, alpha0_per_s=1e-4, prior_floor=1e-3)


def test_half_life_forgetting_discounts_by_half_per_half_life_in_the_scalar_path() -> None:
    # L_N = 0.5 ** ((t_N - t_N-1) / half_life) * L_N-1 + (log p(Y_1:N | m) - log p(Y_1:N-1 | m)), L_0 = increment
    t = 1.7e9 + np.array([0.0, 1800.0, 9000.0, 9000.0, 16200.0])
    y = np.ones(5, dtype=np.int8)
    f = _half_life_filter()
    per, emg = MixtureFilter(PER, 0.1, 0.1), MixtureFilter(EMG, 0.1, 0.1, emergence=True)
    want, ev_prev, prev_t = np.zeros(2), np.zeros(2), None
    for ti, yi in zip(t.tolist(), y.tolist()):
        f.update(ti, yi)
        per.update(ti, yi)
        emg.update(ti, yi)
        ev = np.array([per.log_evidence(), emg.log_evidence()])
        g = 1.0 if prev_t is None else 0.5 ** ((ti - prev_t) / 3600.0)
        want = g * want + (ev - ev_prev)
        ev_prev, prev_t = ev, ti
    assert f.n_restarts == 0
    np.testing.assert_allclose(f.L, want, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("seed", [0, 1])
def test_half_life_batches_with_a_time_varying_prior_equal_one_at_a_time(seed: int) -> None:
    prior = SchedulePrior(parse_llm_schedule("['Mon: 08:00 - Mon: 18:00', 'Tue: 08:00 - Fri: 18:00']"), 0.8, 0.15,
                          "UTC")
    rng = np.random.default_rng(seed)
    n = 400
    t = 1.7e9 + np.cumsum(rng.uniform(60, 5400, n))
    x = (np.mod(t, 86400) < 50000).astype(np.int8)
    y = np.where(rng.random(n) < 0.15, 1 - x, x).astype(np.int8)
    a, b = _half_life_filter(prior), _half_life_filter(prior)
    a.update_many(t, y)
    for ti, yi in zip(t.tolist(), y.tolist()):
        b.update(ti, yi)
    assert a.n_restarts == b.n_restarts > 0 and a.phase == b.phase
    np.testing.assert_allclose(a.L, b.L, rtol=1e-9, atol=1e-9)
    q = t[-1] + np.linspace(0, 86400, 9)
    np.testing.assert_allclose(a.predict(q), b.predict(q), atol=1e-9)


def test_estimator_settings_reach_its_filters() -> None:
    from psg_data.estimators._common import escape_floors

    streams = conformance_streams(days=4)
    defaults = get_estimator("perpetua_star").get_params()
    assert defaults["time_unit_s"] == 60.0 and defaults["max_components"] == 5  # alpha0 per minute (the paper)
    assert get_estimator("perpetua_star_oracle", gamma=0.9).get_params()["gamma"] == 0.9
    est = get_estimator("perpetua_star_annealed", prior="none", gamma=0.95, escape=1e-8).fit(streams)
    seen = streams[0].edge
    f = est.make_filter(seen)
    s = f.get_state()
    assert (s["estimator"], s["edge"], s["gamma"], s["anneal_prediction"]) == (
        "perpetua_star_annealed", list(seen), 0.95, True)
    assert s["escape"] == list(escape_floors(1e-8)) and s["escape"][0] != s["escape"][1]
    assert s["per_survival"] == est.survivals_[seen][0].to_dict()
    # an edge never trained on: the default mixtures and the flat prior
    u = est.make_filter(("never", "seen"))
    us = u.get_state()
    assert us["per_survival"] == est.default_survivals_[0].to_dict()
    assert us["emg_survival"] == est.default_survivals_[1].to_dict()
    assert u.predict(np.array([1.7e9])).tolist() == [0.5]


def test_fit_summary_records_each_resolved_setting_and_its_source() -> None:
    from psg_data.estimators._cadence import training_cadence
    from psg_data.estimators._fremen_estimator import order_selection_summary

    streams = conformance_streams(days=4)
    cad = training_cadence(streams)
    src = f"cadence: typical gap {cad.typical_gap_s:g} s" + ("" if cad.measured else " (fallback)")
    est = get_estimator("perpetua_star", n_periods=20).fit(streams)
    assert est.fit_summary_["settings"] == {
        "forgetting": {"value": f"half-life {cad.half_life_s:g} s", "source": src},
        "alpha0": {"value": f"{cad.alpha0_per_s * 60:.4g} per 60 s ({cad.alpha0_per_s:.4g} per s)", "source": src},
        "n_periods": {"value": 20, "source": "set"}}
    assert (est.gamma_, est.half_life_s_, est.alpha0_per_s_, est.n_periods_, est.profile_step_s_) == (
        None, cad.half_life_s, cad.alpha0_per_s, 20, cad.profile_step_s)
    assert est.fit_summary_["estimator"] == "perpetua_star" and est.fit_summary_["cadence"] == cad.to_dict()
    assert est.timezone_ == "UTC"
    assert {i["validation"] for i in est.fit_info_.values()} == {"none (order 0)"}  # 4 days: no held-out week
    assert est.fit_summary_["order_selection"] == order_selection_summary("reference", True, 1e-3, est.fit_info_)
    on_val = get_estimator("perpetua_star", n_periods=20, duration_rule=False).fit(streams, val_streams=streams)
    assert {i["validation"] for i in on_val.fit_info_.values()} == {"val_streams"}
    assert on_val.fit_summary_["order_selection"] == order_selection_summary("reference", False, 1e-3,
                                                                              on_val.fit_info_)

    set_all = get_estimator("perpetua_star", prior="profile", gamma=0.99, alpha0=0.01, time_unit_s=30.0,
                            profile_step_s=7200.0).fit(streams)
    assert set_all.fit_summary_["settings"] == {
        "forgetting": {"value": "gamma 0.99 per observation", "source": "set"},
        "alpha0": {"value": f"0.01 per 30 s ({0.01 / 30:.4g} per s)", "source": "set"},
        "profile_step_s": {"value": 7200.0, "source": "set"}}
    assert (set_all.gamma_, set_all.half_life_s_, set_all.alpha0_per_s_) == (0.99, None, 0.01 / 30)
    half = get_estimator("perpetua_star", prior="profile", half_life_s=5000.0).fit(streams)
    assert half.fit_summary_["settings"]["forgetting"] == {"value": "half-life 5000 s", "source": "set"}
    assert half.fit_summary_["settings"]["profile_step_s"] == {"value": cad.profile_step_s, "source": src}
    assert half.n_periods_ == cad.n_periods and half.half_life_s_ == 5000.0
    with pytest.raises(EstimatorError, match=r"^perpetua_star: give gamma \(forgetting per observation\) or "
                                             r"half_life_s \(per time\), not both \(got gamma=0\.9, half_life_s=100\)$"):
        get_estimator("perpetua_star", gamma=0.9, half_life_s=100).fit(streams)


def test_documented_defaults_and_parameters_round_trip() -> None:
    est = get_estimator("perpetua_star")
    p = est.get_params()
    assert {k: p[k] for k in ("prior", "gamma", "half_life_s", "alpha0", "time_unit_s", "max_components", "p_m",
                              "p_f", "min_segment", "segment_penalty", "pool_weight", "sigma_min", "n_periods",
                              "max_order", "order_tol", "duration_rule", "profile_step_s", "schedules",
                              "ground_truth", "prior_floor", "random_state")} == {
        "prior": "fremen", "gamma": None, "half_life_s": None, "alpha0": None, "time_unit_s": 60.0,
        "max_components": 5, "p_m": None, "p_f": None, "min_segment": 5, "segment_penalty": 3.0, "pool_weight": 2.0,
        "sigma_min": 0.05, "n_periods": None, "max_order": None, "order_tol": 1e-3, "duration_rule": True,
        "profile_step_s": None, "schedules": None, "ground_truth": None, "prior_floor": 1e-3, "random_state": 0}
    given = {"gamma": 0.9, "alpha0": 0.02, "p_m": 0.05, "p_f": 0.07, "n_periods": 30, "max_order": 4,
             "profile_step_s": 1800.0, "schedules": {"o/r": "[]"}, "ground_truth": {"o/r": ([0.0], [1.0])}}
    assert {k: get_estimator("perpetua_star", **given).get_params()[k] for k in given} == given
    assert get_estimator("perpetua_star", half_life_s=600.0).get_params()["half_life_s"] == 600.0


@pytest.mark.parametrize("log_g", [
    np.full(40, -50.0),  # the cumulative factor passes e^-300 after 6 steps: several stretches
    np.array([0.0, -400.0, -1.0, -np.inf, -2.0, -350.0, -350.0, 0.0, -0.5]),  # single steps below e^-300, a reset
])
def test_discounted_cumsum_log_matches_the_loop_across_stretches(log_g: np.ndarray) -> None:
    from psg_data.estimators._perpetua_star import discounted_cumsum_log

    inc = np.random.default_rng(1).uniform(-5.0, 1.0, log_g.size)
    want, cur = [], -3.0
    for g, v in zip(log_g.tolist(), inc.tolist()):
        cur = math.exp(g) * cur + v
        want.append(cur)
    np.testing.assert_allclose(discounted_cumsum_log(-3.0, inc, log_g), want, rtol=1e-12, atol=1e-12)


class _OutOfRangePrior(ConstantPrior):
    def __call__(self, t_s):  # a plugin prior may return values outside [0, 1]: they are clipped
        return np.where(np.asarray(t_s) < 1.7e9 + 43200.0, -0.5, 1.5)


@pytest.mark.parametrize("anneal", [False, True])
def test_an_out_of_range_prior_is_clipped_with_and_without_observations(anneal: bool) -> None:
    f = PerpetuaStarFilter(("o", "r"), PER, EMG, 0.1, 0.1, _OutOfRangePrior(), gamma=0.99, alpha0_per_s=1.0,
                           prior_floor=1e-3, anneal_prediction=anneal)
    q = 1.7e9 + np.array([0.0, 86400.0])
    assert f.predict(q).tolist() == [0.0, 1.0]
    f.update(1.7e9 - 3600.0, 1)
    if anneal:  # alpha = exp(-1 * 1e5 s): the prediction is the clipped prior
        assert f.predict(1.7e9 + np.array([100000.0])).tolist() == [1.0]


def test_annealed_prediction_at_the_last_observation_is_eq14() -> None:
    a = PerpetuaStarFilter(("o", "r"), PER, EMG, 0.1, 0.1, ConstantPrior(0.9), gamma=0.99, alpha0_per_s=0.5,
                           prior_floor=1e-3, anneal_prediction=True)
    b = PerpetuaStarFilter(("o", "r"), PER, EMG, 0.1, 0.1, ConstantPrior(0.9), gamma=0.99, alpha0_per_s=0.5,
                           prior_floor=1e-3)
    t = 1.7e9 + np.arange(5) * 600.0
    for f in (a, b):
        f.update_many(t, np.array([0, 0, 0, 0, 0], dtype=np.int8))
    np.testing.assert_array_equal(a.predict(t[-1:]), b.predict(t[-1:]))  # alpha(t_N) = 1 exactly


def test_scalar_update_accepts_equal_times_and_names_bad_input() -> None:
    f = _filter()
    f.update(1.7e9, 1)
    f.update(1.7e9, 0)  # two scans at the same second
    with pytest.raises(EstimatorError, match=r"^edge \('o', 'r'\): observation times must be finite$"):
        f.update(float("nan"), 1)
    with pytest.raises(EstimatorError, match=r"^edge \('o', 'r'\): observations must be 0 or 1$"):
        f.update(1.7e9 + 1.0, 2)


def test_long_runs_in_chunks_with_half_life_equal_one_at_a_time_in_every_state_field() -> None:
    # long stretches without a change: scans continue from their last row (chunks of 128, 512, ...)
    rng = np.random.default_rng(5)
    n = 1500
    t = 1.7e9 + np.cumsum(rng.uniform(30, 900, n))
    x = (np.arange(n) // 600 % 2).astype(np.int8)
    y = np.where(rng.random(n) < 0.02, 1 - x, x).astype(np.int8)
    a, b = _half_life_filter(), _half_life_filter()
    for lo, hi in ((0, 7), (7, 700), (700, n)):
        a.update_many(t[lo:hi], y[lo:hi])
    for ti, yi in zip(t.tolist(), y.tolist()):
        b.update(ti, yi)
    sa, sb = a.get_state(), b.get_state()
    for k in ("phase", "n_restarts", "last_t_s"):
        assert sa[k] == sb[k]
    assert sa["per"]["n"] == sb["per"]["n"] and sa["emg"]["n"] == sb["emg"]["n"]
    np.testing.assert_allclose(sa["L"], sb["L"], rtol=1e-9)
    np.testing.assert_allclose(sa["E"], sb["E"], rtol=1e-9)


def test_profile_prior_is_the_one_fitted_on_the_edges_training_observations() -> None:
    from psg_data.estimators._priors import ProfilePrior

    streams = conformance_streams(days=4)
    est = get_estimator("perpetua_star", prior="profile", profile_step_s=7200.0, profile_days="all").fit(
        streams, timezone="America/Toronto")
    for s in streams[:2]:
        want = ProfilePrior.fit(s.t_s, s.y, step_s=7200.0, days="all", timezone="America/Toronto")
        q = s.t_s[::5]
        np.testing.assert_array_equal(est.priors_[s.edge](q), want(q))


def test_filter_defaults_first_observation_and_settings_checks() -> None:
    f = _filter()
    assert (f.get_state()["estimator"], f.anneal_prediction, f.phase) == ("perpetua_star", False, -1)
    f.update(1.7e9, 0)  # the first observation sets the filtered state; it is no change
    assert (f.phase, f.n_restarts) == (0, 0)
    with pytest.raises(EstimatorError, match=r"^edge \('o', 'r'\): give exactly one of gamma \(per observation\) "
                                             r"and half_life_s$"):
        PerpetuaStarFilter(("o", "r"), PER, EMG, 0.1, 0.1, ConstantPrior(0.5), gamma=0.9, half_life_s=60.0,
                           alpha0_per_s=1e-4, prior_floor=1e-3)


def test_gamma_zero_keeps_only_the_last_increment_and_a_certain_prior_stays_finite() -> None:
    t = 1.7e9 + np.arange(4) * 600.0
    y = np.array([1, 1, 1, 1], dtype=np.int8)
    f = _filter(gamma=0.0)
    per, emg = MixtureFilter(PER, 0.1, 0.1), MixtureFilter(EMG, 0.1, 0.1, emergence=True)
    for ti, yi in zip(t[:-1].tolist(), y[:-1].tolist()):
        f.update(ti, yi)
        per.update(ti, yi)
        emg.update(ti, yi)
    before = np.array([per.log_evidence(), emg.log_evidence()])
    f.update(float(t[-1]), 1)
    per.update(float(t[-1]), 1)
    emg.update(float(t[-1]), 1)
    np.testing.assert_allclose(f.L, np.array([per.log_evidence(), emg.log_evidence()]) - before, rtol=1e-12)
    sure = _filter(prior=ConstantPrior(1.0))
    sure.update_many(t, y)
    assert np.all(np.isfinite(sure.model_posterior(t[-1] + np.array([0.0, 3600.0]))))


def test_short_batches_after_earlier_observations_forget_from_the_last_one() -> None:
    # scalar-path batches (<= 6) and scanned ones (> 6) right after earlier observations, with ties:
    # the first step of each batch is discounted from the previous batch's last time
    rng = np.random.default_rng(7)
    t = 1.7e9 + np.cumsum(rng.choice([0.0, 300.0, 1200.0], 40))
    y = (rng.random(40) < 0.8).astype(np.int8)
    a, b = _half_life_filter(), _half_life_filter()
    for lo, hi in ((0, 3), (3, 6), (6, 20), (20, 40)):
        a.update_many(t[lo:hi], y[lo:hi])
        for ti, yi in zip(t[lo:hi].tolist(), y[lo:hi].tolist()):
            b.update(ti, yi)
        assert a.n_restarts == b.n_restarts
        np.testing.assert_allclose(a.L, b.L, rtol=1e-9, atol=1e-12)
