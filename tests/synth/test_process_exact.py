"""The forward algorithm of the step process against brute-force enumeration of every path.

The enumeration follows the generative description (pattern draw at the first step of a day,
routine placement with probability rho, else hold or jump, fresh dwells uniform in whole steps)
step by step, with no shared code beyond the model's parameters.
"""

from __future__ import annotations

import datetime as dt

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from psg_data.schemas._generator_model import EntityProcess, StepProcess
from psg_data.synth._process import ForwardBelief, llm_schedules, observation_likelihood

START = dt.date(2025, 3, 7)  # a Friday: day 1 is a Saturday (weekend mask)


def tiny_process(seed: int, *, K: int = 2, S: int = 3, D: int = 2, max_hi: int = 2, absent: bool = True,
                 rho: float | None = None) -> StepProcess:
    rng = np.random.default_rng(seed)
    states = tuple([f"r{i}" for i in range(S - 1)] + [None if absent else f"r{S - 1}"])
    allowed = np.ones((7, D), bool)
    allowed[5:, 0] = False  # weekends: pattern 0 not allowed
    lo = rng.integers(1, max_hi + 1, size=(D, S))
    hi = np.minimum(lo + rng.integers(0, 2, size=(D, S)), max_hi)
    ent = EntityProcess(
        "obj", "object", "dynamic", states, tuple(f"p{i}" for i in range(D)), allowed, rng.dirichlet(np.ones(D)),
        rng.dirichlet(np.ones(D), size=D), rng.dirichlet(np.ones(S)), rng.integers(0, S, size=(D, K)),
        np.full((D, K), rho) if rho is not None else rng.uniform(0, 1, size=(D, K)),
        rng.dirichlet(np.ones(S), size=(D, S)), np.stack([lo, hi], axis=-1))
    return StepProcess("America/Toronto", START, 3, tuple(9.0 + 2 * k for k in range(K)), {"obj": ent})


def brute_force(proc: StepProcess, ent: EntityProcess, n_steps: int, obs: dict[int, list[tuple[str | None, int]]],
                p_m: float, p_f: float) -> tuple[np.ndarray, float]:
    """P(state at step n_steps - 1 | observations) and the evidence, by enumerating every path."""
    K = proc.n_slots
    post = np.zeros(ent.n_states)

    def lik(n: int, s: int) -> float:
        out = 1.0
        for label, y in obs.get(n, []):
            at = ent.states[s] == label
            p1 = (1 - p_m) if at else p_f
            out *= p1 if y == 1 else 1 - p1
        return out

    def rec(n: int, p: int, s: int, r: int, w: float) -> None:
        if w == 0.0:
            return
        if n == n_steps:
            post[s] += w
            return
        day, k = divmod(n, K)
        if k == 0:
            allowed = proc.allowed(ent, day).astype(float)
            row = ent.pattern_initial * allowed if day == 0 else ent.pattern_transition[p] * allowed
            choices = [(q, row[q] / row.sum()) for q in range(ent.n_patterns) if row[q] > 0]
        else:
            choices = [(p, 1.0)]
        for q, wq in choices:
            rho = ent.routine_strength[q, k]
            moves: list[tuple[int, int, float]] = []
            lo, hi = 0, 0
            s_r = int(ent.routine[q, k])
            lo, hi = ent.dwell[q, s_r]
            moves += [(s_r, d, rho / (hi - lo + 1)) for d in range(lo, hi + 1)]
            if r > 1:
                moves.append((s, r - 1, 1 - rho))
            else:
                for s2 in range(ent.n_states):
                    lo, hi = ent.dwell[q, s2]
                    moves += [(s2, d, (1 - rho) * ent.jump[q, s, s2] / (hi - lo + 1)) for d in range(lo, hi + 1)]
            for s2, r2, wm in moves:
                rec(n + 1, q, s2, r2, w * wq * wm * lik(n, s2))

    for s0 in range(ent.n_states):
        rec(0, -1, s0, 1, float(ent.state_initial[s0]))
    z = post.sum()
    return post / z, float(z)


def forward(proc: StepProcess, ent: EntityProcess, n_steps: int, obs: dict[int, list[tuple[str | None, int]]],
            p_m: float, p_f: float) -> tuple[np.ndarray, float]:
    b = ForwardBelief(proc, ent).start()
    for n in range(n_steps):
        b.advance_to(n)
        for label, y in obs.get(n, []):
            b.observe(observation_likelihood(ent, label, y, p_m, p_f))
    return b.state_marginal(), float(np.exp(b.log_evidence))


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_forward_equals_brute_force(seed: int) -> None:
    proc = tiny_process(seed)
    ent = proc.entities["obj"]
    obs = {0: [("r0", 1)], 2: [("r1", 0)], 3: [("r0", 0), ("r1", 0)]}
    for n_steps in (1, 3, 5):  # n_steps = 5: forecast one step past the last observation, across a night
        want, z_want = brute_force(proc, ent, n_steps, obs, 0.1, 0.05)
        got, z_got = forward(proc, ent, n_steps, obs, 0.1, 0.05)
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)
        np.testing.assert_allclose(z_got, z_want, rtol=1e-9)


