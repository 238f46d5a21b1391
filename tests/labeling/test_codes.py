"""Privileged codes, noise injection and error-rate estimates."""

from __future__ import annotations

import numpy as np
import pytest

from psg_data.errors import LabelingError
from psg_data.labeling import LabelGrid, binomial_interval, error_rates, inject_noise, privileged_codes


def _grid(codes: np.ndarray, source: str = "gt") -> LabelGrid:
    S, O, R = codes.shape
    return LabelGrid([f"s{i}" for i in range(S)], [f"o{i}" for i in range(O)], [f"r{i}" for i in range(R)],
                     np.arange(S, dtype=np.int64) * 10**9, codes, source)


def _reference_code(gt: int, obj_vis: bool, rec_vis: bool) -> int:
    """The paper's case list, literally, in priority order."""
    if gt == -2:
        return -2
    if gt == 1 and obj_vis:
        return 1
    if gt == 0 and rec_vis:
        return 0
    return -1


def test_privileged_codes_every_case() -> None:
    rng = np.random.default_rng(0)
    S, O, R = 6, 4, 5
    present_rec = rng.integers(-1, R, (S, O))  # -1: object absent from every receptacle
    gt = np.zeros((S, O, R), np.int8)
    for s in range(S):
        for o in range(O):
            if present_rec[s, o] >= 0:
                gt[s, o, present_rec[s, o]] = 1
    gt[:, 0, 4] = -2
    rv = rng.random((S, R)) < 0.5
    ov = rng.random((S, O)) < 0.5
    got = privileged_codes(_grid(gt), rv, ov).codes
    for s in range(S):
        for o in range(O):
            for r in range(R):
                assert got[s, o, r] == _reference_code(gt[s, o, r], ov[s, o], rv[s, r])
    # default object visibility: the object's ground-truth receptacle is visible
    got_default = privileged_codes(_grid(gt), rv).codes
    for s in range(S):
        for o in range(O):
            vis = present_rec[s, o] >= 0 and rv[s, present_rec[s, o]]
            for r in range(R):
                assert got_default[s, o, r] == _reference_code(gt[s, o, r], bool(vis), rv[s, r])
    # present, object hidden, receptacle visible: -1 (the documented choice)
    one = np.ones((1, 1, 1), np.int8)
    assert privileged_codes(_grid(one), np.ones((1, 1), bool), np.zeros((1, 1), bool)).codes[0, 0, 0] == -1
    with pytest.raises(LabelingError, match="shape"):
        privileged_codes(_grid(gt), rv[:, :2])


def test_wilson_and_clopper_pearson_against_scipy() -> None:
    from scipy.stats import binomtest

    for k, n in [(0, 10), (3, 10), (50, 500), (10, 10), (1, 3)]:
        for method, sp in (("wilson", "wilson"), ("clopper-pearson", "exact")):
            ref = binomtest(k, n).proportion_ci(0.95, method=sp)
            lo, hi = binomial_interval(k, n, 0.95, method)
            assert lo == pytest.approx(ref.low, abs=1e-9) and hi == pytest.approx(ref.high, abs=1e-9)
    assert binomial_interval(0, 0) == (0.0, 1.0)
    with pytest.raises(LabelingError, match="interval method"):
        binomial_interval(1, 2, method="wald")


def _obs_grid(seed: int, S: int = 200, O: int = 6, R: int = 5) -> LabelGrid:
    rng = np.random.default_rng(seed)
    codes = np.zeros((S, O, R), np.int8)
    codes[np.arange(S)[:, None], np.arange(O)[None], rng.integers(0, R, (S, O))] = 1
    codes[rng.random((S, O, R)) < 0.2] = -1
    codes[:, 0, 0] = -2
    return _grid(codes, "privileged")


def test_noise_rates_within_confidence_interval() -> None:
    base = _obs_grid(0)
    p_m, p_f = 0.1, 0.05
    noisy = inject_noise(base, p_m, p_f, seed=3)
    assert noisy.source == "noisy:0.1,0.05"
    # -1 and -2 untouched, only 1 <-> 0 flips
    keep = ~base.observed
    assert np.array_equal(noisy.codes[keep], base.codes[keep])
    r = error_rates(noisy, base, confidence=0.999)
    assert r.p_m_ci[0] <= p_m <= r.p_m_ci[1] and r.p_f_ci[0] <= p_f <= r.p_f_ci[1]
    assert r.n_present == int((base.codes == 1).sum()) and r.n_absent == int((base.codes == 0).sum())
    # coverage of the 95% Wilson interval over seeds is close to nominal
    hits = 0
    for seed in range(40):
        rr = error_rates(inject_noise(base, p_m, p_f, seed=seed), base)
        hits += int(rr.p_m_ci[0] <= p_m <= rr.p_m_ci[1]) + int(rr.p_f_ci[0] <= p_f <= rr.p_f_ci[1])
    assert hits >= 0.85 * 80
    # determinism and seed dependence
    assert np.array_equal(inject_noise(base, p_m, p_f, seed=3).codes, noisy.codes)
    assert not np.array_equal(inject_noise(base, p_m, p_f, seed=4).codes, noisy.codes)
    with pytest.raises(LabelingError, match="P_M"):
        inject_noise(base, 1.5, 0.1)


def test_error_rates_align_by_id_and_table_roundtrip() -> None:
    base = _obs_grid(1, S=5, O=3, R=4)
    t = base.to_table()
    assert t.num_rows == 5 * 3 * 4
    back = LabelGrid.from_table(t, "privileged")
    assert back.scan_ids == base.scan_ids and np.array_equal(back.codes, base.codes)
    assert np.array_equal(back.stamps_ns, base.stamps_ns)
    # reversed receptacle order: alignment by id gives zero error rates
    perm = LabelGrid(base.scan_ids, base.object_ids, base.receptacle_ids[::-1], base.stamps_ns,
                     base.codes[:, :, ::-1], "gt")
    r = error_rates(base, perm)
    assert r.p_m == 0 and r.p_f == 0
    with pytest.raises(LabelingError, match="no rows of source"):
        LabelGrid.from_table(t, "gt")


def test_public_api_complete() -> None:
    import importlib
    import pkgutil

    import psg_data.labeling as pkg

    assert sorted(pkg.__all__) == sorted(set(pkg.__all__))
    for name in pkg.__all__:
        assert hasattr(pkg, name)
    for mod in pkgutil.iter_modules(pkg.__path__):
        m = importlib.import_module(f"psg_data.labeling.{mod.name}")
        for name in getattr(m, "__all__", []):
            if name in ("GENERAL_IOU_GRID", "pixel_rays", "project_points", "VISIBILITY_KINDS"):
                continue  # module-level details
            assert name in pkg.__all__, f"{mod.name}.{name} not re-exported"
