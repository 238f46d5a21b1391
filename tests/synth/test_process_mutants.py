"""The step process's sampler, forward pass, schedules and the process oracle against independent
references: path enumeration with regimes and shifted days, closed forms, hand-evaluated cases
(written for the mutation groups ``synth_process`` and ``process_oracle``, docs/TESTING.md)."""

from __future__ import annotations

import dataclasses
import datetime as dt
import math
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from psg_data.errors import EstimatorError, PsgDataError
from psg_data.estimators import EdgeStream, get_estimator
from psg_data.schemas._generator_model import Regime, StepProcess
from psg_data.synth._process import ForwardBelief, observation_likelihood, sample_entity, save_process
from tests.estimators.test_process_oracle import P, _reference, _streams
from tests.synth.test_process_exact import tiny_process


def test_the_oracle_reads_the_process_of_a_dataset_folder_or_file(tmp_path: Path) -> None:
    proc = tiny_process(12, K=2, S=3)
    (tmp_path / "generator").mkdir()
    save_process(proc, tmp_path / "generator" / "process.json")
    t = np.array([proc.clock.step_start_s(i) + 60.0 for i in range(4)])
    streams = [EdgeStream(("obj", "r0"), t, np.array([1, 0, 0, 1], np.int8))]
    q = t[-1] + np.array([0.0, 3600.0, 86400.0])
    want = _reference(proc, [(float(a), "r0", int(b)) for a, b in zip(t, streams[0].y)], float(t[-1]), q, "r0",
                      p=0.1)
    for source in (str(tmp_path), str(tmp_path / "generator" / "process.json")):
        est = get_estimator("process_oracle", dataset=source, p_m=0.1, p_f=0.1).fit(streams)
        f = est.make_filter(("obj", "r0"))
        f.update_many(t, streams[0].y)
        np.testing.assert_allclose(f.predict(q), want, rtol=0, atol=1e-12)


# -- the forward pass with regimes and shifted days, against path enumeration ------------------------


def _regime_process(seed: int, *, start_day: int = 1, shifted: tuple[int, ...] = (), K: int = 2):  # type: ignore[no-untyped-def]
    """tiny_process with a second entity model from ``start_day`` on (other kernels, dwells permuted)."""
    base_proc = tiny_process(seed, K=K)
    base = base_proc.entities["obj"]
    other = tiny_process(seed + 100, K=K).entities["obj"]
    allowed = np.ones((7, base.n_patterns), bool)
    allowed[:5, 1] = False  # weekdays: pattern 1 not allowed in the regime (the base forbids pattern 0 on weekends)
    shifted_ent = dataclasses.replace(base, pattern_transition=other.pattern_transition, pattern_allowed=allowed,
                                      routine=other.routine, routine_strength=other.routine_strength,
                                      jump=other.jump, dwell=base.dwell[:, ::-1].copy())
    regimes = (Regime(start_day, "shift", {"obj": shifted_ent}),) if start_day > 0 else ()
    return StepProcess(base_proc.timezone, base_proc.start_date, 4, base_proc.step_hours, {"obj": base},
                       shifted, {}, regimes)


def _model_of_day(proc: StepProcess, day: int):  # type: ignore[no-untyped-def]
    ent = proc.entities["obj"]
    for r in proc.regimes:
        if r.start_day <= day:
            ent = r.entities["obj"]
    return ent


def _mask(proc: StepProcess, ent, day: int) -> np.ndarray:  # type: ignore[no-untyped-def]
    wd = 5 if day in proc.shifted_days else (proc.start_date + dt.timedelta(days=day)).weekday()
    return ent.pattern_allowed[wd].astype(float)


