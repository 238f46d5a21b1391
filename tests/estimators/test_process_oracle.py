"""process_oracle: conformance, the exact posterior of its information set, no peeking in any
processing order, refusal of datasets without a generator model, the CLI on a small lab."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from psg_data.errors import EstimatorError
from psg_data.estimators import EdgeStream, check_estimator, get_estimator
from psg_data.synth import LabConfig, build_lab
from psg_data.schemas._generator_model import StepProcess
from psg_data.synth._process import ForwardBelief, observation_likelihood, sample_entity
from tests.synth.test_process_exact import tiny_process

P = 0.1  # label noise of the streams below (declared to the oracle)


def _streams(proc: StepProcess, days: int, seed: int, noise: float = P) -> list[EdgeStream]:
    """One observation per step (3 minutes after its start) for every receptacle edge, flipped with ``noise``."""
    ent = proc.entities["obj"]
    n = days * proc.n_slots
    path = sample_entity(proc, ent, n, np.random.default_rng(seed))
    t = np.array([proc.clock.step_start_s(i) + 180.0 for i in range(n)])
    rng = np.random.default_rng(seed + 1)
    out = []
    for j, label in enumerate(ent.states):
        if label is None:
            continue
        x = (path.states == j).astype(np.int8)
        y = np.where(rng.random(n) < noise, 1 - x, x).astype(np.int8)
        out.append(EdgeStream(("obj", label), t, y))
    return out


@pytest.fixture()
def proc() -> StepProcess:
    p = tiny_process(11, K=2, S=4)  # edges r0, r1, r2 (and the state absent)
    p.days = 30
    return p


def test_check_estimator(proc: StepProcess) -> None:
    est = get_estimator("process_oracle", process=proc.to_dict(), p_m=P, p_f=P)
    report = check_estimator(est, streams=_streams(proc, 12, 0))
    assert set(report.values()) == {"ok"}


def _reference(proc: StepProcess, obs: list[tuple[float, str, int]], H: float, query: np.ndarray, label: str,
               p: float = P) -> np.ndarray:
    """The posterior from an explicit list of observations with t <= H (independent bookkeeping)."""
    ent = proc.entities["obj"]
    b = ForwardBelief(proc, ent).start()
    for t, lab, y in sorted(o for o in obs if o[0] <= H):
        b.advance_to(int(proc.clock.step_of(np.array([t]))[0]))
        b.observe(observation_likelihood(ent, lab, y, p, p))
    b.advance_to(int(proc.clock.step_of(np.array([H]))[0]))
    steps = proc.clock.step_of(query)
    return b.forecast(np.maximum(steps, b.n))[:, ent.state_index(label)]


def test_prediction_is_the_posterior_of_its_information_set(proc: StepProcess) -> None:
    train = _streams(proc, 10, 3)
    est = get_estimator("process_oracle", process=proc.to_dict(), p_m=P, p_f=P).fit(train)
    own = train[0]
    cut = own.t_s[11]  # the filter knows its edge up to step 11 only
    f = est.make_filter(own.edge)
    f.update_many(own.t_s[:12], own.y[:12])
    q = np.linspace(cut, cut + 5 * 86400, 50)
    obs = [(t, s.edge[1], int(y)) for s in train for t, y in zip(s.t_s, s.y) if s.edge != own.edge or t <= cut]
    np.testing.assert_allclose(f.predict(q), _reference(proc, obs, cut, q, own.edge[1]), atol=1e-12)
    med = get_estimator("process_oracle", process=proc.to_dict(), p_m=P, p_f=P, output="median").fit(train)
    m = med.make_filter(own.edge)
    m.update_many(own.t_s[:12], own.y[:12])
    np.testing.assert_array_equal(m.predict(q), (f.predict(q) >= 0.5).astype(float))
    # a filter without observations predicts the prior marginal
    g = est.make_filter(train[1].edge)
    np.testing.assert_allclose(g.predict(q[:3]), _reference(proc, [], -np.inf, q[:3], train[1].edge[1]), atol=1e-12)


def _run(proc: StepProcess, train: list[EdgeStream], test: list[EdgeStream], order: list[int], H_x: float,
         share: bool) -> list[np.ndarray]:
    """Edge 0 is fed up to H_x first; the others then run their whole test streams in ``order``,
    edge 0 predicting after each sibling update. Returns edge 0's predictions."""
    est = get_estimator("process_oracle", process=proc.to_dict(), p_m=P, p_f=P, share_updates=share).fit(train)
    filters = [est.make_filter(s.edge) for s in train]
    for f, s in zip(filters[1:], train[1:]):
        f.update_many(s.t_s, s.y)
    x = filters[0]
    t0 = np.concatenate([train[0].t_s, test[0].t_s])
    y0 = np.concatenate([train[0].y, test[0].y])
    t0, idx = np.unique(t0, return_index=True)
    keep = t0 <= H_x
    x.update_many(t0[keep], y0[idx][keep])
    q = np.linspace(H_x, H_x + 3 * 86400, 30)
    preds = [x.predict(q)]
    for i in order:
        for t, y in zip(test[i].t_s, test[i].y):
            if t <= (filters[i].last_t_s or -np.inf):
                continue  # already in its (longer) training stream
            filters[i].update(float(t), int(y))
            preds.append(x.predict(q))
    return preds


