"""A digital twin from a ride log: the diagnosis turned into a ``randomize=`` description.

``ptw-assist twin LOG.csv --out twin.json`` diagnoses the log (:func:`assist.diagnose.diagnose`) and writes
what it measured, centred on the fitted values and as wide as their uncertainty, in the form the
environments read (:mod:`ptw_env.randomize`), so that a controller or a policy can be tested and trained
on "this rider's bike on this road"::

    from ptw_env.randomize import Randomization
    envs = gymnasium.make_vec("PTWRoll-v0", num_envs=1024, vectorization_mode="vector_entry_point",
                              **Randomization.env_kwargs("twin.json"))

The file (JSON)::

    {"log": ..., "vehicle": {name, model_sha256[, file, file_sha256]},     # the diagnosed vehicle
     "diagnosis": {"explained": ..., "extended": ..., "gain": ...},
     "randomize": {"CAUSE:PARAM": ["normal", value, spread * std], ...,    # table causes of the verdict
                   "force:EQUATION:FEATURE": ["normal", c, spread * std],  # closure terms (model extension)
                   "sensor_bias:CHANNEL": ["normal", c, spread * std]},    # sensor-offset closures
     "effects": [{"cause": ..., "params": {...}}],                          # fitted without an uncertainty
     "not_reproduced": ["..."],                                             # what the envs cannot carry
     "notes": ["..."],                                                      # e.g. the log was not explained
     "spread": 1.0}

Each fitted value is ``normal(value, spread * std)`` with ``std`` the fit's standard deviation
(:meth:`assist.diagnose.hypotheses.Fit.std`, from the weighted-residual Jacobian; closure terms:
diagnose.md's ``std``), clipped to effects.md's physical range. Values are the unrounded fit (the
report rounds). ``sensor_delay`` (not randomisable per episode) and table values without a finite
uncertainty go to ``effects`` (fixed), closure terms without one stay fixed numbers in ``randomize``
(with a note); sensor scale-factor closures, which the environments do not
model, to ``not_reproduced``. ``spread`` > 1 widens the distribution (the statistical ``std`` does not
contain model error, which a designer may want to cover).
"""

from __future__ import annotations

import math
from typing import Any

from ptw_env.dynamics import FORCE_ROWS
from ptw_env.randomize import Randomization

from .params import CAUSES, CLOSURE_INDEX, CLOSURES, param_set
from .report import DiagnosisReport


def twin(report: DiagnosisReport, spread: float = 1.0) -> dict[str, Any]:
    """The digital-twin description of a diagnosed log (module docstring); checked by
    :class:`ptw_env.randomize.Randomization`."""
    if not (isinstance(spread, (int, float)) and math.isfinite(spread) and spread > 0):
        raise ValueError(f"spread must be a finite number > 0, got {spread!r}")
    if report.verdict_z is None or report.model_z is None:
        raise ValueError("twin needs a report made by assist.diagnose.diagnose (its fitted parameter vectors)")
    ps = param_set(report.vehicle)
    randomize: dict[str, Any] = {}
    fixed: dict[str, dict[str, float]] = {}
    not_reproduced: list[str] = []
    notes: list[str] = []
    ext = report.extension
    table = [] if (ext is not None and ext.get("extends") == "nominal model") else [
        c["cause"] for c in report.causes if c["cause"] != "none"]
    for cause in table:
        stds = (report.causes_std or {}).get(cause, {})
        for i in CAUSES[cause]:
            spec = ps.params[i]
            value = float(spec.value(report.verdict_z[i]))
            sd = stds.get(spec.name)
            if not math.isfinite(value):
                continue  # e.g. mu_peak = inf: no saturation
            if cause == "sensor_delay" or sd is None or not math.isfinite(sd):
                fixed.setdefault(cause, {})[spec.name] = value
            else:
                randomize[f"{cause}:{spec.name}"] = ["normal", value, spread * sd]
    for term in (ext or {}).get("terms", []):
        closure = CLOSURES[term["name"]]
        c = float(report.model_z[CLOSURE_INDEX[term["name"]]])
        sd = term.get("std")
        if closure.equation in FORCE_ROWS:
            key = f"force:{closure.equation}:{closure.feature}"
        elif closure.feature == "offset":
            key = f"sensor_bias:{closure.equation.split(':', 1)[1]}"
        else:
            not_reproduced.append(f"{term['name']} ({term['term']}, {closure.equation}, coefficient {term['coefficient']}): "
                                  + ("the environments have no sensor scale factor" if closure.feature == "scale" else
                                     "the environments have no sensor drift (a drift belongs to one ride's log)"))
            continue
        if sd is None or not math.isfinite(sd):
            notes.append(f"{term['name']}: no finite uncertainty, kept fixed at {c:.6g}")
            randomize[key] = c
        else:
            randomize[key] = ["normal", c, spread * float(sd)]
    Randomization(randomize)  # the environments will read it: check it here
    if not report.explained and not report.extended:
        notes.append("the diagnosis did not explain the log to within the noise: the twin carries its closest "
                     "candidates, not a confirmed model")
    if not randomize and not fixed:
        notes.append("the nominal model explains the log: the twin is the vehicle as it is")
    return {
        "log": report.log,
        "vehicle": report.vehicle.identity(),
        "diagnosis": {"explained": bool(report.explained), "extended": bool(report.extended),
                      "gain": round(float(report.gain), 4),
                      "causes": report.causes, "extension": None if ext is None else ext.get("terms")},
        "randomize": randomize,
        "effects": [{"cause": c, "params": p} for c, p in fixed.items()],
        "not_reproduced": not_reproduced,
        "notes": notes,
        "spread": float(spread),
    }


__all__ = ["twin"]