def enumerate_paths(proc: StepProcess, n_steps: int, obs: dict[int, list[tuple[str | None, int]]], p_m: float,
                    p_f: float) -> tuple[np.ndarray, float]:
    """Joint P(pattern, state, remaining dwell) at step n_steps - 1 given the observations, and the
    evidence, summing over every path; the model of each day is looked up by hand (regimes, shifted days)."""
    K = proc.n_slots
    ent0 = proc.entities["obj"]
    R = int(ent0.dwell[..., 1].max())
    joint = np.zeros((ent0.n_patterns, ent0.n_states, R))

    def lik(ent, n: int, s: int) -> float:  # type: ignore[no-untyped-def]
        out = 1.0
        for label, y in obs.get(n, []):
            p1 = (1 - p_m) if ent.states[s] == label else p_f
            out *= p1 if y == 1 else 1 - p1
        return out

    def rec(n: int, p: int, s: int, r: int, w: float) -> None:
        if w == 0.0:
            return
        if n == n_steps:
            joint[p, s, r - 1] += w
            return
        day, k = divmod(n, K)
        ent = _model_of_day(proc, day)
        if k == 0:
            mask = _mask(proc, ent, day)
            row = (ent.pattern_initial if day == 0 else ent.pattern_transition[p]) * mask
            if row.sum() == 0:
                row = mask
            choices = [(q, row[q] / row.sum()) for q in range(ent.n_patterns) if row[q] > 0]
        else:
            choices = [(p, 1.0)]
        for q, wq in choices:
            rho = float(ent.routine_strength[q, k])
            s_r = int(ent.routine[q, k])
            lo, hi = ent.dwell[q, s_r]
            moves = [(s_r, d, rho / (hi - lo + 1)) for d in range(lo, hi + 1)]
            if r > 1:
                moves.append((s, r - 1, 1 - rho))
            else:
                for s2 in range(ent.n_states):
                    lo, hi = ent.dwell[q, s2]
                    moves += [(s2, d, (1 - rho) * ent.jump[q, s, s2] / (hi - lo + 1)) for d in range(lo, hi + 1)]
            for s2, r2, wm in moves:
                rec(n + 1, q, s2, r2, w * wq * wm * lik(ent, n, s2))

    for s0 in range(ent0.n_states):
        rec(0, -1, s0, 1, float(ent0.state_initial[s0]))
    z = float(joint.sum())
    return joint / z, z


@pytest.mark.parametrize(("seed", "start_day", "shifted"), [(0, 1, ()), (1, 2, (1,)), (2, 0, (1, 2)), (3, 1, (2,))])
def test_forward_with_regimes_and_shifted_days_equals_path_enumeration(seed: int, start_day: int,
                                                                       shifted: tuple[int, ...]) -> None:
    proc = _regime_process(seed, start_day=start_day, shifted=shifted)
    ent = proc.entities["obj"]
    obs = {0: [("r0", 1)], 1: [("r1", 0)], 3: [("r0", 0)], 4: [("r1", 1), ("r0", 0)]}
    b = ForwardBelief(proc, ent).start()
    for n in range(6):  # days 0, 1, 2 (K = 2): across both regime and shift boundaries
        b.advance_to(n)
        for label, y in obs.get(n, []):
            b.observe(observation_likelihood(ent, label, y, 0.15, 0.1))
        want, z = enumerate_paths(proc, n + 1, {m: v for m, v in obs.items() if m <= n}, 0.15, 0.1)
        assert b.n == n
        np.testing.assert_allclose(b.alpha, want, rtol=0, atol=1e-12)
        np.testing.assert_allclose(np.exp(b.log_evidence), z, rtol=1e-10)
        np.testing.assert_allclose(b.state_marginal(), want.sum(axis=(0, 2)), rtol=0, atol=1e-12)
    # a forecast from a copy across the next regime day agrees with enumeration without further observations
    c = ForwardBelief(proc, ent).start()
    got = c.forecast([0, 3, 5])
    for row, n in zip(got, (0, 3, 5)):
        np.testing.assert_allclose(row, enumerate_paths(proc, n + 1, {}, 0.0, 0.0)[0].sum(axis=(0, 2)), atol=1e-12)
    assert c.n == 0 and c.entity is ent