def test_noise_free_observations_and_clockwork() -> None:
    proc = tiny_process(7, rho=1.0)
    ent = proc.entities["obj"]
    got, _ = forward(proc, ent, 4, {}, 0.0, 0.0)
    want, _ = brute_force(proc, ent, 4, {}, 0.0, 0.0)
    np.testing.assert_allclose(got, want, atol=1e-9)
    proc = tiny_process(8, rho=0.0)
    ent = proc.entities["obj"]
    obs = {1: [("r1", 1)]}
    np.testing.assert_allclose(forward(proc, ent, 4, obs, 0.0, 0.0)[0], brute_force(proc, ent, 4, obs, 0.0, 0.0)[0],
                               atol=1e-9)


@settings(max_examples=12, deadline=None)
@given(st.integers(0, 10_000), st.integers(1, 5), st.lists(st.tuples(st.integers(0, 4), st.integers(0, 2),
                                                                     st.integers(0, 1)), max_size=4))
def test_forward_equals_brute_force_property(seed: int, n_steps: int, raw: list[tuple[int, int, int]]) -> None:
    proc = tiny_process(seed, max_hi=2)
    ent = proc.entities["obj"]
    obs: dict[int, list[tuple[str | None, int]]] = {}
    for n, j, y in raw:
        if n < n_steps:
            obs.setdefault(n, []).append((ent.states[j], y))
    want, z = brute_force(proc, ent, n_steps, obs, 0.2, 0.1)
    got, z2 = forward(proc, ent, n_steps, obs, 0.2, 0.1)
    np.testing.assert_allclose(got, want, atol=1e-9)
    np.testing.assert_allclose(z2, z, rtol=1e-9)


def test_json_round_trip_and_problems() -> None:
    proc = tiny_process(3)
    back = StepProcess.from_dict(proc.to_dict())
    e0, e1 = proc.entities["obj"], back.entities["obj"]
    for name in ("pattern_transition", "jump", "dwell", "routine", "routine_strength", "pattern_allowed"):
        np.testing.assert_allclose(getattr(e1, name), getattr(e0, name), atol=1e-12)
    assert e1.states == e0.states and back.step_hours == proc.step_hours
    bad = proc.to_dict()
    bad["entities"][0]["jump"][0][0] = [0.5, 0.5, 0.5]
    with pytest.raises(Exception, match="jump: rows must be probability distributions"):
        StepProcess.from_dict(bad)


def test_llm_schedules_follow_the_modal_routine() -> None:
    proc = tiny_process(4, K=2, rho=1.0)
    ent = proc.entities["obj"]
    ent.pattern_transition[:] = [[0.0, 1.0], [0.0, 1.0]]  # always pattern 1 after day 0
    ent.routine[1] = [0, 1]
    sched = llm_schedules(proc)
    # slot 0 (09-11) on r0 every day; slot 1 (11-13, the last: until 09:00 next day) on r1
    assert sched[("obj", "r0")] == [f"{d}: 09:00 - {d}: 11:00" for d in ("Mon", "Tue", "Wed", "Thu", "Fri", "Sat", "Sun")]
    assert sched[("obj", "r1")][0] == "Mon: 11:00 - Tue: 09:00" and len(sched[("obj", "r1")]) == 7
    assert ("obj", "None") not in sched
    from psg_data.estimators import parse_llm_schedule

    assert len(parse_llm_schedule(repr(sched[("obj", "r1")]))) == 7


def test_forecast_is_each_steps_marginal_in_any_order_without_moving_the_belief() -> None:
    proc = tiny_process(5)
    ent = proc.entities["obj"]
    b = ForwardBelief(proc, ent).start()
    b.advance_to(2)
    b.observe(observation_likelihood(ent, "r0", 1, 0.1, 0.05))
    alpha, n = b.alpha.copy(), b.n
    assert b.forecast([]).shape == (0, ent.n_states)

    def marginal(step: int) -> np.ndarray:
        c = b.copy()
        c.advance_to(max(step, n))
        return c.state_marginal()

    np.testing.assert_allclose(b.forecast([5])[0], marginal(5), rtol=0, atol=1e-15)
    steps = [6, 2, 4, 6, 0, 3]  # unsorted, repeated, and before the current step (0: the current one)
    got = b.forecast(np.array(steps))
    assert got.shape == (len(steps), ent.n_states)
    for row, s in zip(got, steps):
        np.testing.assert_allclose(row, marginal(s), rtol=0, atol=1e-15)
    np.testing.assert_array_equal(b.alpha, alpha)
    assert b.n == n