@pytest.mark.parametrize("share", [False, True])
def test_never_uses_an_observation_after_the_filters_last_update(proc: StepProcess, share: bool) -> None:
    """Whatever order the siblings run in, changing their observations after edge 0's last update
    time (training or test, seen directly or through the tracker) leaves edge 0's predictions equal."""
    streams = _streams(proc, 14, 5)
    cut = streams[0].t_s[8 * proc.n_slots]
    train = [s.between(-np.inf, cut) for s in streams]
    test = [s.between(cut, np.inf) for s in streams]
    H_x = float(test[0].t_s[5])

    def flipped(ss: list[EdgeStream]) -> list[EdgeStream]:
        return [s if k == 0 else EdgeStream(s.edge, s.t_s, np.where(s.t_s > H_x, 1 - s.y, s.y)) for k, s in enumerate(ss)]

    train_late = [s.between(-np.inf, H_x + 3 * 86400) for s in streams]  # training data reaching past H_x
    for order in itertools.permutations(range(1, len(streams))):
        a = _run(proc, train, test, list(order), H_x, share)
        b = _run(proc, flipped(train), flipped(test), list(order), H_x, share)
        for pa, pb in zip(a, b):
            np.testing.assert_array_equal(pa, pb)
        c = _run(proc, train_late, test, list(order), H_x, share)
        d = _run(proc, flipped(train_late), flipped(test), list(order), H_x, share)
        np.testing.assert_array_equal(c[0], d[0])
    if share:  # the tracker does pass on sibling test observations up to H_x
        assert not np.allclose(a[0], a[-1])
    else:
        assert all(np.array_equal(a[0], p) for p in a)


def test_refuses_missing_or_wrong_models(tmp_path: Path, make_dataset) -> None:  # type: ignore[no-untyped-def]
    streams = [EdgeStream(("redmug", "table"), np.array([0.0, 1.0]), np.array([1, 0]))]
    with pytest.raises(EstimatorError, match="needs the generator model of a synthetic dataset"):
        get_estimator("process_oracle").fit(streams)
    ds = make_dataset("tiny")
    with pytest.raises(EstimatorError, match=r"no generator process \(generator/process.json\)") as exc:
        get_estimator("process_oracle", dataset=str(ds)).fit(streams)
    assert "\n" not in str(exc.value)
    with pytest.raises(EstimatorError, match="not an entity of the generator model"):
        get_estimator("process_oracle", process=tiny_process(0).to_dict()).fit(streams)