def test_advance_to_refuses_going_back_and_observe_refuses_impossible_observations() -> None:
    proc = tiny_process(3)
    ent = proc.entities["obj"]
    b = ForwardBelief(proc, ent).start()
    b.advance_to(3)
    b.advance_to(3)  # the current step: no move
    assert b.n == 3
    with pytest.raises(PsgDataError, match=r"^ForwardBelief: cannot go back from step 3 to 2$"):
        b.advance_to(2)
    at_r0 = np.zeros(ent.n_states)
    b.observe(np.where(np.arange(ent.n_states) == 0, 1.0, 0.0))  # noise-free: seen at r0
    np.testing.assert_allclose(b.state_marginal(), np.eye(ent.n_states)[0], atol=1e-15)
    with pytest.raises(PsgDataError, match=r"^obj: observation at step 3 is impossible under the generator model "
                                           r"\(zero likelihood\); noisy labels need p_m/p_f > 0$"):
        b.observe(at_r0)


def test_observation_likelihood_by_hand() -> None:
    ent = tiny_process(0, S=3).entities["obj"]  # states r0, r1, None
    np.testing.assert_allclose(observation_likelihood(ent, "r0", 1, 0.2, 0.1), [0.8, 0.1, 0.1], rtol=0, atol=1e-15)
    np.testing.assert_allclose(observation_likelihood(ent, "r0", 0, 0.2, 0.1), [0.2, 0.9, 0.9], rtol=0, atol=1e-15)
    np.testing.assert_allclose(observation_likelihood(ent, "r1", 1, 0.2, 0.1), [0.1, 0.8, 0.1], rtol=0, atol=1e-15)
    np.testing.assert_allclose(observation_likelihood(ent, "r1", np.int8(0), 0.2, 0.1), [0.9, 0.2, 0.9],
                               rtol=0, atol=1e-15)
    # a label the entity never takes: P(y = 1) = p_f everywhere
    np.testing.assert_allclose(observation_likelihood(ent, "kitchen", 1, 0.2, 0.1), [0.1, 0.1, 0.1], rtol=0, atol=1e-15)
    np.testing.assert_allclose(observation_likelihood(ent, "kitchen", 0, 0.2, 0.1), [0.9, 0.9, 0.9], rtol=0, atol=1e-15)


# -- the sampler: its law at every step is the enumerated one, its bookkeeping the generative story ---


def _chi2_p(counts: np.ndarray, p: np.ndarray) -> float:
    keep = p > 1e-15
    assert counts[~keep].sum() == 0, "an outcome of probability 0 was sampled"
    return float(stats.chisquare(counts[keep], p[keep] / p[keep].sum() * counts.sum()).pvalue)


def test_sampled_paths_follow_the_enumerated_law_step_by_step() -> None:
    proc = _regime_process(4, start_day=1, shifted=(2,))
    ent = proc.entities["obj"]
    K, n_steps, n_paths = proc.n_slots, 6, 3000
    rng = np.random.default_rng(2024)
    paths = [sample_entity(proc, ent, n_steps, rng) for _ in range(n_paths)]
    before = np.array([p.before for p in paths])
    assert _chi2_p(np.bincount(before, minlength=ent.n_states), ent.state_initial) > 1e-3
    R = int(ent.dwell[..., 1].max())
    for n in range(n_steps):
        day, k = divmod(n, K)
        cell = np.array([np.ravel_multi_index((p.patterns[day], p.states[n], p.dwell[n] - 1),
                                              (ent.n_patterns, ent.n_states, R)) for p in paths])
        want = enumerate_paths(proc, n + 1, {}, 0.0, 0.0)[0].ravel()
        assert _chi2_p(np.bincount(cell, minlength=want.size), want) > 1e-3, n
    for p in paths:
        assert p.patterns.shape == (3,) and p.states.shape == p.dwell.shape == p.events.shape == (n_steps,)
        prev_s, prev_r = p.before, 1
        for n in range(n_steps):
            day, k = divmod(n, K)
            model = _model_of_day(proc, day)
            q, s, r, ev = p.patterns[day], p.states[n], p.dwell[n], p.events[n]
            if ev == 1:  # a hold: same state, one step less, no dwell drawn
                assert prev_r > 1 and s == prev_s and r == prev_r - 1 and p.fresh[n] == 0
            else:  # a routine placement (at the routine's state) or a jump (only when the dwell ran out)
                lo, hi = model.dwell[q, s]
                assert p.fresh[n] == r and lo <= r <= hi
                assert ev == 2 and prev_r == 1 or ev == 0 and s == model.routine[q, k]
            prev_s, prev_r = s, r
    # the routine acts with probability rho at every step, whatever the dwell left
    for n in range(n_steps):
        day, k = divmod(n, K)
        for q in range(ent.n_patterns):
            ev = np.array([p.events[n] for p in paths if p.patterns[day] == q])
            rho = float(_model_of_day(proc, day).routine_strength[q, k])
            if ev.size >= 100:
                assert abs(np.mean(ev == 0) - rho) < 5 * np.sqrt(rho * (1 - rho) / ev.size) + 1e-12, (n, q)


