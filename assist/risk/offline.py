"""The risk warning run offline on a ride log (what ``ptw-assist risk`` does), and its timeline figure.

:func:`assess_log` replays a ride log (logs.md) sample by sample through
:class:`~assist.risk.pipeline.RiskPipeline`, exactly as the online wrapper
would have seen it: the estimator gets ``[delta, yaw_rate, roll_rate,
delta_rate, ay]``, ``tau`` and the logged (GPS) speed; the ``roll`` column
and any truth columns (``x_*``, ``vx_true``, ``mu_true``) are never used.

The road ahead
--------------
* If the log has a ``kappa`` column (the planned route's curvature [1/m] at
  each sample, e.g. from the navigation system; logs.md allows extra
  columns), it is the map: ``kappa`` against the distance travelled by
  odometry ``s_hat = cumsum(vx dt)``, previewed over the monitor's horizon.
* Otherwise only the curvature being ridden, ``r_hat / vx`` (the estimated
  yaw rate), is known: no preview, so a too-fast curve is seen only once it
  is being ridden.

Warnings
--------
:meth:`RiskRun.warnings` lists the warning episodes: each time the level
rises to caution or danger, ``{"t", "level", "reason", "until"}`` (``until``:
when the level changed again, or the end of the log).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ptw_env.logs import input_series, sidecar_noise_pct
from ptw_env.vehicle import Vehicle
from ptw_env.vehicle_files import vehicle_of_log

from .monitor import LEVELS, PathAhead, RiskAssessment, RiskConfig, RiskMonitor
from .pipeline import OUTPUTS, MonitorInputs, RiskPipeline, default_estimator, output_matrix

#: Sensor noise [% of range] the estimator is designed for when neither the caller nor the sidecar gives one
#: (the papers' level).
DEFAULT_NOISE_PCT = 5.0


class RiskLogError(ValueError):
    """A ride log the risk warning cannot use (the message names the file and what is wrong)."""


@dataclass(frozen=True, eq=False)
class RiskRun:
    """Assessments of a whole log.

    Attributes
    ----------
    t : ndarray (K,)
        Time [s].
    assessments : list of RiskAssessment
        One per sample.
    path_source : str
        ``"kappa column"`` or ``"yaw rate (no preview)"``.
    inputs : list of MonitorInputs
        What the monitor was fed at each sample (estimator outputs, speed, path): :func:`replay`
        runs another monitor on them without running the estimator again.
    """

    t: np.ndarray
    assessments: list
    path_source: str
    inputs: list | None = None

    def series(self, name: str) -> np.ndarray:
        """One attribute of every assessment as an array (e.g. ``"mu_hat"``, ``"level_code"``)."""
        return np.array([getattr(a, name) for a in self.assessments], dtype=float)

    @property
    def level_code(self) -> np.ndarray:
        return self.series("level_code").astype(int)

    def warnings(self) -> list[dict[str, Any]]:
        """Warning episodes: ``[{"t", "level", "reason", "until"}]`` at each rise to caution or danger."""
        out: list[dict[str, Any]] = []
        lv = self.level_code
        t_end = float(self.t[-1]) if len(self.t) else 0.0
        prev = 0
        for k, a in enumerate(self.assessments):
            if lv[k] != prev:
                if out and out[-1]["until"] is None:
                    out[-1]["until"] = float(self.t[k])
                if lv[k] > 0:
                    out.append({"t": float(self.t[k]), "level": a.level, "reason": a.reason, "until": None})
                prev = lv[k]
        if out and out[-1]["until"] is None:
            out[-1]["until"] = t_end
        return out

    def to_json(self) -> dict[str, Any]:
        """``{"mu_hat_final", "warnings": [...]}`` (cli.md) and more."""
        last: RiskAssessment = self.assessments[-1]
        lv = self.level_code
        dt = float(np.median(np.diff(self.t))) if len(self.t) > 1 else 0.0
        w = self.warnings()
        return {
            "mu_hat_final": float(last.mu_hat),
            "mu_std_final": float(last.mu_std),
            "friction_status_final": last.friction_status,
            "warnings": w,
            "counts": {lev: sum(1 for e in w if e["level"] == lev) for lev in LEVELS[1:]},
            "time_in_level_s": {lev: round(float(np.sum(lv == i) * dt), 4) for i, lev in enumerate(LEVELS)},
            "max_risk_index": float(np.max(self.series("risk_index"))),
            "path_source": self.path_source,
            "duration_s": float(self.t[-1] - self.t[0]) if len(self.t) > 1 else 0.0,
        }


def assess_log(log, pipeline: RiskPipeline | None = None, noise_pct: float | None = None,
               use_kappa: bool = True, vehicle: Vehicle | None = None, tire: str = "peak") -> RiskRun:
    """Run the risk warning over a :class:`ptw_env.logs.RideLog` (module docstring).

    Parameters
    ----------
    log : RideLog
    pipeline : RiskPipeline, optional
        Default: :func:`~assist.risk.pipeline.default_estimator` for ``tire``, designed for ``noise_pct`` (else the sidecar's
        ``noise_pct``, else 5 %) at the log's sample period, and the default monitor.
    noise_pct : float, optional
    use_kappa : bool
        Use a ``kappa`` column as the map when present (default True).
    vehicle : Vehicle, optional
        The vehicle of the default pipeline (default: the sidecar's, :func:`ptw_env.vehicle_files.vehicle_of_log`,
        else the reference scooter).
    tire : {"peak", "stiffness"}
        The default pipeline's friction reading (:class:`RiskPipeline` ``tire``; default "peak").

    Examples
    --------
    >>> from ptw_env.ride import ride_scenario
    >>> ride = ride_scenario("double_lane_change", noise_pct=5.0, seed=0)
    >>> run = assess_log(ride.log)
    >>> js = run.to_json()
    >>> js["warnings"], js["path_source"]
    ([], 'yaw rate (no preview)')
    """
    c = log.columns
    missing = [n for n in (*OUTPUTS, "tau", "vx") if n not in c]
    if missing:
        raise RiskLogError(f"{getattr(log, 'path', None) or 'log'}: missing column(s) {missing}")
    t = np.asarray(log.t, dtype=float)
    if len(t) < 2:
        raise RiskLogError(f"{getattr(log, 'path', None) or 'log'}: too short ({len(t)} samples)")
    dt = float(np.median(np.diff(t)))
    if pipeline is None:
        pct = noise_pct if noise_pct is not None else sidecar_noise_pct(log.meta)
        pct = DEFAULT_NOISE_PCT if pct is None else pct
        v = vehicle if vehicle is not None else vehicle_of_log(log.meta or {}, getattr(log, "path", None))
        pipeline = RiskPipeline(default_estimator(pct, dt, v, np.asarray(c["vx"], dtype=float), tire=tire), vehicle=v,
                                tire=tire)
    pipeline.reset()
    Y = output_matrix(c)
    vx = np.asarray(c["vx"], dtype=float)
    try:  # ptw_env.logs: the one check of the inputs and the one reconstruction of the held speed
        tau, vfill = input_series(t, c["tau"], vx, str(getattr(log, "path", None) or "log"))
    except ValueError as exc:
        raise RiskLogError(str(exc)) from None
    kmap = None
    if use_kappa and "kappa" in c:
        kap = np.asarray(c["kappa"], dtype=float)
        if not np.all(np.isfinite(kap)):
            raise RiskLogError(f"{getattr(log, 'path', None) or 'log'}: the kappa column has missing values")
        s_hat = np.concatenate(([0.0], np.cumsum(vfill[:-1] * np.diff(t))))
        kmap = (s_hat, kap)
    cfg = pipeline.monitor.config
    out: list[RiskAssessment] = []
    fed: list[MonitorInputs] = []
    for k in range(len(t)):
        path = None
        if kmap is not None:
            horizon = max(cfg.preview_min_m, vfill[k] * cfg.preview_s)
            path = PathAhead.from_map(kmap[0][k], kmap[0], kmap[1], horizon)
        out.append(pipeline.update(float(t[k]), Y[k], float(tau[k]), float(vx[k]), path=path,
                                   yaw_rate_path=kmap is None))
        fed.append(pipeline.last_inputs)
    return RiskRun(t=t, assessments=out, path_source="kappa column" if kmap is not None else "yaw rate (no preview)",
                   inputs=fed)


def replay(run: RiskRun, monitor: RiskMonitor) -> RiskRun:
    """The assessments another ``monitor`` (other thresholds, margins, friction options) gives on the
    same estimator outputs as ``run`` (``monitor`` is reset first)."""
    if not run.inputs:
        raise RiskLogError("this run has no recorded monitor inputs to replay")
    monitor.reset()
    return RiskRun(t=run.t, assessments=[monitor.update(*i) for i in run.inputs], path_source=run.path_source,
                   inputs=run.inputs)


def plot_risk(run: RiskRun, path: str | Path | None = None, mu_true: np.ndarray | None = None,
              true_utilisation: np.ndarray | None = None, saturation_t: np.ndarray | None = None,
              title: str = "risk warning", config: RiskConfig | None = None):
    """Timeline: friction (true vs estimated with its 2-sigma band, grey where not informed),
    utilisation (now per axle, ahead, and the true ``|F_ss|/Fmax`` if given) with the caution and
    danger thresholds of ``config`` (default :class:`RiskConfig`), warning level, and the true
    saturation instants (red lines) if given."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = run.t
    mu, sd = run.series("mu_hat"), run.series("mu_std")
    inf = run.series("friction_informed").astype(bool)
    fig, axs = plt.subplots(3, 1, figsize=(11, 8), sharex=True, constrained_layout=True)
    ax = axs[0]
    ax.fill_between(t, mu - 2 * sd, mu + 2 * sd, color="C0", alpha=0.2, lw=0, label="mu_hat +- 2 sigma")
    ax.plot(t, mu, color="C0", label="mu_hat")
    ax.plot(t, np.where(inf, np.nan, mu), color="0.55", lw=2.0, label="held (not read: the tires do not tell)")
    if mu_true is not None:
        ax.plot(t, mu_true, "k--", lw=1.2, label="true friction")
    ax.set(ylabel="friction [-]", title=title, ylim=(0, 1.4))
    ax.legend(loc="lower left", fontsize=8, ncol=2)
    ax = axs[1]
    ax.plot(t, run.series("utilisation_front"), color="C1", lw=0.9, label="front (estimated)")
    ax.plot(t, run.series("utilisation_rear"), color="C2", lw=0.9, label="rear (estimated)")
    ax.plot(t, run.series("utilisation_ahead"), color="C4", lw=0.9, label="path ahead")
    if true_utilisation is not None:
        tu = np.asarray(true_utilisation)
        ax.plot(t, tu.max(axis=1) if tu.ndim == 2 else tu, "k", lw=0.8, alpha=0.7, label="true |F_ss|/Fmax")
    cfg = config or RiskConfig()
    cfg_lines = ((cfg.caution_enter, "caution"), (cfg.danger_enter, "danger"))
    for y, lab in cfg_lines:
        ax.axhline(y, color="0.5", ls=":", lw=0.8)
        ax.text(t[0], y, f" {lab}", fontsize=7, va="bottom", color="0.4")
    ax.set(ylabel="utilisation [-]", ylim=(0, 1.6))
    ax.legend(loc="upper left", fontsize=8, ncol=4)
    ax = axs[2]
    lv = run.level_code
    colors = ("#3a3", "#e90", "#d22")
    for i, col in enumerate(colors):
        ax.fill_between(t, 0, 1, where=lv == i, step="post", color=col, alpha=0.8, lw=0, label=LEVELS[i])
    ax.set(ylabel="warning", yticks=[], xlabel="t [s]", ylim=(0, 1))
    ax.legend(loc="upper left", fontsize=8, ncol=3)
    if saturation_t is not None and np.size(saturation_t):
        for ts in np.atleast_1d(saturation_t):
            for a in axs:
                a.axvline(ts, color="r", lw=1.0, alpha=0.8)
        axs[2].text(float(np.atleast_1d(saturation_t)[0]), 0.5, " tire saturates", color="r", fontsize=8)
    if path is not None:
        fig.savefig(path, dpi=110)
        plt.close(fig)
    return fig


__all__ = ["RiskLogError", "RiskRun", "assess_log", "plot_risk", "replay"]
