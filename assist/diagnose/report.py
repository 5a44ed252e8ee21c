"""The diagnosis report: the JSON of ``shared/spec/diagnose.md``, the extended model, the figure.

JSON structure (diagnose.md; keys beyond the contract are marked *extra*)::

    {
      "log": "LOG.csv",
      "nominal": {"rmse": {channel: ...},            # held-out RMS prediction error, physical units
                  "where": {...}},                   # extra: where the nominal residual lives
      "verdict": {"explained": bool,
                  "causes": [{"cause": ..., "params": {...}}],
                  "std": {cause: {param: ...}},      # extra: the fitted values' standard deviations
                  "gain": ...,                       # held-out, 0 = nominal, 1 = perfect
                  "rmse": {channel: ...},
                  "gain_channels": {channel: ...},   # extra: the gain per channel
                  "residual": {...}},                # only when explained is false
      "hypotheses": [{"causes": [...], "gain": ..., "score": ...,  # sorted by score, best first
                      "improvement": ..., "trimmed_improvement": ...,    # extra: the evidence
                      "support_margin": ..., "supported": bool}, ...],   # (assist.diagnose.selection)
      "noise": {channel: ...},                       # extra: the noise levels used
      "method": {...}                                # extra: windows, split, criteria
    }

Every number is rounded (4 significant digits for physical values, 4
decimals for gains and scores), and nothing depends on the clock or a random
generator, so the JSON is identical for the same log.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ptw_env.dynamics import Plant, add_generalised_forces, compile_plant
from ptw_env.effects import Effects
from ptw_env.vehicle import REFERENCE_SCOOTER, Vehicle

from . import selection
from .measurement import UNITS
from .params import CLOSURES


def sig(x: float, digits: int = 4) -> float:
    """``x`` rounded to ``digits`` significant digits (finite floats only)."""
    return float(f"{float(x):.{digits}g}")


def causes_text(causes: list[dict[str, Any]], sep: str = "; ") -> str:
    """The report's causes as text, ``cause(param=value, ...)`` joined by ``sep`` (``none`` as itself)."""
    return sep.join(c["cause"] + ("(" + ", ".join(f"{k}={v:g}" for k, v in c["params"].items()) + ")"
                                  if c["params"] else "") for c in causes)


def hypotheses_json(ranked, causes_of) -> list[dict[str, Any]]:
    """The report's ``hypotheses`` list: per ranked hypothesis (:func:`assist.diagnose.selection.order`), its
    causes (``causes_of(r)``, effects.md form), gain, score and the evidence (rounded to 4 decimals)."""
    return [
        {"causes": causes_of(r), "gain": round(r.gain, 4), "score": round(r.score, 4),
         "improvement": round(r.improvement, 4), "trimmed_improvement": round(r.trimmed, 4),
         "support_margin": round(r.margin, 4), "supported": bool(r.supported)}
        for r in ranked
    ]


def method_json(window_s: float, lead_s: float, n_fit: int, n_held_out: int, singles: int, pairs: int,
                pairs_rule: str, quantum: float | None, notes: list[str]) -> dict[str, Any]:
    """The report's ``method``: the replay, windows [s] and their split, the hypotheses tried, the encoder
    quantum [rad], and the acceptance criteria of :mod:`assist.diagnose.selection` in words."""
    return {
        "replay": "multi-step prediction over short windows, each from its least-squares initial state",
        "window_s": window_s,
        "lead_s": lead_s,
        "windows": {"fit": int(n_fit), "held_out": int(n_held_out)},
        "hypotheses": {"singles": int(singles), "pairs": int(pairs), "pairs_rule": pairs_rule},
        "encoder_quantum_rad": None if quantum is None else sig(quantum),
        "score": f"accepted (supported) hypotheses: held-out improvement in noise variances - "
                 f"{selection.PARAM_PENALTY} per parameter (> 0); none: 0; the others: their support margin "
                 f"(< 0, how far they fall short of acceptance); hypotheses are listed by this score",
        "support": f"held-out improvement >= {selection.MIN_IMPROVEMENT} noise variances per value, >= half "
                   f"that without the {selection.TRIM:.0%} most improved held-out windows (at least one), "
                   f"penalised improvement > 0, and for a pair the same over each of its single causes, paying "
                   f"{selection.PARAM_PENALTY} for each parameter it adds; "
                   f"support_margin is the smallest margin of these tests",
        "explained": f"held-out RMS residual <= {1 + selection.EXPLAINED_TOL:g} x noise in every channel",
        "notes": notes,
    }