def test_a_longer_path_extends_a_shorter_one() -> None:
    proc = _regime_process(5, start_day=1)
    ent = proc.entities["obj"]
    short = sample_entity(proc, ent, 3, np.random.default_rng(8))
    long = sample_entity(proc, ent, 8, np.random.default_rng(8))
    for name in ("states", "dwell", "events", "fresh"):
        np.testing.assert_array_equal(getattr(long, name)[:3], getattr(short, name))
    np.testing.assert_array_equal(long.patterns[:2], short.patterns)
    assert long.before == short.before and long.patterns.shape == (4,)


def test_fresh_dwells_are_the_uniform_draw_of_their_range_even_below_one() -> None:
    """A fresh dwell is lo + floor(u (hi - lo + 1)) for the step's fourth uniform, recomputed here from the
    same seed: the constructor does not check 1 <= lo (only ``problems()`` does), so the draw is pinned for
    a range starting below 0 as well (a cap of hi + lo instead of hi - lo would bind there)."""
    proc = tiny_process(4, rho=1.0)  # routine strength 1: every step draws a fresh dwell
    ent = proc.entities["obj"]
    ent.dwell[...] = np.array([-2, 3])
    path = sample_entity(proc, ent, 30, np.random.default_rng(11))
    rng = np.random.default_rng(11)
    rng.random()  # the initial state's uniform
    u = rng.random((30, 4))
    expected = np.array([-2 + math.floor(float(x) * 6) for x in u[:, 3]])
    assert set(expected) == set(range(-2, 4))  # the whole range occurs, negative dwells too
    np.testing.assert_array_equal(path.events, np.zeros(30, np.int64))
    np.testing.assert_array_equal(path.fresh, expected)


def test_pick_never_returns_an_outcome_of_probability_zero() -> None:
    from psg_data.synth._process import _pick

    p = np.array([0.0, 0.25, 0.0, 0.75, 0.0])
    assert _pick(p, 0.0) == 1  # u = 0 lands after the leading zero
    assert _pick(p, 0.2499) == 1 and _pick(p, 0.25) == 3 and _pick(p, 0.9999) == 3
    assert _pick(np.array([0.5, 0.5]), 1.0) == 1  # u = 1 (outside [0, 1)): still an index
    assert _pick(np.array([2.0, 6.0]), 0.3) == 1  # unnormalised weights: 0.3 * 8 = 2.4 > 2


# -- the process oracle: the posterior of exactly its information set, in any order of calls ----------

