"""The step process's sampler, forward pass, schedules and the process oracle against independent
references: path enumeration with regimes and shifted days, closed forms, hand-evaluated cases
(written for the mutation groups ``synth_process`` and ``process_oracle``, docs/TESTING.md)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from psg_data.estimators import EdgeStream, get_estimator
from psg_data.synth._process import ForwardBelief, observation_likelihood, save_process
from tests.synth.test_process_exact import tiny_process


def _posterior(proc, obs, H, query, label, p=0.0):  # type: ignore[no-untyped-def]
    ent = proc.entities["obj"]
    b = ForwardBelief(proc, ent).start()
    for t, lab, y in sorted(o for o in obs if o[0] <= H):
        b.advance_to(int(proc.clock.step_of(np.array([t]))[0]))
        b.observe(observation_likelihood(ent, lab, y, p, p))
    b.advance_to(int(proc.clock.step_of(np.array([H]))[0]))
    return b.forecast(np.maximum(proc.clock.step_of(query), b.n))[:, ent.state_index(label)]


def test_the_oracle_reads_the_process_of_a_dataset_folder_or_file(tmp_path: Path) -> None:
    proc = tiny_process(12, K=2, S=3)
    (tmp_path / "generator").mkdir()
    save_process(proc, tmp_path / "generator" / "process.json")
    t = np.array([proc.clock.step_start_s(i) + 60.0 for i in range(4)])
    streams = [EdgeStream(("obj", "r0"), t, np.array([1, 0, 0, 1], np.int8))]
    q = t[-1] + np.array([0.0, 3600.0, 86400.0])
    want = _posterior(proc, [(float(a), "r0", int(b)) for a, b in zip(t, streams[0].y)], float(t[-1]), q, "r0",
                      p=0.1)
    for source in (str(tmp_path), str(tmp_path / "generator" / "process.json")):
        est = get_estimator("process_oracle", dataset=source, p_m=0.1, p_f=0.1).fit(streams)
        f = est.make_filter(("obj", "r0"))
        f.update_many(t, streams[0].y)
        np.testing.assert_allclose(f.predict(q), want, rtol=0, atol=1e-12)
