"""Settings of a navigation run in one frozen record, and the protocol presets.

:class:`NavigationOptions` holds everything :func:`~psg_data.navigation.run_navigation` needs
besides the data and the methods; it is stored in ``summary.json`` / ``results.json`` so that a
run can be repeated. :meth:`NavigationOptions.preset` starts from a protocol:

``sim`` (default; the paper's simulation-style "Predictive Navigation" table)
    250 queries per seed, a random start cell per query, natural mix of static / dynamic / absent
    targets (unreachable ones reported apart), predictive setting, delta 0.2, two attempts,
    1 m success radius, the agent knows the door states at the query time.

``paper-real`` (the paper's real-world experiment, Table "Real-World Navigation")
    25 queries per seed: 10 static, 10 dynamic, 5 absent targets, all present ones reachable;
    one fixed start pose for every query (the recordings' first camera pose, snapped to the
    nearest start cell); adaptive setting; delta 0.2; two attempts; success when the object is
    visible within 1 m of the final position; doors as the method predicts them (each method's
    estimator trained on the door streams of the label source).

Query times (``windows``): ``auto`` (default) draws them inside the dataset's scoring windows (its
operating hours: the lab's 9:00-17:00; a converted dataset's scan hours), ``none`` anywhere after the
map, or local hours such as ``9-17``.

Door beliefs (``door_belief``), per method: ``truth`` (the true states at the query time),
``predicted`` (registry estimators: the same estimator fitted on the door streams, open iff
P(open) >= 0.5; ``last_seen_map``: the last door observation; ``oracle``: the truth),
``last_map`` (the true states at the last map update) or ``all_open``. A door believed open but
closed is discovered when the agent reaches it.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields, replace
from typing import Any

from psg_data.errors import EvaluationError
from psg_data.navigation._env import WEEK_S

__all__ = ["NavigationOptions", "PROTOCOLS", "DOOR_BELIEFS", "START_MODES"]

DOOR_BELIEFS = ("truth", "predicted", "last_map", "all_open")
START_MODES = ("random", "fixed")
_ABSENT_RULES = ("abort_is_success", "abort_is_success_spl_path", "exclude")


@dataclass(frozen=True)
class NavigationOptions:
    """All settings of a navigation run (module docstring for the protocols).

    Attributes:
        protocol: name of the preset the options came from (``sim``, ``paper-real``, or
            ``custom``), stored with the results.
        labels: label source of the map, door and sighting observations (``gt``, ``privileged``,
            ``noisy:P[,P_F]``, ``detections:FILE``); scoring always uses the schedule.
        label_seed: seed of the ``noisy`` flips and of the sighting draws.
        seeds: one query set per seed; the tables report mean ± std across seeds.
        n_queries: queries per seed (the sum of ``quotas`` when they are given).
        quotas: ``((category, count), ...)``: sample exactly this many static / dynamic / absent
            queries per seed (rejection sampling), or None for the natural mix.
        start: ``random`` (a start cell per query) or ``fixed`` (the environment's start pose).
        reachable_only: redraw queries whose present target cannot be reached under the true doors.
        setting: ``predictive`` or ``adaptive``.
        delta: belief threshold below which a receptacle is not considered (abort when none is left).
        max_attempts: receptacles the agent may walk to.
        detect_en_route: stop as soon as the target is seen on the way.
        door_belief: door states the agent plans with (module docstring).
        absent_in_overall, unreachable: scoring rules (:mod:`psg_data.navigation._runner`).
        horizon_s: latest query time after the last map update, seconds.
        reach_m: success radius, metres.
        resolution_m, robot_radius_m, grid_source: occupancy grid (``geometry`` or ``scans``).
        keep_trails: keep the walked paths in memory (plots).
        windows: ``auto``, ``none`` or local hours (``9-17``): where query times are drawn.
        delta_sweep: more deltas to run every method with (the sweep table and plot); the main
            table uses ``delta``.
    """

    protocol: str = "sim"
    labels: str = "gt"
    label_seed: int = 0
    seeds: tuple[int, ...] = (0,)
    n_queries: int = 250
    quotas: tuple[tuple[str, int], ...] | None = None
    start: str = "random"
    reachable_only: bool = False
    setting: str = "predictive"
    delta: float = 0.2
    max_attempts: int = 2
    detect_en_route: bool = True
    door_belief: str = "truth"
    absent_in_overall: str = "abort_is_success"
    unreachable: str = "exclude"
    horizon_s: float = WEEK_S
    reach_m: float = 1.0
    resolution_m: float = 0.05
    robot_radius_m: float = 0.25
    grid_source: str = "geometry"
    keep_trails: bool = True
    windows: str = "auto"
    delta_sweep: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        if self.start not in START_MODES:
            raise EvaluationError(f"start: expected one of {START_MODES}, got {self.start!r}")
        if self.door_belief not in DOOR_BELIEFS:
            raise EvaluationError(f"door_belief: expected one of {DOOR_BELIEFS}, got {self.door_belief!r}")
        if self.absent_in_overall not in _ABSENT_RULES:
            raise EvaluationError(f"absent_in_overall: expected one of {_ABSENT_RULES}, got {self.absent_in_overall!r}")
        from psg_data.evaluation._navigation_scores import UNREACHABLE_RULES

        if self.unreachable not in UNREACHABLE_RULES:
            raise EvaluationError(f"unreachable: expected one of {UNREACHABLE_RULES}, got {self.unreachable!r}")
        if not self.seeds:
            raise EvaluationError("navigation options: no seeds")
        if self.quotas is not None:
            bad = [c for c, _ in self.quotas if c not in ("static", "dynamic", "absent")]
            if bad or any(int(n) < 0 for _, n in self.quotas) or sum(int(n) for _, n in self.quotas) < 1:
                raise EvaluationError(f"quotas {self.quotas}: expected non-negative counts of static / dynamic / "
                                      "absent queries, at least one query")
            object.__setattr__(self, "n_queries", sum(int(n) for _, n in self.quotas))
        if self.n_queries < 1:
            raise EvaluationError(f"n_queries must be >= 1, got {self.n_queries}")
        object.__setattr__(self, "seeds", tuple(int(s) for s in self.seeds))
        sweep = tuple(float(d) for d in self.delta_sweep)
        if any(not 0.0 <= d <= 1.0 for d in (*sweep, float(self.delta))):
            raise EvaluationError(f"delta {self.delta} / delta_sweep {sweep}: expected beliefs in [0, 1]")
        object.__setattr__(self, "delta_sweep", tuple(d for d in dict.fromkeys(sweep) if d != float(self.delta)))

    @property
    def deltas(self) -> tuple[float, ...]:
        """``delta`` first, then the sweep's other values."""
        return (float(self.delta), *self.delta_sweep)

    @classmethod
    def preset(cls, protocol: str = "sim", **overrides: Any) -> NavigationOptions:
        """Options of a protocol (:data:`PROTOCOLS`) with some fields replaced.

        Raises:
            EvaluationError: unknown protocol or field.
        """
        if protocol not in PROTOCOLS:
            raise EvaluationError(f"protocol {protocol!r}: expected one of {sorted(PROTOCOLS)}")
        names = {f.name for f in fields(cls)}
        bad = sorted(set(overrides) - names)
        if bad:
            raise EvaluationError(f"navigation options: unknown settings {bad}")
        return replace(PROTOCOLS[protocol], **overrides)

    @property
    def query_tag(self) -> str:
        """Part of the stored query-set file name that identifies how the queries were drawn."""
        quota = "_" + "-".join(f"{c}{n}" for c, n in self.quotas) if self.quotas else ""
        tag = f"_n{self.n_queries}{quota}"
        tag += "_fixedstart" if self.start == "fixed" else ""
        tag += "_reachable" if self.reachable_only else ""
        tag += "" if self.windows == "auto" else ("_anytime" if self.windows == "none" else
                                                   "_w" + self.windows.replace(":", "").replace(",", "_"))
        return tag

    def to_dict(self) -> dict[str, Any]:
        """The options as a JSON-ready dictionary (stored with the results)."""
        d = asdict(self)
        d["seeds"] = list(self.seeds)
        d["quotas"] = dict(self.quotas) if self.quotas else None
        d["delta_sweep"] = list(self.delta_sweep)
        return d


PROTOCOLS: dict[str, NavigationOptions] = {
    "sim": NavigationOptions(protocol="sim"),
    "paper-real": NavigationOptions(protocol="paper-real", quotas=(("static", 10), ("dynamic", 10), ("absent", 5)),
                                    start="fixed", reachable_only=True, setting="adaptive", delta=0.2, max_attempts=2,
                                    reach_m=1.0, door_belief="predicted"),
}
"""The protocol presets (module docstring)."""