@pytest.mark.parametrize(("share", "seed"), [(False, 0), (True, 1), (True, 2)])
def test_every_prediction_is_the_posterior_of_the_information_set_in_a_random_schedule(share: bool,
                                                                                       seed: int) -> None:
    proc = tiny_process(11, K=2, S=4)
    proc.days = 30
    streams = _streams(proc, 12, seed)
    t_all = streams[0].t_s
    cut = float(t_all[5 * proc.n_slots])
    train = [s.between(-np.inf, cut) for s in streams]
    test = [s.between(cut, np.inf) for s in streams]
    fit_end = max(float(s.t_s[-1]) for s in train)  # between(): start <= t < end
    labels = [s.edge[1] for s in streams]
    est = get_estimator("process_oracle", process=proc.to_dict(), p_m=P, p_f=P, share_updates=share)
    est.fit(train + [EdgeStream(("obj", "elsewhere"), np.zeros(0), np.zeros(0, np.int8))])
    med = get_estimator("process_oracle", process=proc.to_dict(), p_m=P, p_f=P, share_updates=share,
                        output="median").fit(train)
    filters = [est.make_filter(s.edge) for s in streams]
    medians = [med.make_filter(s.edge) for s in streams]
    fed: list[list[tuple[float, str, int]]] = [[] for _ in streams]  # what each filter was given
    rng = np.random.default_rng(seed)
    for i in rng.permutation(len(streams)):
        if i != 0:  # edge 0 starts from its training data only after the others ran ahead
            for f in (filters[i], medians[i]):
                f.update_many(train[i].t_s, train[i].y)
            fed[i] += [(float(a), labels[i], int(b)) for a, b in zip(train[i].t_s, train[i].y)]
    nxt = [0] * len(streams)
    for step in range(40):
        i = int(rng.integers(len(streams)))
        if step == 3:
            for f in (filters[0], medians[0]):
                f.update_many(train[0].t_s, train[0].y)
            fed[0] += [(float(a), labels[0], int(b)) for a, b in zip(train[0].t_s, train[0].y)]
        elif nxt[i] < len(test[i]) and (i != 0 or step > 3):
            m = int(rng.integers(1, 3))
            ts, ys = test[i].t_s[nxt[i]:nxt[i] + m], test[i].y[nxt[i]:nxt[i] + m]
            for f in (filters[i], medians[i]):
                f.update_many(ts, ys)
            fed[i] += [(float(a), labels[i], int(b)) for a, b in zip(ts, ys)]
            nxt[i] += m
        j = int(rng.integers(len(streams)))
        H = filters[j].last_t_s
        if H is None:
            continue
        info = list(fed[j])
        for k in range(len(streams)):
            if k != j:
                info += [(float(a), labels[k], int(b)) for a, b in zip(train[k].t_s, train[k].y) if a <= H]
                if share:
                    info += [o for o in fed[k] if fit_end < o[0] <= H]
        q = H + np.array([-7200.0, 0.0, 1800.0, 3 * 3600.0, 86400.0, 2.5 * 86400.0])
        want = _reference(proc, info, H, q, labels[j], p=P)
        np.testing.assert_allclose(filters[j].predict(q), want, rtol=0, atol=1e-12, err_msg=f"step {step}")
        np.testing.assert_array_equal(medians[j].predict(q), (want >= 0.5).astype(float))
    assert min(nxt) > 0
    never = est.make_filter(("obj", "elsewhere"))
    never.update_many(t_all[:3], np.zeros(3, np.int8))
    np.testing.assert_array_equal(never.predict(t_all[3:9]), np.zeros(6))


def test_the_median_of_a_posterior_of_exactly_one_half_is_present() -> None:
    proc = tiny_process(1, K=2, S=3, rho=1.0)
    ent = proc.entities["obj"]
    ent.pattern_initial[:] = [0.5, 0.5]
    ent.pattern_allowed[:] = True
    ent.routine[:, 0] = [0, 1]  # day 0's first step: r0 under pattern 0, r1 under pattern 1
    ent.dwell[:] = 1
    q = np.array([proc.clock.step_start_s(0) + 60.0])
    p = get_estimator("process_oracle", process=proc.to_dict()).fit([]).make_filter(("obj", "r0")).predict(q)
    assert p[0] == 0.5  # 1/2 exactly: the two patterns' routine
    m = get_estimator("process_oracle", process=proc.to_dict(), output="median").fit([])
    assert m.make_filter(("obj", "r0")).predict(q)[0] == 1.0  # the decision P >= 0.5


def test_train_model_drops_the_regimes_and_generating_keeps_them() -> None:
    proc = _regime_process(6, start_day=2)
    proc.days = 20
    plain = StepProcess(proc.timezone, proc.start_date, proc.days, proc.step_hours, dict(proc.entities))
    t = np.array([proc.clock.step_start_s(i) + 60.0 for i in range(3)])
    y = np.array([1, 1, 0], np.int8)
    q = t[-1] + 86400.0 * np.array([0.5, 1.0, 2.0, 3.0])
    obs = [(float(a), "r0", int(b)) for a, b in zip(t, y)]
    got = {}
    for model, ref in (("generating", proc), ("train", plain)):
        est = get_estimator("process_oracle", process=proc.to_dict(), model=model, p_m=P, p_f=P).fit([])
        f = est.make_filter(("obj", "r0"))
        f.update_many(t, y)
        got[model] = f.predict(q)
        np.testing.assert_allclose(got[model], _reference(ref, obs, float(t[-1]), q, "r0", p=P), rtol=0, atol=1e-12)
    assert np.abs(got["generating"] - got["train"]).max() > 1e-3