@pytest.fixture(scope="module")
def lab(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return build_lab(tmp_path_factory.mktemp("oracle") / "lab",
                     LabConfig(seed=4, days=6, train_days=4, frames_per_scan=2, width=48, height=36))


def test_cli_runs_the_oracle_and_the_schedule_and_oracle_priors(lab: Path, tmp_path: Path) -> None:
    from psg_data.cli.psg_eval_cmd import main

    out = tmp_path / "res"
    res = CliRunner().invoke(main, ["--dataset", str(lab), "-e", "process_oracle", "-e", "perpetua_star_schedule",
                                    "-e", "perpetua_star_oracle", "-e", "last_seen", "--no-references", "--seeds", "1",
                                    "--setting", "predictive", "--out", str(out), "--quiet", "--no-plots"])
    assert res.exit_code == 0, res.output + str(res.exception)
    from psg_data.evaluation import load_results

    data = load_results(out)
    table = data.table()
    assert {r.method for r in table.rows} == {"process_oracle", "perpetua_star_schedule", "perpetua_star_oracle",
                                             "last_seen"}
    assert not data.errors
    assert table.row("process_oracle").values["mae"].mean < table.row("last_seen").values["mae"].mean
    assert data.config["estimator_params"]["process_oracle"]["dataset"] == str(lab)


def test_cli_refuses_the_oracle_on_other_datasets(make_dataset, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    from psg_data.cli.psg_eval_cmd import main

    ds = make_dataset("tiny", scans=4)
    res = CliRunner().invoke(main, ["--dataset", str(ds), "-e", "process_oracle", "--no-references", "--seeds", "1",
                                    "--out", str(tmp_path / "o"), "--quiet"])
    assert res.exit_code == 1
    lines = [ln for ln in res.output.splitlines() if ln.startswith("error:")]
    assert len(lines) == 1 and "process_oracle needs a synthetic dataset" in lines[0], res.output


def test_navigation_with_the_oracle(lab: Path) -> None:
    from psg_data.navigation import run_navigation

    res = run_navigation(lab, {"process_oracle": "process_oracle", "last_seen": "last_seen"}, seed=0, n_queries=30,
                         setting="predictive", reachable_only=True,
                         estimator_settings={"process_oracle": {"dataset": str(lab)}}, keep_trails=False)
    table = res.summary
    assert {"process_oracle", "last_seen"} <= set(table["method"] if "method" in table else table.iloc[:, 0])


def test_a_state_without_own_observations_restores_a_fresh_filter(proc: StepProcess) -> None:
    train = _streams(proc, 6, 5)
    est = get_estimator("process_oracle", process=proc.to_dict(), p_m=P, p_f=P).fit(train)
    edge = train[0].edge
    q = np.linspace(train[0].t_s[-1], train[0].t_s[-1] + 2 * 86400, 7)
    bare = est.filter_from_state({"estimator": "process_oracle", "edge": list(edge)})
    assert bare.last_t_s is None
    np.testing.assert_allclose(bare.predict(q), est.make_filter(edge).predict(q), rtol=0, atol=0)
    f = est.make_filter(edge)
    f.update_many(train[0].t_s[:5], train[0].y[:5])
    back = est.filter_from_state(json.loads(json.dumps(f.get_state())))
    assert back.last_t_s == f.last_t_s
    np.testing.assert_allclose(back.predict(q), f.predict(q), rtol=0, atol=1e-15)


def test_a_deep_copy_is_independent_and_predicts_the_same(proc: StepProcess) -> None:
    import copy

    train = _streams(proc, 6, 6)
    for share in (False, True):
        est = get_estimator("process_oracle", process=proc.to_dict(), p_m=P, p_f=P, share_updates=share).fit(train)
        f = est.make_filter(train[0].edge)
        f.update_many(train[0].t_s[:6], train[0].y[:6])
        q = np.linspace(train[0].t_s[6], train[0].t_s[6] + 86400, 5)
        before = f.predict(q)
        g = copy.deepcopy(f)
        np.testing.assert_array_equal(g.predict(q), before)
        g.update_many(train[0].t_s[6:9], 1 - train[0].y[6:9])  # the copy learns, the original does not
        assert g.last_t_s == train[0].t_s[8] and f.last_t_s == train[0].t_s[5]
        np.testing.assert_array_equal(f.predict(q), before)
        assert f.get_state()["own_t"] == train[0].t_s[:6].tolist()
        fresh = est.make_filter(train[0].edge)
        fresh.update_many(train[0].t_s[:6], train[0].y[:6])
        fresh.update_many(train[0].t_s[6:9], 1 - train[0].y[6:9])
        np.testing.assert_allclose(g.predict(q), fresh.predict(q), rtol=0, atol=1e-15)


def test_deep_copies_keep_the_shared_tracker_and_a_fresh_filter_copies(proc: StepProcess) -> None:
    import copy

    streams = _streams(proc, 10, 7)
    cut = streams[0].t_s[6 * proc.n_slots]
    train = [s.between(-np.inf, cut) for s in streams]
    test = [s.between(cut, np.inf) for s in streams]
    est = get_estimator("process_oracle", process=proc.to_dict(), p_m=P, p_f=P, share_updates=True).fit(train)
    fresh = est.make_filter(train[0].edge)
    q = np.linspace(test[0].t_s[5], test[0].t_s[5] + 86400, 5)
    np.testing.assert_array_equal(copy.deepcopy(fresh).predict(q), fresh.predict(q))  # no belief yet
    f, g = est.make_filter(train[0].edge), est.make_filter(train[1].edge)
    f.update_many(np.concatenate([train[0].t_s, test[0].t_s[:6]]), np.concatenate([train[0].y, test[0].y[:6]]))
    g.update_many(np.concatenate([train[1].t_s, test[1].t_s[:2]]), np.concatenate([train[1].y, test[1].y[:2]]))
    # the sibling's observations after the training data reach f through the tracker, and its copy
    np.testing.assert_array_equal(copy.deepcopy(f).predict(q), f.predict(q))
    fc, gc = copy.deepcopy([f, g])  # copied together: the copies share one (copied) tracker
    t3, y3 = float(test[1].t_s[2]), int(1 - test[1].y[2])
    before = fc.predict(q)
    g.update(t3, y3)
    gc.update(t3, y3)
    np.testing.assert_array_equal(fc.predict(q), f.predict(q))
    assert not np.array_equal(fc.predict(q), before)
