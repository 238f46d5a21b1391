"""Generator steps-v2: the sampled schedules follow the stored model (chi-square at 1e5 steps),
dwell times are uniform in whole steps, states change only at step boundaries, the stored schedule
is the physical state at every scan, and the forward algorithm matches Monte Carlo on the lab."""

from __future__ import annotations

import dataclasses
import datetime as dt

import numpy as np
import pytest
from scipy import stats

from psg_data.synth import LabConfig, LabModel, make_layout
from psg_data.synth._lab_process import ProcessParams, lab_process
from psg_data.schemas._generator_model import StepProcess, load_process
from psg_data.synth._process import ForwardBelief, observation_likelihood, sample_entity

START = dt.date(2025, 3, 3)
TZ = "America/Toronto"
N_STEPS = 100_000
P_MIN = 1e-3


@pytest.fixture(scope="module")
def process() -> StepProcess:
    return lab_process(make_layout(0), 0, START, 21, TZ, (9.0, 11.0, 13.0, 15.0), ProcessParams())


def _chi2(observed: np.ndarray, expected_p: np.ndarray) -> float:
    keep = expected_p > 0
    assert observed[~keep].sum() == 0, "an outcome of probability 0 occurred"
    obs = observed[keep]
    if obs.sum() == 0 or keep.sum() < 2:
        return 1.0
    return float(stats.chisquare(obs, expected_p[keep] / expected_p[keep].sum() * obs.sum()).pvalue)