def test_oracle_error_messages(tmp_path: Path) -> None:
    proc = tiny_process(2, K=2, S=3)
    d = proc.to_dict()
    with pytest.raises(EstimatorError, match=r"^fit: expected EdgeStream objects, got tuple$"):
        get_estimator("process_oracle", process=d).fit([(("obj", "r0"), [0.0], [1])])  # type: ignore[list-item]
    est = get_estimator("process_oracle", process=d).fit([])
    with pytest.raises(EstimatorError, match=r"^process_oracle: edge \('nope', 'r0'\): 'nope' is not an entity of "
                                             r"the generator model$"):
        est.make_filter(("nope", "r0"))
    bad = tmp_path / "process.json"
    bad.write_text("{not json", encoding="utf-8")
    with pytest.raises(EstimatorError, match=rf"^process_oracle: {bad}: not valid JSON"):
        get_estimator("process_oracle", dataset=str(bad)).fit([])
    # noise-free labels that the model cannot produce: seen at r0 and at r1 in one step
    t0 = proc.clock.step_start_s(1) + 60.0
    streams = [EdgeStream(("obj", "r1"), np.array([t0]), np.array([1], np.int8))]
    est = get_estimator("process_oracle", process=d).fit(streams)
    f = est.make_filter(("obj", "r0"))
    f.update(t0 + 1.0, 1)
    msg = (r"^process_oracle: edge \('obj', 'r0'\): obj: observation at step 1 is impossible under the generator "
           r"model \(zero likelihood\); noisy labels need p_m/p_f > 0$")
    for _ in range(2):  # the failed belief is dropped: asking again fails the same way
        with pytest.raises(EstimatorError, match=msg):
            f.predict(np.array([t0 + 10.0]))


# -- LLM-format schedules -------------------------------------------------------------------------------


def test_weekday_marginals_of_a_seven_day_cycle_keep_the_initial_law_and_its_phase() -> None:
    """A day chain that moves pattern q -> q + 1 (mod 7) every day never forgets day 0: on the day
    w days after day 0's weekday, the pattern is day 0's plus w, so P(q | weekday) is the initial
    law, restricted to day 0's mask, shifted by the weekday's distance from day 0's."""
    from psg_data.synth._process import weekday_pattern_marginals

    proc = tiny_process(3, D=7)
    ent = proc.entities["obj"]
    w0 = proc.start_date.weekday()
    ent.pattern_allowed[:] = True
    ent.pattern_allowed[w0, 6] = False  # day 0's weekday forbids pattern 6 (never reached there later)
    raw = np.array([5.0, 1.0, 4.0, 2.0, 6.0, 3.0, 7.0])  # not a fixed point of day 0's matrix
    ent.pattern_initial[:] = raw / raw.sum()
    ent.pattern_transition[:] = np.roll(np.eye(7), 1, axis=1)
    pi = raw.copy()
    pi[6] = 0.0
    pi /= pi.sum()
    want = np.array([[pi[(q - (w - w0)) % 7] for q in range(7)] for w in range(7)])
    for weeks in (30, 12):
        np.testing.assert_allclose(weekday_pattern_marginals(proc, ent, weeks), want, rtol=0, atol=1e-12)
    np.testing.assert_allclose(weekday_pattern_marginals(proc, ent), want, rtol=0, atol=1e-12)


