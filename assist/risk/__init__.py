"""Risk warning from the estimated road friction (issue 5; the aim of Fouka, Nehaoua, Arioui).

* :mod:`assist.risk.friction_estimate`: ``mu_hat`` from an estimator's own friction reading (the friction filter
  of :mod:`assist.estimation.friction_imm`, the default) or from a tire-stiffness estimate, held between readings;
* :mod:`assist.risk.monitor`: :class:`RiskMonitor` (utilisation, safe lean, safe curve speed, levels);
* :mod:`assist.risk.pipeline`: sensors -> pluggable estimator (friction filter or stiffness estimator) -> monitor;
* :mod:`assist.risk.wrapper`: :class:`RiskWarningWrapper`, the assessment in a Gymnasium ``info``;
* :mod:`assist.risk.offline`: :func:`assess_log` on a ride log, the timeline figure;
* :mod:`assist.risk.evaluation`: the evaluation rides (dry, wet patch, curve too fast) and simulator truth.
"""

from .friction_estimate import FrictionConfig, FrictionEstimate, FrictionState, stiffness_to_friction
from .monitor import (LEVELS, PathAhead, RiskAssessment, RiskConfig, RiskInputError, RiskMonitor, safe_curve_speed,
                      safe_lean_angle)
from .offline import RiskLogError, RiskRun, assess_log, plot_risk
from .pipeline import RiskPipeline, StiffnessEstimator, default_estimator
from .wrapper import RiskWarningWrapper

__all__ = [
    "FrictionConfig",
    "FrictionEstimate",
    "FrictionState",
    "LEVELS",
    "PathAhead",
    "RiskAssessment",
    "RiskConfig",
    "RiskInputError",
    "RiskLogError",
    "RiskMonitor",
    "RiskPipeline",
    "RiskRun",
    "RiskWarningWrapper",
    "StiffnessEstimator",
    "assess_log",
    "default_estimator",
    "plot_risk",
    "safe_curve_speed",
    "safe_lean_angle",
    "stiffness_to_friction",
]