@pytest.mark.parametrize("entity", ["redbowl", "headphones", "door_bc"])
def test_transition_and_dwell_frequencies_match_the_model(process: StepProcess, entity: str) -> None:
    ent = process.entities[entity]
    path = sample_entity(process, ent, N_STEPS, np.random.default_rng(5))
    K, D, S = process.n_slots, ent.n_patterns, ent.n_states
    # day level: (pattern yesterday -> pattern today), rows per weekday mask
    masks: dict[tuple[bool, ...], list[int]] = {}
    for d in range(1, path.patterns.size):
        masks.setdefault(tuple(process.allowed(ent, d)), []).append(d)
    pvals = []
    for days in masks.values():
        M = process.day_matrix(ent, days[0])
        prev, cur = path.patterns[np.array(days) - 1], path.patterns[np.array(days)]
        for p in range(D):
            pvals.append(_chi2(np.bincount(cur[prev == p], minlength=D), M[p]))
    # hour level: routine placements happen with probability rho[p, k]
    n = np.arange(N_STEPS)
    pat = path.patterns[n // K]
    slot = n % K
    for p in range(D):
        for k in range(K):
            m = (pat == p) & (slot == k)
            rho = ent.routine_strength[p, k]
            hits = int(np.sum(path.events[m] == 0))
            pvals.append(float(stats.binomtest(hits, int(m.sum()), rho).pvalue) if 0 < rho < 1 else 1.0)
            assert rho < 1 or hits == m.sum()
    # jumps (dwell ran out, no routine): target ~ jump[p, s, :]
    prev_state = np.concatenate([[path.before], path.states[:-1]])
    for p in range(D):
        for s in range(S):
            m = (path.events == 2) & (pat == p) & (prev_state == s)
            pvals.append(_chi2(np.bincount(path.states[m], minlength=S), ent.jump[p, s]))
    # fresh dwells uniform on lo..hi
    for p in range(D):
        for s in range(S):
            m = (path.events != 1) & (pat == p) & (path.states == s)
            lo, hi = ent.dwell[p, s]
            if hi > lo:
                pvals.append(_chi2(np.bincount(path.fresh[m] - lo, minlength=hi - lo + 1), np.ones(hi - lo + 1)))
            else:
                assert np.all(path.fresh[m] == lo)
    assert min(pvals) > P_MIN, sorted(pvals)[:3]


def test_observed_stays_uniform_in_whole_steps(process: StepProcess) -> None:
    """Without routine and self-jumps a stay lasts exactly its dwell: stay lengths are uniform."""
    ent = dataclasses.replace(process.entities["greenbowl"])
    ent.routine_strength = np.zeros_like(ent.routine_strength)
    j = ent.jump.copy()
    j[:, np.arange(ent.n_states), np.arange(ent.n_states)] = 0.0
    ent.jump = j / j.sum(axis=-1, keepdims=True)
    path = sample_entity(process, ent, N_STEPS, np.random.default_rng(9))
    change = np.flatnonzero(np.diff(path.states) != 0) + 1
    runs_state = path.states[change[:-1]]
    runs_len = np.diff(change)
    for s in range(ent.n_states):
        lo, hi = ent.dwell[0, s]  # the same dwell ranges in every pattern
        lens = runs_len[runs_state == s]
        assert lens.min() >= lo and lens.max() <= hi
        if hi > lo:
            assert _chi2(np.bincount(lens - lo, minlength=hi - lo + 1), np.ones(hi - lo + 1)) > P_MIN


def test_states_change_only_at_step_starts() -> None:
    lab = LabModel(LabConfig(seed=1, days=9, frames_per_scan=1, width=32, height=24))
    sched = lab.schedule
    starts = set(sched.step_starts_ns.tolist())
    for tl in [*sched.objects.values(), *sched.doors.values()]:
        assert set(tl.change_ns[1:].tolist()) <= starts
        assert tl.change_ns[0] == sched.start_ns
    # one scan per step, inside it
    assert len(lab.scans) == sched.step_starts_ns.size
    for plan, a in zip(lab.scans, sched.step_starts_ns):
        assert a <= plan.start_ns <= plan.stamps_ns.max() < a + 2 * 3600 * 10**9


def test_schedule_table_is_the_state_at_every_scan_time(small_dataset, small_lab) -> None:  # type: ignore[no-untyped-def]
    sched = small_dataset.table("schedule").to_pandas().astype(object).where(lambda d: d.notna(), None)
    doors = small_dataset.df("door_states")
    for scan in small_dataset.scans:
        rows = sched[sched.scan_id == scan.scan_id]
        drow = doors[doors.scan_id == scan.scan_id]
        for t in (scan.start_stamp_ns, *scan.stamps_ns.tolist(), scan.end_stamp_ns):
            truth = small_lab.schedule.objects_at(int(t))
            assert dict(zip(rows.object_id, rows.receptacle_id)) == truth
            dt_ = small_lab.schedule.doors_at(int(t))
            assert {d: s == "open" for d, s in zip(drow.door_id, drow.state)} == dt_


def test_stored_process_rebuilds_the_schedule(small_dataset_path, small_lab) -> None:  # type: ignore[no-untyped-def]
    proc = load_process(small_dataset_path)
    assert proc.to_dict() == small_lab.schedule.process.to_dict()
    for i, (eid, ent) in enumerate(proc.entities.items()):
        path = sample_entity(proc, ent, proc.n_steps, np.random.default_rng([small_lab.config.seed, 621, i]))
        np.testing.assert_array_equal(path.states, small_lab.schedule.paths[eid].states)


def test_routine_strength_ranges_from_random_walk_to_clockwork() -> None:
    clock = LabModel(LabConfig(seed=2, days=14, routine_strength=1.0, frames_per_scan=1, width=32, height=24))
    proc = clock.schedule.process
    K = proc.n_slots
    for eid, path in clock.schedule.paths.items():
        ent = proc.entities[eid]
        pat = path.patterns[np.arange(path.states.size) // K]
        np.testing.assert_array_equal(path.states, ent.routine[pat, np.arange(path.states.size) % K])
    walk = LabModel(LabConfig(seed=2, days=14, routine_strength=0.0, frames_per_scan=1, width=32, height=24))
    moving = [e for e, ent in walk.schedule.process.entities.items() if ent.n_states > 1]
    assert len(moving) == 16 and all(np.all(walk.schedule.paths[e].events != 0) for e in moving)
    with pytest.raises(Exception, match="routine_strength"):
        LabConfig(routine_strength=1.5)


def test_forward_matches_monte_carlo_on_the_lab(process: StepProcess) -> None:
    """Forecasts after an observed state equal the frequencies over sampled paths that show it."""
    ent = process.entities["redbowl"]
    M, n_obs, horizon = 6000, 9, 10
    paths = np.stack([sample_entity(process, ent, n_obs + horizon, np.random.default_rng([77, m])).states
                      for m in range(M)])
    b = ForwardBelief(process, ent).start()
    b.advance_to(n_obs)
    j = int(np.argmax(b.state_marginal()))
    b.observe(observation_likelihood(ent, ent.states[j], 1, 0.0, 0.0))
    want = b.forecast(np.arange(n_obs, n_obs + horizon))
    keep = paths[:, n_obs] == j
    assert keep.sum() > 1000
    emp = np.stack([np.bincount(paths[keep, n], minlength=ent.n_states) / keep.sum()
                    for n in range(n_obs, n_obs + horizon)])
    se = np.sqrt(np.maximum(want * (1 - want), 1e-4) / keep.sum())
    assert np.all(np.abs(emp - want) < 4.5 * se + 1e-9), np.max(np.abs(emp - want) / se)
    prior = ForwardBelief(process, ent).start().forecast(np.arange(n_obs + horizon))
    emp0 = np.stack([np.bincount(paths[:, n], minlength=ent.n_states) / M for n in range(n_obs + horizon)])
    assert np.all(np.abs(emp0 - prior) < 4.5 * np.sqrt(np.maximum(prior * (1 - prior), 1e-4) / M))
