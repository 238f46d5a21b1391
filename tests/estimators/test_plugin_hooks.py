"""Plugin authors need no underscore member of the base classes: public hooks (check_fitted,
edge_of_state, last_t_s, base_state, restore_state), documented state keys (STATE_KEYS); and a
plugin's comparison rows include the paper's own method, Perpetua*.
"""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

from psg_data.errors import EstimatorError, NotFittedError
from psg_data.estimators import STATE_KEYS, EdgeStream, check_estimator
from psg_data.evaluation._hints import EstimatorSpec
from psg_data.evaluation._persistence_job import persistence_rows

PLUGIN = Path(__file__).resolve().parents[2] / "examples" / "plugin"
OVERRIDDEN = {"_update_many", "_predict", "_parameters"}  # what a subclass implements or declares


def _plugin():  # type: ignore[no-untyped-def]
    """The example plugin's module, loaded from its file (it is not an installed distribution here)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("example_plugin_under_test",
                                                  PLUGIN / "psg_example_plugin" / "__init__.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_example_plugin_uses_only_public_members() -> None:
    """Every ``_name`` it reads is its own or a hook it overrides (not _last_t, _check_state, _check_fitted)."""
    tree = ast.parse((PLUGIN / "psg_example_plugin" / "__init__.py").read_text())
    targets = [t for n in ast.walk(tree) if isinstance(n, ast.Assign) for t in n.targets]
    targets += [e for t in targets if isinstance(t, ast.Tuple) for e in t.elts]
    own = {t.attr for t in targets if isinstance(t, ast.Attribute)}
    used = {n.attr for n in ast.walk(tree) if isinstance(n, ast.Attribute) and n.attr.startswith("_")
            and not n.attr.startswith("__")}
    assert used - own - OVERRIDDEN == set()


def test_public_hooks_round_trip_a_filter_state() -> None:
    """get_state has the STATE_KEYS; filter_from_state with the public hooks restores the same predictions."""
    plugin = _plugin()
    est = plugin.DecayEstimator(half_life_h=2.0)
    with pytest.raises(NotFittedError):
        est.make_filter(("mug", "table"))
    t0 = 1_700_000_000.0
    est.fit([EdgeStream(("mug", "table"), t0 + 3600.0 * np.arange(6), np.array([1, 1, 0, 1, 0, 1]))])
    f = est.make_filter(("mug", "table"))
    f.update_many(t0 + 3600.0 * np.array([10.0, 11.0]), np.array([0, 1]))
    state = f.get_state()
    assert set(STATE_KEYS) <= set(state) and state["last_t_s"] == f.last_t_s == t0 + 11 * 3600.0
    g = est.filter_from_state(state)
    q = t0 + 3600.0 * np.array([11.0, 12.5, 20.0])
    np.testing.assert_array_equal(g.predict(q), f.predict(q))
    # independent: w = 0.5 ** (1.5 h / 2 h) after a present observation, base rate 4/6
    assert g.predict(q)[1] == pytest.approx(0.5 ** 0.75 + (1 - 0.5 ** 0.75) * 4 / 6)
    with pytest.raises(EstimatorError, match="not 'example_decay'"):
        est.edge_of_state({**state, "estimator": "fremen"})
    with pytest.raises(EstimatorError, match="last_t_s"):
        est.filter_from_state({**state, "last_t_s": "noon"})
    check_estimator(plugin.DecayEstimator())  # raises on a missing or wrong member


def test_a_plugins_comparison_rows_include_perpetua_star() -> None:
    """psg-eval -e PLUGIN scores Perpetua* (the paper's method) next to Perpetua and FreMEn."""
    rows, _ = persistence_rows([EstimatorSpec.of("example_decay")], {}, references=True)
    labels = [r.label for r in rows]
    assert labels[:4] == ["example_decay", "perpetua_star", "perpetua", "fremen"]
