"""A conformance check for estimator plugins (scikit-learn's ``check_estimator`` in spirit)."""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from typing import Any, NoReturn

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import EstimatorError, NotFittedError
from psg_data.estimators._base import EdgeStream, PersistenceEstimator

__all__ = ["check_estimator", "conformance_streams", "ESTIMATOR_MEMBERS", "FILTER_MEMBERS"]

_Fail = Callable[[str, str], NoReturn]
_T0 = 1_704_085_200.0  # 2024-01-01 00:00 America/Toronto (a Monday)
ESTIMATOR_MEMBERS = ("fit", "make_filter", "filter_from_state", "get_params")
"""Methods a :class:`~psg_data.estimators.PersistenceEstimator` has."""
FILTER_MEMBERS = ("update", "update_many", "predict", "get_state")
"""Methods an :class:`~psg_data.estimators.EdgeFilter` has (and the ``last_t_s`` attribute)."""


class _Stage:
    """The check being run, so that an unexpected exception is reported under its name."""

    name = "members"


def conformance_streams(days: int = 10, seed: int = 0, start_s: float = _T0) -> list[EdgeStream]:
    """Two small edges with a daily pattern, noisy observations every ~30 min, ground truth in ``meta``."""
    rng = np.random.default_rng(seed)
    out = []
    for e, (on, off) in {("obj_a", "rec_1"): (8, 18), ("obj_b", "rec_2"): (19, 23)}.items():
        gt_t = start_s + np.arange(0, days * 86400, 600.0)
        hour = ((gt_t - start_s) % 86400) / 3600
        gt = ((hour >= on) & (hour < off)).astype(np.int8)
        t = start_s + np.cumsum(rng.uniform(900, 2700, size=int(days * 86400 / 1800)))
        t = t[t < start_s + days * 86400]
        x = gt[np.clip(np.searchsorted(gt_t, t, side="right") - 1, 0, gt.size - 1)]
        y = np.where(rng.random(t.size) < 0.1, 1 - x, x).astype(np.int8)
        out.append(EdgeStream(e, t, y, {"gt_t_s": gt_t, "gt_state": gt}))
    return out


def _fresh(est: PersistenceEstimator) -> PersistenceEstimator:
    return type(est)(**est.get_params())  # type: ignore[call-arg]


def check_estimator(estimator: PersistenceEstimator, *, streams: Sequence[EdgeStream] | None = None,
                    timezone: str = "America/Toronto") -> dict[str, str]:
    """Run the conformance checks on an (unfitted) estimator; raise on the first failure.

    Checks: ``members`` (every method of :data:`ESTIMATOR_MEMBERS` exists; all missing ones are
    named); ``get_params`` returns a dict and ``type(est)(**est.get_params())`` rebuilds it
    (``clone``); ``filter_members`` (every method of :data:`FILTER_MEMBERS` and ``last_t_s``);
    ``fit`` returns self; ``make_filter`` before ``fit`` raises NotFittedError; predictions
    have the query's shape, are finite and in [0, 1]; two fits with equal settings predict
    identically (determinism); ``get_state`` is JSON-serialisable and ``filter_from_state`` restores
    a filter predicting identically, also after further updates; ``update`` one at a time equals
    ``update_many``; ``predict`` does not change the filter; observations earlier than the last one
    raise EstimatorError.

    Args:
        estimator: the estimator to check (constructed with its settings).
        streams: training streams (default :func:`conformance_streams`); the last third of each
            stream is used as test observations.
        timezone: passed to ``fit``.

    Returns:
        {check name: "ok"}.

    Raises:
        EstimatorError: naming the failed check (an exception an estimator raises where it should
            not is reported under the name of the check that was running).
    """
    where = f"check_estimator({type(estimator).__name__})"
    stage = _Stage()

    def fail(check: str, msg: str) -> NoReturn:
        raise EstimatorError(f"{where}: {check}: {msg}")

    try:
        return _run_checks(estimator, streams, timezone, fail, stage)
    except EstimatorError as exc:
        if str(exc).startswith(where):
            raise
        raise EstimatorError(f"{where}: {stage.name}: raised {type(exc).__name__}: {exc}") from exc
    except Exception as exc:  # noqa: BLE001 - a plugin's own bug, reported as the check it broke
        raise EstimatorError(f"{where}: {stage.name}: raised {type(exc).__name__}: {exc}") from exc


def _members(obj: Any, names: Sequence[str]) -> list[str]:
    return [f"{n}()" for n in names if not callable(getattr(obj, n, None))]