@dataclass
class DiagnosisReport:
    """Result of :func:`assist.diagnose.diagnose` (see the module docstring for the JSON).

    Attributes
    ----------
    log : str
        The log's path (or ``"<memory>"``).
    explained : bool
        Whether the verdict explains the log to within the noise.
    causes : list of dict
        The verdict ``[{"cause": ..., "params": {...}}]`` (``none`` when the nominal model
        explains the log; the closest candidates when ``explained`` is false).
    gain : float
        Held-out fractional reduction of the RMS prediction error by the verdict.
    nominal_rmse, verdict_rmse : dict channel -> float
        Held-out RMS prediction error per channel [physical units] before and after.
    hypotheses : list of dict
        Every hypothesis tried, best first.
    seconds, sim_seconds : float
        Wall time of the diagnosis and the part spent in the batched simulator [s]
        (not in the JSON: it would not be deterministic).
    """

    log: str
    explained: bool
    causes: list[dict]
    gain: float
    gain_channels: dict[str, float]
    nominal_rmse: dict[str, float]
    verdict_rmse: dict[str, float]
    hypotheses: list[dict]
    nominal_where: dict
    residual: dict | None
    noise: dict[str, float]
    method: dict[str, Any]
    vehicle: Vehicle = REFERENCE_SCOOTER
    seconds: float = math.nan
    sim_seconds: float = math.nan
    sim_steps: int = 0
    plot_data: dict[str, Any] = field(default_factory=dict, repr=False)
    #: standard deviation of each fitted parameter of :attr:`causes`, ``{cause: {param: std}}`` (effects.md units,
    #: from the fit's weighted-residual Jacobian, :meth:`assist.diagnose.hypotheses.Fit.std`); None for ``none``
    causes_std: dict | None = None
    extension: dict | None = None  #: diagnose.md verdict.extension (closure terms and their gain), or None
    extended: bool = False  #: the extended model explains the log to within the noise
    #: ``{"between": [causes A, causes B], "separation_margin": m}`` when the held-out data do not
    #: separate the verdict A from a confusable cause B (:func:`assist.diagnose.selection.ambiguity`),
    #: each with its own fitted size; else None
    ambiguous: dict | None = None
    #: internal parameter vector (:mod:`assist.diagnose.params`) of the reported model: the extension's when there is one,
    #: else the verdict's; what :func:`assist.diagnose.score_model` replays on another log of the same vehicle
    model_z: np.ndarray | None = field(default=None, repr=False)
    #: internal parameter vector of the effects.md verdict alone (equal to :attr:`model_z` without an extension)
    verdict_z: np.ndarray | None = field(default=None, repr=False)

    # -- the extended model ----------------------------------------------------------
    @property
    def effects(self) -> Effects:
        """The verdict as :class:`ptw_env.effects.Effects`, e.g.
        ``gymnasium.make("PTWRoll-v0", effects=report.effects)`` (empty for ``none``)."""
        return Effects.from_causes(self.causes)

    def extended_model(self) -> Plant:
        """The reported model compiled (:func:`ptw_env.dynamics.compile_plant`), for simulation and observers:
        the nominal vehicle with the verdict's dynamic effects or, when the model was extended
        (:attr:`extension`), with the effects it extends and its closure terms that are forces or moments
        (:func:`ptw_env.dynamics.add_generalised_forces`: ``E x' = ... + c phi(x, vx) e_row``), at the sizes and
        coefficients the report states. Sensor effects and closure terms on a channel (offsets, scales) are not
        dynamics: they are in :attr:`effects` (``.sensor``) and :attr:`extension`."""
        if self.extension is None:
            return compile_plant(self.vehicle, self.effects.dynamic)
        base = self.extension.get("extends")
        plant = compile_plant(self.vehicle, Effects.from_causes(base if isinstance(base, list) else []).dynamic)
        forces = [(t["equation"], CLOSURES[t["name"]].feature, float(t["coefficient"]))
                  for t in self.extension["terms"] if not t["equation"].startswith("sensor:")]
        return add_generalised_forces(plant, forces) if forces else plant

    def model_label(self) -> str:
        """What the reported model is, in words: ``verdict (causes)``, or ``extended model (base + closure
        terms)`` when the model was extended."""
        if self.extension is None:
            return self._verdict_label()
        base = self.extension.get("extends")
        base_text = causes_text(base, ", ") if isinstance(base, list) and base else "nominal"
        return f"extended model ({base_text} + {', '.join(t['name'] for t in self.extension['terms'])})"

    def _verdict_label(self) -> str:
        return f"verdict ({causes_text(self.causes, ', ')})"

    # -- JSON ----------------------------------------------------------------------------
    def to_json(self) -> dict[str, Any]:
        """The report as diagnose.md's JSON structure (module docstring)."""
        verdict: dict[str, Any] = {
            "explained": bool(self.explained),
            "causes": self.causes,
            **({} if self.causes_std is None else {"std": self.causes_std}),
            "gain": round(float(self.gain), 4),
            "rmse": {c: sig(v) for c, v in self.verdict_rmse.items()},
            "gain_channels": {c: round(float(v), 4) for c, v in self.gain_channels.items()},
        }
        if not self.explained and self.residual is not None:
            verdict["residual"] = self.residual
        if self.extension is not None:
            verdict["extension"] = self.extension
        verdict["extended"] = bool(self.extended)
        if self.ambiguous is not None:
            verdict["ambiguous"] = self.ambiguous
        return {
            "log": self.log,
            "vehicle": self.vehicle.identity(),
            "nominal": {"rmse": {c: sig(v) for c, v in self.nominal_rmse.items()}, "where": self.nominal_where},
            "verdict": verdict,
            "hypotheses": self.hypotheses,
            "noise": {c: sig(v) for c, v in self.noise.items()},
            "method": self.method,
        }

    def summary(self) -> str:
        """A few human-readable lines."""
        names = causes_text(self.causes, ", ")
        lines = [
            f"verdict: {names}; {'explained' if self.explained else 'NOT explained'} to within the noise; "
            f"held-out gain {self.gain:.3f}",
            "held-out RMS prediction error, nominal -> verdict: "
            + ", ".join(f"{c} {self.nominal_rmse[c]:.3g} -> {self.verdict_rmse[c]:.3g} {UNITS[c]}"
                        for c in self.nominal_rmse),
            "nominal residual: " + self.nominal_where.get("summary", ""),
        ]
        if self.ambiguous is not None:
            a, b = (causes_text(c, ", ") for c in self.ambiguous["between"])
            lines.insert(1, f"ambiguous between {a} and {b}: the held-out data do not separate them "
                            f"(separation margin {self.ambiguous['separation_margin']:g} noise variances per value; "
                            "a ride that reaches the friction limit would)")
        if not self.explained and self.residual is not None:
            lines.append("unexplained residual: " + self.residual.get("summary", ""))
        if self.extension is not None:
            terms = "; ".join(f"{t['equation']}: {t['term']} with c = {t['coefficient']:g}"
                              + (f" +- {t['std']:g}" if t["std"] is not None else "") + f" {t['unit']}"
                              for t in self.extension["terms"])
            sensors = [t["name"] for t in self.extension["terms"] if t["equation"].startswith("sensor:")]
            lines.append(f"model extended beyond effects.md ({'explains' if self.extended else 'does not explain'} "
                         f"the log to within the noise; held-out gain {self.extension['gain']:.3f}): {terms}"
                         + (f"; {', '.join(sensors)}: the sensors' (a channel's offset, scale or drift), a data "
                            "problem, not the vehicle" if sensors else ""))
        top = [h for h in self.hypotheses[:4]]
        lines.append("best hypotheses: " + "; ".join(
            f"{'+'.join(c['cause'] for c in h['causes'])} gain {h['gain']:.3f} score {h['score']:.3g}" for h in top))
        lines += [f"note: {n}" for n in self.method.get("notes", [])]
        return "\n".join(lines)

    # -- figure --------------------------------------------------------------------------
    def plot(self, path: str | None = None):
        """Measured vs nominal vs reported model (the extension when there is one, else the verdict) on the two
        channels its replay improves most (held-out windows), and the RMS residual per channel of the two
        replays drawn, in units of the noise (the bars are the lines above, channel by channel)."""
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        d = self.plot_data
        chans = list(self.nominal_rmse)
        fig, axs = plt.subplots(3, 1, figsize=(11, 9), constrained_layout=True)
        label, gain = self.model_label(), self.gain if self.extension is None else float(self.extension["gain"])
        state = "explained" if self.explained else ("extended, explained" if self.extended else "NOT explained")
        noise = np.array([self.noise[c] for c in chans])
        if d:
            t, Y, Yn, Ye, sc = d["t"], d["Y"], d["Ynom"], d["Yext"], d["score"]
            before, after = (_rms(Y - Ym, sc) / noise for Ym in (Yn, Ye))
            order = sorted(range(len(chans)), key=lambda i: after[i] / max(before[i], 1e-300))[:2]
            for ax, i in zip(axs[:2], order):
                def line(a):
                    a = np.where(sc[..., i], a[..., i], np.nan)
                    return np.concatenate([np.r_[row, np.nan] for row in a])
                tt = np.concatenate([np.r_[row, np.nan] for row in t])
                ax.plot(tt, line(Y), color="0.55", lw=0.7, label="measured")
                ax.plot(tt, line(Yn), color="C3", lw=1.0, label="nominal model")
                ax.plot(tt, line(Ye), color="C0", lw=1.0, ls="--", label=label)
                ax.set(xlabel="t [s] (held-out windows)", ylabel=f"{chans[i]} [{UNITS[chans[i]]}]",
                       title=f"{chans[i]}: RMS residual {before[i]:.3g} -> {after[i]:.3g} noise levels")
                ax.legend(loc="best", fontsize=8)
        else:  # a report without its replays (e.g. read back from JSON): the report's own figures
            before = np.array([self.nominal_rmse[c] for c in chans]) / noise
            after = np.array([self.verdict_rmse[c] for c in chans]) / noise
            label, gain = self._verdict_label(), self.gain
            state = "explained" if self.explained else "NOT explained"
        ax = axs[2]
        x = np.arange(len(chans))
        ax.bar(x - 0.2, before, 0.4, color="C3", label="nominal model")
        ax.bar(x + 0.2, after, 0.4, color="C0", label=label)
        ax.axhline(1.0, color="k", lw=0.8, ls=":", label="noise level")
        ax.set_xticks(x, chans)
        ax.set_yscale("log")
        ax.set(ylabel="held-out RMS residual / noise",
               title=f"residual before/after; {state}; held-out gain {gain:.3f}")
        ax.legend(fontsize=8)
        if path is not None:
            fig.savefig(path, dpi=110)
            plt.close(fig)
        return fig


def _rms(e: np.ndarray, score: np.ndarray) -> np.ndarray:
    """RMS per channel of ``e`` (windows, samples, channels) over the scored samples."""
    return np.sqrt((np.where(score, e, 0.0) ** 2).sum(axis=(0, 1)) / np.maximum(score.sum(axis=(0, 1)), 1))


__all__ = ["DiagnosisReport", "causes_text", "hypotheses_json", "method_json", "sig"]
