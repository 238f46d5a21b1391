"""Persistence estimators: the plugin interface, the registry and the built-ins.

Built-ins (``list_estimators()``): ``perpetua_star`` (FreMEn switching prior; ``prior=`` selects
"fremen", "profile", "oracle", "schedule" or "none"), ``perpetua_star_schedule``, ``perpetua_star_oracle``,
``perpetua_star_annealed`` (a variant whose prediction anneals to the prior, not the paper's),
``perpetua``, ``persistence_filter``, ``fremen``, ``last_seen``, ``always_present``, ``always_absent``,
``time_of_week_frequency``, ``training_mean``, ``time_of_day_histogram``. Plugins register in the
entry-point group ``psg_data.estimators``
and may declare their settings (``_parameters = {"alpha": Real(0, 1)}``, see :class:`Param`) so
that ``set_params`` and ``psg-eval -e NAME:alpha=...`` check them before any work.

Writing a plugin: subclass :class:`BaseEstimator` (settings, ``get_params`` / ``set_params`` /
``clone``; ``check_fitted()`` and ``edge_of_state(state)``) and :class:`BaseFilter` (time checks and
``last_t_s``; implement ``_update_many``, ``_predict`` and ``get_state``, which starts from
``base_state(name)``: the keys of :data:`STATE_KEYS`; ``restore_state(state)`` takes the time back);
``examples/plugin/`` in the repository is a complete installable package, and
:func:`check_estimator` names every member that is missing or wrong.

Example::

    from psg_data.estimators import get_estimator
    est = get_estimator("perpetua_star").fit(train_streams, val_streams=val_streams, timezone=tz)
    f = est.make_filter(("redmug", "kitchen_table"))
    f.update_many(t_s, y)
    p = f.predict(query_times_s)
"""

from psg_data.estimators._base import EdgeFilter, EdgeKey, EdgeStream, PersistenceEstimator
from psg_data.estimators._cadence import PAPER_SETTINGS, Cadence, training_cadence
from psg_data.estimators._check import check_estimator, conformance_streams
from psg_data.estimators._common import STATE_KEYS, BaseEstimator, BaseFilter
from psg_data.estimators._fremen import FremenComponents, FremenModel, LocalClock, fourier_sums
from psg_data.estimators._fremen_estimator import FremenEstimator
from psg_data.estimators._hmm import HmmFit, fit_error_hmm
from psg_data.estimators._interval_em import IntervalFit, fit_interval_mixture
from psg_data.estimators._mixture import MixtureFilter
from psg_data.estimators._multi import joint_log_belief, map_receptacle, receptacle_belief
from psg_data.estimators._params import Boolean, Integral, Options, Pair, Param, Real
from psg_data.estimators._perpetua import PerpetuaEstimator
from psg_data.estimators._perpetua_star import (
    PerpetuaStarAnnealedEstimator,
    PerpetuaStarEstimator,
    PerpetuaStarOracleEstimator,
    PerpetuaStarScheduleEstimator,
)
from psg_data.estimators._priors import (
    ConstantPrior,
    FremenPrior,
    OraclePrior,
    ProfilePrior,
    SchedulePrior,
    parse_llm_schedule,
    render_llm_prompt,
)
from psg_data.estimators._registry import (
    ENTRY_POINT_GROUP,
    get_estimator,
    get_factory,
    list_estimators,
    register_estimator,
)
from psg_data.estimators._segmentation import segment_reference
from psg_data.estimators._simple import (
    AlwaysAbsentEstimator,
    AlwaysPresentEstimator,
    LastSeenEstimator,
    PersistenceFilterEstimator,
    TimeOfWeekFrequencyEstimator,
)
from psg_data.estimators._state_baselines import TimeOfDayHistogramEstimator, TrainingMeanEstimator
from psg_data.estimators._survival import SURVIVAL_FAMILIES, SurvivalMixture
from psg_data.estimators._training import fit_lognormal_mixture, segment_stream

__all__ = [
    "EdgeKey",
    "EdgeStream",
    "EdgeFilter",
    "PersistenceEstimator",
    "BaseEstimator",
    "BaseFilter",
    "STATE_KEYS",
    "get_estimator",
    "get_factory",
    "Param",
    "Real",
    "Integral",
    "Options",
    "Boolean",
    "Pair",
    "list_estimators",
    "register_estimator",
    "ENTRY_POINT_GROUP",
    "check_estimator",
    "conformance_streams",
    "PerpetuaStarEstimator",
    "PerpetuaStarScheduleEstimator",
    "PerpetuaStarOracleEstimator",
    "PerpetuaStarAnnealedEstimator",
    "PerpetuaEstimator",
    "PersistenceFilterEstimator",
    "FremenEstimator",
    "LastSeenEstimator",
    "AlwaysPresentEstimator",
    "AlwaysAbsentEstimator",
    "TimeOfWeekFrequencyEstimator",
    "TrainingMeanEstimator",
    "TimeOfDayHistogramEstimator",
    "MixtureFilter",
    "SurvivalMixture",
    "SURVIVAL_FAMILIES",
    "FremenModel",
    "FremenComponents",
    "LocalClock",
    "fourier_sums",
    "ConstantPrior",
    "FremenPrior",
    "SchedulePrior",
    "OraclePrior",
    "ProfilePrior",
    "parse_llm_schedule",
    "render_llm_prompt",
    "receptacle_belief",
    "map_receptacle",
    "joint_log_belief",
    "fit_lognormal_mixture",
    "segment_stream",
    "segment_reference",
    "fit_interval_mixture",
    "IntervalFit",
    "fit_error_hmm",
    "HmmFit",
    "training_cadence",
    "Cadence",
    "PAPER_SETTINGS",
]