def _run_checks(estimator: PersistenceEstimator, streams: Sequence[EdgeStream] | None, timezone: str, fail: _Fail,
                stage: _Stage) -> dict[str, str]:
    missing = _members(estimator, ESTIMATOR_MEMBERS)
    if missing:
        fail("members", f"missing or not callable: {', '.join(missing)} (see psg_data.estimators.BaseEstimator)")
    report: dict[str, str] = {"members": "ok"}
    stage.name = "get_params"
    params = estimator.get_params()
    if not isinstance(params, dict):
        fail("get_params", f"get_params() must return a dict, got {type(params).__name__}")
    try:
        type(estimator)(**params)
    except TypeError as exc:
        fail("get_params", f"type(est)(**est.get_params()) fails ({exc}); the constructor must take every setting "
                           "get_params() returns as a keyword")
    report["get_params"] = "ok"
    data = list(streams) if streams is not None else conformance_streams()
    train, test = _split(data)
    stage.name = "not_fitted"
    try:
        _fresh(estimator).make_filter(data[0].edge)
        fail("not_fitted", "make_filter before fit did not raise NotFittedError")
    except NotFittedError:
        report["not_fitted"] = "ok"
    stage.name = "fit_returns_self"
    est = _fresh(estimator)
    if est.fit(train, val_streams=None, timezone=timezone) is not est:
        fail("fit_returns_self", "fit() must return self")
    report["fit_returns_self"] = "ok"
    stage.name = "filter_members"
    f0 = est.make_filter(train[0].edge)
    missing = _members(f0, FILTER_MEMBERS) + ([] if hasattr(f0, "last_t_s") else ["last_t_s"])
    if missing:
        fail("filter_members", f"the filter ({type(f0).__name__}) misses {', '.join(missing)} "
                               "(see psg_data.estimators.BaseFilter)")
    report["filter_members"] = "ok"
    stage.name = "determinism"
    est2 = _fresh(estimator).fit(train, val_streams=None, timezone=timezone)
    for tr, te in zip(train, test):
        stage.name = "predictions"
        f, q, p = _check_predictions(est, est2, tr, fail)
        stage.name = "state_roundtrip"
        _check_state(est, f, q, p, te, fail)
        stage.name = "time_monotonicity"
        _check_monotonic(f, fail)
    report.update(shape="ok", range="ok", predict_pure="ok", determinism="ok", update_vs_update_many="ok",
                  state_json="ok", state_roundtrip="ok", time_monotonicity="ok", last_t_s="ok")
    return report


def _split(data: Sequence[EdgeStream]) -> tuple[list[EdgeStream], list[EdgeStream]]:
    """Each stream's first two thirds (in time, ground truth kept) for training, the rest for testing."""
    train, test = [], []
    for s in data:
        cut = s.t_s[0] + (s.t_s[-1] - s.t_s[0]) * 2 / 3
        tr = s.between(-np.inf, cut)
        train.append(EdgeStream(s.edge, tr.t_s, tr.y, dict(s.meta)))
        test.append(s.between(cut, np.inf))
    return train, test


def _check_predictions(est: PersistenceEstimator, est2: PersistenceEstimator, tr: EdgeStream,
                       fail: _Fail) -> tuple[Any, NDArray[np.float64], NDArray[np.float64]]:
    """last_t_s, shape, range, predict_pure, determinism, update_vs_update_many on one edge.

    Returns:
        (the filter after the training observations, the query times (s), its predictions).
    """
    f = est.make_filter(tr.edge)
    f.update_many(tr.t_s, tr.y)
    if f.last_t_s != float(tr.t_s[-1]):
        fail("last_t_s", f"last_t_s is {f.last_t_s}, expected {tr.t_s[-1]}")
    q = np.linspace(tr.t_s[-1], tr.t_s[-1] + 3 * 86400, 97)
    p = np.asarray(f.predict(q))
    if p.shape != q.shape:
        fail("shape", f"predict of shape {q.shape} returned {p.shape}")
    p2d = np.asarray(f.predict(q.reshape(-1, 1)))
    if p2d.shape != (q.size, 1):
        fail("shape", f"predict of shape {(q.size, 1)} returned {p2d.shape}")
    if not np.all(np.isfinite(p)) or p.min() < 0 or p.max() > 1:
        fail("range", f"predictions must be finite and in [0, 1], got [{np.nanmin(p)}, {np.nanmax(p)}]")
    if not np.array_equal(np.asarray(f.predict(q)), p):
        fail("predict_pure", "predict changed the filter (second call differs)")
    g = est2.make_filter(tr.edge)
    g.update_many(tr.t_s, tr.y)
    if not np.array_equal(np.asarray(g.predict(q)), p):
        fail("determinism", "two fits with equal settings predict differently")
    one = est.make_filter(tr.edge)
    for ti, yi in zip(tr.t_s, tr.y):
        one.update(float(ti), int(yi))
    if not np.allclose(np.asarray(one.predict(q)), p, rtol=0, atol=1e-9):
        fail("update_vs_update_many", "update() one at a time differs from update_many()")
    return f, q, p


def _check_state(est: PersistenceEstimator, f: Any, q: NDArray[np.float64], p: NDArray[np.float64],
                 te: EdgeStream, fail: _Fail) -> None:
    """state_json and state_roundtrip (also after the test observations ``te``; updates ``f``)."""
    state = f.get_state()
    try:
        text = json.dumps(state, allow_nan=False)
    except (TypeError, ValueError) as exc:
        fail("state_json", f"get_state() is not JSON-serialisable: {exc}")
    h = est.filter_from_state(json.loads(text))
    if not np.array_equal(np.asarray(h.predict(q)), p):
        fail("state_roundtrip", "filter_from_state(get_state()) predicts differently")
    if len(te):
        f.update_many(te.t_s, te.y)
        h.update_many(te.t_s, te.y)
        q2 = np.linspace(te.t_s[-1], te.t_s[-1] + 86400, 25)
        if not np.allclose(np.asarray(h.predict(q2)), np.asarray(f.predict(q2)), rtol=0, atol=1e-12):
            fail("state_roundtrip", "restored filter diverges after further updates")


def _check_monotonic(f: Any, fail: _Fail) -> None:
    """time_monotonicity: observations earlier than the last one raise EstimatorError."""
    last = f.last_t_s
    assert last is not None
    for bad in (lambda: f.update(last - 10.0, 1), lambda: f.update_many([last + 5.0, last + 1.0], [1, 0])):
        try:
            bad()
            fail("time_monotonicity", "an observation earlier than the last one did not raise EstimatorError")
        except EstimatorError as exc:
            if "check_estimator" in str(exc):
                raise