def test_weekday_pattern_marginals_long_run_closed_forms() -> None:
    import dataclasses

    from psg_data.synth._process import weekday_pattern_marginals

    proc = tiny_process(6)
    ent = proc.entities["obj"]
    got = weekday_pattern_marginals(proc, ent)
    assert got.shape == (7, ent.n_patterns)
    # the periodic stationary law of the day chain: the eigenvector of one week's product of day matrices
    first = 7  # a day index whose weekday is the start's
    week = np.linalg.multi_dot([proc.day_matrix(ent, first + d) for d in range(1, 8)])
    w, v = np.linalg.eig(week.T)
    pi = np.real(v[:, np.argmin(np.abs(w - 1))])
    pi = pi / pi.sum()
    want = np.zeros((7, ent.n_patterns))
    p = pi
    for d in range(1, 8):
        p = p @ proc.day_matrix(ent, first + d)
        want[proc.clock.weekday(first + d)] = p
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    # a chain that alternates its two patterns every day never settles: each weekday sees each
    # pattern in every other week, so the long-run frequency is 1/2 (an average over whole weeks pairs)
    alt = dataclasses.replace(ent, pattern_allowed=np.ones((7, 2), bool),
                              pattern_transition=np.array([[0.0, 1.0], [1.0, 0.0]]))
    np.testing.assert_allclose(weekday_pattern_marginals(proc, alt), np.full((7, 2), 0.5), rtol=0, atol=1e-15)


def test_save_process_writes_the_json_document_and_replaces_a_file(tmp_path) -> None:  # type: ignore[no-untyped-def]
    import json

    from psg_data.synth._process import save_process

    proc = tiny_process(9)
    out = tmp_path / "process.json"
    out.write_text("old", encoding="utf-8")
    save_process(proc, out)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["process.json"]
    text = out.read_text(encoding="utf-8")
    assert text == proc.to_json()
    assert StepProcess.from_dict(json.loads(text)).to_json() == text
    save_process(proc, str(out))  # a str path as well
    assert out.read_text(encoding="utf-8") == text


def _slot_minutes(d: int, s: int, hours: tuple[float, ...]) -> int:
    return d * 1440 + int(round(hours[s] * 60))


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 4), st.data())
def test_intervals_cover_exactly_the_on_slots_in_maximal_runs(K: int, data: st.DataObject) -> None:
    """Decode the 'Day: HH:MM - Day: HH:MM' strings back to slots: every on slot once, no off slot,
    one interval per maximal run of on slots around the week (Sunday's last slot runs into Monday)."""
    from psg_data.synth._process import WEEKDAYS, _intervals

    hours = tuple(sorted(data.draw(st.sets(st.integers(0, 23), min_size=K, max_size=K))))
    n = 7 * K
    on = np.array(data.draw(st.lists(st.booleans(), min_size=n, max_size=n)))
    got = _intervals(on, K, hours)
    starts = {_slot_minutes(d, s, hours): d * K + s for d in range(7) for s in range(K)}
    if on.all():
        assert got == [f"{WEEKDAYS[d]}: 00:00 - {WEEKDAYS[(d + 1) % 7]}: 00:00" for d in range(7)]
        return
    covered: list[int] = []
    for text in got:
        a, b = text.split(" - ")
        t0 = WEEKDAYS.index(a[:3]) * 1440 + int(a[5:7]) * 60 + int(a[8:10])
        t1 = WEEKDAYS.index(b[:3]) * 1440 + int(b[5:7]) * 60 + int(b[8:10])
        i = starts[t0]
        while True:  # walk the slots from the interval's start until the one that ends at t1
            covered.append(i)
            nxt = (i + 1) % n
            if _slot_minutes(nxt // K, nxt % K, hours) == t1:
                break
            i = nxt
            assert len(covered) <= n
    assert sorted(covered) == list(np.flatnonzero(on))
    runs = sum(1 for i in range(n) if on[i] and not on[i - 1])  # circular run starts
    assert len(got) == runs
    keys = [(WEEKDAYS.index(s[:3]), s[5:10]) for s in got]
    assert keys == sorted(keys)


def test_llm_schedules_skip_an_absent_state_anywhere_in_the_list() -> None:
    import dataclasses

    proc = tiny_process(4, K=2, rho=1.0)
    ent = proc.entities["obj"]
    moved = dataclasses.replace(ent, states=("r0", None, "r2"))
    proc.entities["obj"] = moved
    sched = llm_schedules(proc)
    assert set(sched) == {("obj", "r0"), ("obj", "r2")}


def test_intervals_with_a_single_off_slot_wrap_around_the_week() -> None:
    from psg_data.synth._process import _intervals

    on = np.ones(14, bool)
    on[5] = False  # K = 2: only Wednesday's second slot (15:00 until Thursday 09:00) is off
    assert _intervals(on, 2, (9.0, 15.0)) == ["Thu: 09:00 - Wed: 15:00"]  # one run, around the week