def test_intervals_are_listed_by_day_then_clock_time_with_minutes() -> None:
    from psg_data.synth._process import _intervals

    on = np.zeros(21, bool)  # K = 3: Monday's first and last slots on, the week's last slot off
    on[[0, 2]] = True
    hours = (9.25, 11.5, 13.75)
    assert _intervals(on, 3, hours) == ["Mon: 09:15 - Mon: 11:30", "Mon: 13:45 - Tue: 09:15"]
    on[[19, 20]] = True  # Sunday's last two slots: a run into Monday 09:15, listed under Sunday
    on[0] = False
    assert _intervals(on, 3, hours) == ["Mon: 13:45 - Tue: 09:15", "Sun: 11:30 - Mon: 09:15"]


def test_a_callers_own_variant_of_the_entity_stays_in_force_outside_the_regimes() -> None:
    proc = _regime_process(7, start_day=2)
    stored = proc.entities["obj"]
    variant = dataclasses.replace(stored, jump=tiny_process(77).entities["obj"].jump,
                                  routine_strength=np.full_like(stored.routine_strength, 0.3))
    as_base = StepProcess(proc.timezone, proc.start_date, proc.days, proc.step_hours, {"obj": variant},
                          proc.shifted_days, {}, proc.regimes)
    b = ForwardBelief(proc, variant).start()
    for n in range(6):  # days 0 and 1 under the variant, day 2 under the regime
        b.advance_to(n)
        np.testing.assert_allclose(b.alpha, enumerate_paths(as_base, n + 1, {}, 0.0, 0.0)[0], rtol=0, atol=1e-12)
    assert b.entity is proc.regimes[0].entities["obj"]
    path = sample_entity(proc, variant, 4, np.random.default_rng(0))  # days 0-1: the variant's routine strength
    twin = sample_entity(as_base, variant, 4, np.random.default_rng(0))
    np.testing.assert_array_equal(path.events, twin.events)
    np.testing.assert_array_equal(path.states, twin.states)


def test_sampling_draws_one_uniform_for_the_start_and_four_per_step() -> None:
    proc = _regime_process(8, start_day=1)
    for n in (1, 5):
        rng, ref = np.random.default_rng(11), np.random.default_rng(11)
        sample_entity(proc, proc.entities["obj"], n, rng)
        ref.random(1 + 4 * n)
        assert rng.random() == ref.random()


class _ZeroUniforms:
    """A generator whose uniforms are all 0 (the lower end of [0, 1))."""

    def random(self, size: int | tuple[int, ...] | None = None) -> float | np.ndarray:
        return 0.0 if size is None else np.zeros(size)


