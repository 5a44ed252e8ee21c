"""Model discrepancy: what the simulation gets wrong on a ride log, its cause, the extended model, the gain.

The contract is ``shared/spec/diagnose.md``; the causes and their physics are
``shared/spec/effects.md``. Python API::

    from assist.diagnose import diagnose
    report = diagnose("ride.csv")
    report.to_json()                # diagnose.md's JSON
    report.effects                  # the verdict, e.g. gymnasium.make("PTWRoll-v0", effects=report.effects)
    report.extended_model()         # the reported model's compiled plant (closure forces included)
    report.plot("report.png")
    score_model("other_ride.csv", report)   # the fitted model, frozen, on another log of the vehicle

Command line: ``ptw-assist diagnose LOG.csv --json REPORT.json --plot REPORT.png``
(:mod:`assist.cli.diagnose`). How the replay stays honest on an open-loop
unstable vehicle: :mod:`assist.diagnose.replay`; how causes are fitted,
ranked and judged: :mod:`assist.diagnose.hypotheses`,
:mod:`assist.diagnose.selection`.
"""

from .data import DiagnoseInputError
from .diagnosis import TransferScore, diagnose, score_model
from .report import DiagnosisReport

__all__ = ["diagnose", "score_model", "TransferScore", "DiagnosisReport", "DiagnoseInputError"]