def test_the_routine_acts_with_probability_rho_even_at_the_lowest_uniform() -> None:
    """u < rho: a routine of strength 0 never acts, one of strength 1 always does (u = 0 included)."""
    ent = tiny_process(9, rho=0.0).entities["obj"]
    path = sample_entity(tiny_process(9, rho=0.0), ent, 6, _ZeroUniforms())  # type: ignore[arg-type]
    assert path.events[0] == 2 and set(path.events.tolist()) <= {1, 2}  # holds and jumps only
    proc = tiny_process(9, rho=1.0)
    ent = proc.entities["obj"]
    path = sample_entity(proc, ent, 6, _ZeroUniforms())  # type: ignore[arg-type]
    assert set(path.events.tolist()) == {0}
    np.testing.assert_array_equal(path.states, [ent.routine[path.patterns[n // 2], n % 2] for n in range(6)])


def test_shared_updates_stay_with_their_own_object() -> None:
    """Two objects with the same receptacles: what the filters of one object receive after the
    training data never reaches the other's (one tracker per object)."""
    one = tiny_process(11, K=2, S=3)
    cup = dataclasses.replace(tiny_process(12, K=2, S=3).entities["obj"], entity_id="cup")
    proc = StepProcess(one.timezone, one.start_date, 30, one.step_hours, {"obj": one.entities["obj"], "cup": cup})
    n = 16
    t = np.array([proc.clock.step_start_s(i) + 120.0 for i in range(n)])
    rng = np.random.default_rng(3)
    ys = {(e, lab): rng.integers(0, 2, n).astype(np.int8) for e in ("obj", "cup") for lab in ("r0", "r1")}
    cut = 8
    est = get_estimator("process_oracle", process=proc.to_dict(), p_m=0.2, p_f=0.2, share_updates=True)
    est.fit([EdgeStream(edge, t[:cut], y[:cut]) for edge, y in ys.items()])
    filters = {edge: est.make_filter(edge) for edge in ys}
    for edge in (("cup", "r0"), ("cup", "r1"), ("obj", "r0")):
        filters[edge].update_many(t, ys[edge])
    f = filters[("obj", "r1")]
    f.update_many(t[:12], ys[("obj", "r1")][:12])
    obs = [(float(a), "r1", int(b)) for a, b in zip(t[:12], ys[("obj", "r1")][:12])]
    obs += [(float(a), "r0", int(b)) for a, b in zip(t[:12], ys[("obj", "r0")][:12])]  # training and tracker
    q = t[11] + np.array([0.0, 7200.0, 86400.0])
    np.testing.assert_allclose(f.predict(q), _reference(proc, obs, float(t[11]), q, "r1", p=0.2), rtol=0, atol=1e-12)


def test_the_default_oracle_keeps_each_edge_to_its_own_updates_and_answers_empty_queries() -> None:
    from psg_data.estimators._process_oracle import ProcessOracleFilter

    proc = tiny_process(11, K=2, S=4)
    proc.days = 30
    streams = _streams(proc, 8, 4)
    t_all = streams[0].t_s
    cut = float(t_all[4 * proc.n_slots])
    train = [s.between(-np.inf, cut) for s in streams]
    est = get_estimator("process_oracle", process=proc.to_dict(), p_m=P, p_f=P)
    assert est.get_params()["share_updates"] is False and est.get_params()["output"] == "probability"
    est.fit(train)
    sib = est.make_filter(streams[1].edge)
    sib.update_many(streams[1].t_s, streams[1].y)  # training and later observations of a sibling
    f = est.make_filter(streams[0].edge)
    f.update_many(streams[0].t_s, streams[0].y)
    H = float(streams[0].t_s[-1])
    info = [(float(a), s.edge[1], int(b)) for s in [streams[0]] + train[1:] for a, b in zip(s.t_s, s.y)]
    q = H + np.array([0.0, 7200.0, 86400.0])
    want = _reference(proc, info, H, q, streams[0].edge[1], p=P)
    np.testing.assert_allclose(f.predict(q), want, rtol=0, atol=1e-12)
    assert f.predict(np.zeros(0)).shape == (0,) and f.predict(np.zeros((0, 3))).shape == (0, 3)
    # the filter class on its own predicts probabilities unless asked for the median
    g = ProcessOracleFilter(streams[0].edge, est.process_, est.observations_[("obj")], None, est.fit_end_s_, P, P)
    g.update_many(streams[0].t_s, streams[0].y)
    np.testing.assert_allclose(g.predict(q), want, rtol=0, atol=1e-12)


def test_oracle_refusals_in_full() -> None:
    with pytest.raises(EstimatorError, match=r"^process_oracle: needs the generator model of a synthetic dataset "
                                             r"\(dataset=PATH of a psg-data synth dataset; psg-eval sets it for such "
                                             r"datasets\); other datasets have no exact ceiling$"):
        get_estimator("process_oracle").fit([])
    with pytest.raises(EstimatorError, match=r"^process_oracle: edge \('redmug', 'table'\): 'redmug' is not an "
                                             r"entity of the generator model \(is this the dataset the model "
                                             r"belongs to\?\)$"):
        get_estimator("process_oracle", process=tiny_process(0).to_dict()).fit(
            [EdgeStream(("redmug", "table"), np.array([0.0]), np.array([1], np.int8))])


def test_a_state_held_all_week_gives_one_full_day_per_entry() -> None:
    from psg_data.synth._process import _intervals

    want = ["Mon: 00:00 - Tue: 00:00", "Tue: 00:00 - Wed: 00:00", "Wed: 00:00 - Thu: 00:00",
            "Thu: 00:00 - Fri: 00:00", "Fri: 00:00 - Sat: 00:00", "Sat: 00:00 - Sun: 00:00",
            "Sun: 00:00 - Mon: 00:00"]
    assert _intervals(np.ones(14, bool), 2, (9.0, 15.0)) == want
    assert _intervals(np.ones(7, bool), 1, (8.5,)) == want
