"""Closed-loop roll-tracking evaluation through ``env.step``, the way a user runs a controller.

Controllers (``--controller`` of ``ptw-assist evaluate``):

* ``ts``: the Takagi-Sugeno observer-based controller (:mod:`assist.control.ts_controller`),
  from the noisy yaw rate, roll rate, steering angle and rate only;
* ``ts_state``: the same TS design's state feedback on the *true* state
  (observer bypassed, :class:`assist.control.ts_controller.TSStateFeedback`): the
  separation bound of the TS design, i.e. what the TS controller would do
  with a perfect observer;
* ``lqg``: gain-scheduled Kalman filter + LQR (:mod:`assist.control.lqg`), same measurements;
* ``lqr``: the full-state bound: gain-scheduled discrete LQR for roll tracking
  (:class:`assist.control.lqg.TrackingLQR`, Bryson weights on the issue's 1 deg target)
  with the TS controller's reference pre-filter and model-inverse feedforward,
  on the *true* state ``info["state"]`` and speed (same gains as the LQG).
  Not the simulated rider's gentler LQR (:mod:`ptw_env.rider`);
* ``rl``: a stable-baselines3 policy from the noisy observation only (:mod:`assist.rl`;
  the shipped ``assist/policies/ppo_roll.zip`` by default, another file with
  ``controller_options={"policy": PATH}``); needs the ``[rl]`` extra.

Every controller is designed on the environment's *prior* model
(``env.get_prior()``, its dynamic ``prior_effects`` included), never on the
true plant, and sees the observation vector of :class:`ptw_env.env.PTWRollEnv`.
The model-based controllers (ts, ts_state, lqg, lqr) accept the prior effects
the TS model expresses (:data:`assist.control.ts_model.TS_EXPRESSIBLE_EFFECTS`) and
raise :class:`EvaluationError` for the others (a constant term, tire
saturation, and the sensor effects their observers do not model) rather than
ignore them.

Metrics (per episode): roll-tracking RMSE and maximum absolute error [deg]
of the true roll against the reference, torque RMS and peak [N m], whether
the scooter fell, and for observer-based controllers the RMSE of each
estimated state (in its unit) over the episode.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable, Protocol

import gymnasium as gym
import numpy as np

from ptw_env.env import PTWRollEnv, obs_index
from ptw_env.vehicle import STATE_NAMES

CONTROLLERS = ("ts", "ts_state", "lqr", "lqg", "rl")


class EvaluationError(ValueError):
    """A bad evaluation request (unknown controller, bad design range)."""


class Controller(Protocol):
    name: str

    def reset(self) -> None: ...

    def act(self, obs: np.ndarray, info: dict[str, Any]) -> float: ...

    @property
    def x_hat(self) -> np.ndarray | None: ...


def _prior_model(env: PTWRollEnv, controller: str, observer: bool = True):
    """The prior plant a model-based controller is designed on, or :class:`EvaluationError` (module docstring)."""
    from assist.control.ts_model import UnsupportedEffectError, split_model

    prior = env.get_prior()
    try:
        split_model(prior)
    except UnsupportedEffectError as err:
        raise EvaluationError(f"controller {controller}: prior_effects: {err}") from None
    sensor = list(env.prior_effects.sensor.params)
    if observer and sensor:
        raise EvaluationError(f"controller {controller}: prior_effects {', '.join(sensor)} are sensor effects "
                              "its observer does not model; leave them out of the prior")
    return prior


_MEASURED_OBS = list(obs_index("yaw_rate", "roll_rate", "delta", "delta_rate"))
_VX_OBS, _REF_OBS = obs_index("vx", "phi_ref")


def _measurements(obs: np.ndarray) -> np.ndarray:
    """[yaw_rate, roll_rate, delta, delta_rate] from the observation (:data:`ptw_env.env.OBS_NAMES`)."""
    return np.asarray(obs, dtype=float)[_MEASURED_OBS]


class SensorAdapter:
    """A controller that sees the observation only: ``self.ctrl.update(y, vx, phi_ref)`` with the measured
    ``y = [yaw_rate, roll_rate, delta, delta_rate]``, the GPS speed and the reference; its ``x_hat`` is the
    controller's estimate. Subclasses set ``name`` and build ``self.ctrl``."""

    name = "sensors"
    ctrl: Any

    def reset(self) -> None:
        self.ctrl.reset()

    def act(self, obs: np.ndarray, info: dict[str, Any]) -> float:
        return self.ctrl.update(_measurements(obs), float(obs[_VX_OBS]), float(obs[_REF_OBS]))

    @property
    def x_hat(self) -> np.ndarray | None:
        return self.ctrl.x_hat


class TrueStateAdapter(SensorAdapter):
    """A bound, not a controller one can build: ``self.ctrl.update(x, vx, phi_ref)`` with the true state and
    speed (``info``); no estimate."""

    name = "true_state"

    def act(self, obs: np.ndarray, info: dict[str, Any]) -> float:
        return self.ctrl.update(info["state"], info["vx"], info["phi_ref"])

    @property
    def x_hat(self) -> None:
        return None


class TSAdapter(SensorAdapter):
    """The TS observer-based controller on the environment's observation."""

    name = "ts"

    def __init__(self, env: PTWRollEnv, vmin: float | None = None, vmax: float | None = None) -> None:
        from assist.control.ts_controller import TSObserverController
        from assist.control.ts_design import design

        self.design = design(_prior_model(env, self.name), vmin=vmin, vmax=vmax)
        self.ctrl = TSObserverController(self.design, tau_max=env.tau_max)  # fed the torque the plant gets


class LQGAdapter(SensorAdapter):
    """The LQG (Kalman filter + tracking LQR) on the environment's observation."""

    name = "lqg"

    def __init__(self, env: PTWRollEnv) -> None:
        from assist.control.lqg import LQGController

        self.ctrl = LQGController(_prior_model(env, self.name), env.sensor_config, env.dt, env.tau_max)


class FullStateLQR(TrueStateAdapter):
    """:class:`assist.control.lqg.TrackingLQR` on the true state (``info["state"]``) and true speed: the bound."""

    name = "lqr"

    def __init__(self, env: PTWRollEnv) -> None:
        from assist.control.lqg import TrackingLQR

        self.ctrl = TrackingLQR(_prior_model(env, self.name, observer=False), env.dt, env.tau_max)


class TSStateAdapter(TrueStateAdapter):
    """:class:`assist.control.ts_controller.TSStateFeedback` (TS gains, observer bypassed) on the true state and speed."""

    name = "ts_state"

    def __init__(self, env: PTWRollEnv, vmin: float | None = None, vmax: float | None = None) -> None:
        from assist.control.ts_controller import TSStateFeedback
        from assist.control.ts_design import design

        self.design = design(_prior_model(env, self.name, observer=False), vmin=vmin, vmax=vmax)
        self.ctrl = TSStateFeedback(self.design)


#: A controller torque beyond this [N m] (or not finite) ends the episode as diverged: no actuator of a
#: two-wheeler comes near it (the environment clips to its ``tau_max`` anyway), and float32 actions overflow at 3e38.
TORQUE_DIVERGED_NM = 1e9


def make_controller(name: str, env: PTWRollEnv, **options: Any) -> Controller:
    """Build controller ``name`` for ``env`` (designed on ``env.get_prior()``)."""
    if name == "ts":
        return TSAdapter(env, **options)
    if name == "lqg":
        return LQGAdapter(env, **options)
    if name == "lqr":
        return FullStateLQR(env, **options)
    if name == "ts_state":
        return TSStateAdapter(env, **options)
    if name == "rl":
        from .rl import RLAdapter  # noqa: F401  (optional: stable-baselines3)

        return RLAdapter(env, **options)
    raise EvaluationError(f"unknown controller {name!r}; known: {', '.join(CONTROLLERS)}")


@dataclass
class Episode:
    """One closed-loop episode with its traces (sampled every dt)."""

    controller: str
    scenario: str
    speed_kmh: float | None
    noise_pct: float | None
    seed: int
    t: np.ndarray
    phi_ref: np.ndarray
    x: np.ndarray  #: true states (K, 8)
    x_hat: np.ndarray | None  #: estimates (K, 8) or None
    tau: np.ndarray
    vx: np.ndarray
    fell: bool
    reason: str
    extra: dict[str, Any] = field(default_factory=dict)

    def metrics(self) -> dict[str, Any]:
        """The figures of ``ptw-assist evaluate --json`` (cli.md)."""
        err = self.x[:, 0] - self.phi_ref
        out: dict[str, Any] = {
            "controller": self.controller,
            "scenario": self.scenario,
            "speed_kmh": self.speed_kmh,
            "noise_pct": self.noise_pct,
            "seed": self.seed,
            "duration_s": float(self.t[-1]) if len(self.t) else 0.0,
            "roll_rmse_deg": float(np.degrees(np.sqrt(np.mean(err**2)))),
            "roll_max_deg": float(np.degrees(np.max(np.abs(err)))),
            "torque_rms_nm": float(np.sqrt(np.mean(self.tau**2))),
            "torque_max_nm": float(np.max(np.abs(self.tau))),
            "fell": bool(self.fell),
            "diverged": self.reason.startswith("diverged"),
            "end_reason": self.reason,
            "estimation_rmse": None,
        }
        if self.x_hat is not None:
            e = self.x_hat - self.x
            out["estimation_rmse"] = {n: float(np.sqrt(np.mean(e[:, i] ** 2))) for i, n in enumerate(STATE_NAMES)}
            out["estimation_max"] = {n: float(np.max(np.abs(e[:, i]))) for i, n in enumerate(STATE_NAMES)}
        return out


def run_episode(
    controller: str | Callable[[PTWRollEnv], Controller] = "ts",
    scenario: str = "double_lane_change",
    speed_kmh: float | None = None,
    noise_pct: float | None = 5.0,
    seed: int = 0,
    effects=None,
    controller_options: dict[str, Any] | None = None,
    **env_kwargs: Any,
) -> Episode:
    """Run one closed-loop episode through ``env.step`` and record everything.

    The controller acts on the observation returned by the previous
    ``reset``/``step`` (the sample at ``t_k``) and its torque is held over
    ``[t_k, t_{k+1})`` by the environment.
    """
    env = PTWRollEnv(scenario=scenario, speed_kmh=speed_kmh, noise_pct=noise_pct, effects=effects, **env_kwargs)
    ctrl = make_controller(controller, env, **(controller_options or {})) if isinstance(controller, str) \
        else controller(env)
    obs, info = env.reset(seed=seed)
    ctrl.reset()
    ts, refs, xs, xh, taus, vxs = [], [], [], [], [], []
    reason = "scenario_end"
    while True:
        tau = float(ctrl.act(obs, info))
        if not (math.isfinite(tau) and abs(tau) <= TORQUE_DIVERGED_NM):
            # the closed loop diverged: an outcome of the evaluation, not an error of the program
            reason = f"diverged: torque {tau:.3g} N m at t = {info['t']:.2f} s"
            break
        ts.append(info["t"])
        refs.append(info["phi_ref"])
        xs.append(info["state"])
        vxs.append(info["vx"])
        taus.append(tau)
        est = ctrl.x_hat
        if est is not None:
            xh.append(np.array(est, dtype=float))
        obs, _, term, trunc, info = env.step(np.array([tau], dtype=np.float32))
        if term or trunc:
            reason = info.get("reason", "scenario_end")
            break
    env.close()
    if not ts:
        raise EvaluationError(f"controller {ctrl.name}: {reason} (at the first sample: nothing to evaluate)")
    return Episode(
        controller=ctrl.name, scenario=env.scenario.name, speed_kmh=speed_kmh, noise_pct=noise_pct, seed=seed,
        t=np.array(ts), phi_ref=np.array(refs), x=np.array(xs), x_hat=np.array(xh) if xh else None,
        tau=np.array(taus), vx=np.array(vxs), fell=reason == "fell", reason=reason,
    )


def plot_episode(ep: Episode, path=None, compare: list[Episode] | None = None):
    """Figure like the paper's: roll vs reference vs estimate, steering torque, states true vs estimated."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axs = plt.subplots(5, 2, figsize=(12, 13), constrained_layout=True)
    ax = axs[0, 0]
    ax.plot(ep.t, np.degrees(ep.phi_ref), "k--", lw=1, label="reference")
    ax.plot(ep.t, np.degrees(ep.x[:, 0]), color="C3", label=f"true roll ({ep.controller})")
    if ep.x_hat is not None:
        ax.plot(ep.t, np.degrees(ep.x_hat[:, 0]), color="C0", lw=0.9, label="estimated roll")
    colors = ("C4", "C1", "C2", "C5")
    for other, col in zip(compare or [], colors):
        ax.plot(other.t, np.degrees(other.x[:, 0]), lw=0.9, color=col, label=f"true roll ({other.controller})")
    ax.set(ylabel="roll [deg]", title=f"{ep.scenario}, noise {ep.noise_pct} %, seed {ep.seed}")
    ax.legend(fontsize=8)
    ax = axs[0, 1]
    ax.plot(ep.t, ep.tau, color="C3", lw=0.9, label=ep.controller)
    for other, col in zip(compare or [], colors):
        ax.plot(other.t, other.tau, lw=0.7, color=col, label=other.controller)
    ax.set(ylabel="steering torque [N m]", title="control input")
    ax.legend(fontsize=8)
    ax = axs[1, 0]
    ax.plot(ep.t, np.degrees(ep.x[:, 0] - ep.phi_ref), color="C3", lw=0.9, label=ep.controller)
    for other, col in zip(compare or [], colors):
        ax.plot(other.t, np.degrees(other.x[:, 0] - other.phi_ref), lw=0.7, color=col, label=other.controller)
    ax.set(ylabel="roll error phi - phi_ref [deg]", title="tracking error")
    ax.legend(fontsize=8)
    panels = [(1, "delta", "deg", 180 / np.pi), (2, "vy", "m/s", 1.0), (3, "r", "deg/s", 180 / np.pi),
              (4, "phi_dot", "deg/s", 180 / np.pi), (5, "delta_dot", "deg/s", 180 / np.pi), (6, "Fyf", "N", 1.0),
              (7, "Fyr", "N", 1.0)]
    for ax, (i, nm, unit, f) in zip(axs.ravel()[3:], panels):
        ax.plot(ep.t, f * ep.x[:, i], color="C3", label=f"true ({ep.controller})")
        if ep.x_hat is not None:
            ax.plot(ep.t, f * ep.x_hat[:, i], color="C0", lw=0.9, label="estimated")
        ax.set(ylabel=f"{nm} [{unit}]")
        ax.legend(fontsize=8)
    for ax in axs[-1]:
        ax.set_xlabel("t [s]")
    if path is not None:
        fig.savefig(path, dpi=110)
    return fig


#: Estimation columns of :func:`metrics_table`: state, unit shown, factor from the model.md unit.
EST_COLUMNS = (("phi", "deg", 180 / math.pi), ("delta", "deg", 180 / math.pi), ("vy", "m/s", 1.0),
               ("r", "deg/s", 180 / math.pi), ("phi_dot", "deg/s", 180 / math.pi),
               ("delta_dot", "deg/s", 180 / math.pi), ("Fyf", "N", 1.0), ("Fyr", "N", 1.0))


def metrics_table(rows: list[dict[str, Any]]) -> str:
    """A Markdown table of episode metrics (one row per episode or per aggregate), with the RMSE of every
    estimated state (``-`` for controllers without an estimate)."""
    est_head = " | ".join(f"{n} est {u}" for n, u, _ in EST_COLUMNS)
    head = ("| controller | scenario | speed km/h | noise % | seeds | roll RMSE deg | roll max deg | torque RMS N m "
            f"| torque peak N m | falls | {est_head} |")
    lines = [head, "|" + "---|" * (10 + len(EST_COLUMNS))]
    for r in rows:
        est = r.get("estimation_rmse") or {}
        cols = " | ".join(f"{f * est[n]:.3g}" if n in est else "-" for n, _, f in EST_COLUMNS)
        peak = r.get("torque_max_nm")
        lines.append(
            f"| {r['controller']} | {r['scenario']} | {r.get('speed_kmh') or '-'} | {r.get('noise_pct')} | "
            f"{r.get('seeds', 1)} | {r['roll_rmse_deg']:.3f} | {r['roll_max_deg']:.2f} | {r['torque_rms_nm']:.2f} | "
            f"{'-' if peak is None else f'{peak:.1f}'} | {r.get('falls', int(r['fell']))} | {cols} |"
        )
    return "\n".join(lines)


def aggregate(episodes: list[Episode]) -> dict[str, Any]:
    """Mean metrics over seeds of one configuration (max over seeds for the maxima; falls counted)."""
    ms = [e.metrics() for e in episodes]
    out = dict(ms[0])
    out["seeds"] = len(ms)
    out["roll_rmse_deg"] = float(np.mean([m["roll_rmse_deg"] for m in ms]))
    out["roll_max_deg"] = float(np.max([m["roll_max_deg"] for m in ms]))
    out["torque_rms_nm"] = float(np.mean([m["torque_rms_nm"] for m in ms]))
    out["torque_max_nm"] = float(np.max([m["torque_max_nm"] for m in ms]))
    out["falls"] = int(sum(m["fell"] for m in ms))
    out["fell"] = out["falls"] > 0
    if ms[0]["estimation_rmse"] is not None:
        out["estimation_rmse"] = {k: float(np.mean([m["estimation_rmse"][k] for m in ms])) for k in STATE_NAMES}
    return out


# ---------------------------------------------------------------------------
# sweeps: many episodes on the execution layer (issue 22)
# ---------------------------------------------------------------------------
#: Columns of a sweep's table (``ptw-assist evaluate --table``), one row per episode.
SWEEP_COLUMNS = ("controller", "scenario", "speed_kmh", "noise_pct", "seed", "effects", "roll_rmse_deg",
                 "roll_max_deg", "torque_rms_nm", "torque_max_nm", "fell", "diverged", "end_reason", "phi_est_rmse_deg")
#: Keys of a sweep file (JSON) and what each holds.
SWEEP_KEYS = {"controllers": "names of CONTROLLERS", "scenarios": "scenario names",
              "speeds_kmh": "cruise speeds [km/h] (null: the scenario's own)", "seeds": "seeds (integers >= 0)",
              "effects": "effect sets, each a list of CAUSE:PARAM=VALUE texts ([] : none)",
              "noise_pct": "sensor noise [% of range], one number"}


def sweep_points(controllers: list[str], scenarios: list[str], speeds_kmh: list[float | None], seeds: list[int],
                 effects: list[list[str]] | None = None, noise_pct: float | None = 5.0) -> list[dict[str, Any]]:
    """Every combination (controllers x scenarios x speeds x effect sets x seeds) as a point of a sweep."""
    effects = effects if effects else [[]]
    for name, vals in (("controllers", controllers), ("scenarios", scenarios), ("speeds", speeds_kmh),
                       ("seeds", seeds), ("effect sets", effects)):
        texts = [repr(v) for v in vals]
        twice = sorted({t for t in texts if texts.count(t) > 1})
        if twice:
            raise EvaluationError(f"{name}: {', '.join(twice)} given twice (each episode runs once)")
    bad = [c for c in controllers if c not in CONTROLLERS]
    if bad:
        raise EvaluationError(f"controllers: {bad} not in {CONTROLLERS}")
    return [{"controller": c, "scenario": sc, "speed_kmh": v, "noise_pct": noise_pct, "seed": int(sd),
             "effects": list(ef)}
            for c in controllers for sc in scenarios for v in speeds_kmh for ef in effects for sd in seeds]


def _not_a_number(text: str) -> float:
    """``json.load``'s hook for ``NaN``/``Infinity``, which strict JSON does not have."""
    raise ValueError(f"{text} is not a number (strict JSON)")


def load_sweep_file(path: str) -> dict[str, Any]:
    """A sweep file: a JSON object with the keys of :data:`SWEEP_KEYS` (any missing one takes the command
    line's value). Raises :class:`EvaluationError` naming the file and the key for a bad one."""
    import json

    try:
        with open(path, encoding="utf-8") as f:
            obj = json.load(f, parse_constant=_not_a_number)
    except (OSError, ValueError) as exc:
        raise EvaluationError(f"{path}: not a readable JSON sweep file ({exc})") from None
    if not isinstance(obj, dict):
        raise EvaluationError(f"{path}: a sweep file is a JSON object with keys {sorted(SWEEP_KEYS)}")
    unknown = sorted(set(obj) - set(SWEEP_KEYS))
    if unknown:
        raise EvaluationError(f"{path}: unknown key(s) {unknown}; known: {sorted(SWEEP_KEYS)}")
    for k, v in obj.items():
        ok = (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v >= 0) \
            if k == "noise_pct" else (isinstance(v, list) and len(v) > 0)
        if k == "seeds" and ok:
            ok = all(isinstance(x, int) and not isinstance(x, bool) and x >= 0 for x in v)
        if k == "speeds_kmh" and ok:
            ok = all(x is None or (isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)
                                   and x > 0) for x in v)
        if k == "effects" and ok:
            ok = all(isinstance(e, list) and all(isinstance(t, str) for t in e) for e in v)
        if k in ("controllers", "scenarios") and ok:
            ok = all(isinstance(x, str) for x in v)
        if not ok:
            raise EvaluationError(f"{path}: key {k!r}: expected {SWEEP_KEYS[k]}, got {v!r}")
    return obj


def sweep_job(point: dict[str, Any], vehicle=None) -> dict[str, Any]:
    """Job: one episode of a sweep point (:func:`run_episode`); its row of :data:`SWEEP_COLUMNS`
    (JSON-serialisable; the seed is the point's, so the row is the same whichever worker runs it)."""
    from ptw_env.effects import Effects

    kw = {} if vehicle is None else {"vehicle": vehicle}
    ep = run_episode(point["controller"], point["scenario"], speed_kmh=point["speed_kmh"],
                     noise_pct=point["noise_pct"], seed=point["seed"], effects=Effects.parse(point["effects"]), **kw)
    m = ep.metrics()
    est = m["estimation_rmse"]
    row = {k: m[k] for k in ("controller", "scenario", "speed_kmh", "noise_pct", "seed", "roll_rmse_deg",
                             "roll_max_deg", "torque_rms_nm", "torque_max_nm", "fell", "diverged", "end_reason")}
    row["effects"] = ";".join(point["effects"])
    row["phi_est_rmse_deg"] = None if est is None else float(np.degrees(est["phi"]))
    # an episode that diverged at its first step has no finite figure: null, and "diverged" says why
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in row.items()}


def run_sweep(points: list[dict[str, Any]], *, vehicle=None, workers: int = 1, scheduler: str | None = None,
              results: str | None = None, progress: bool = True) -> list[dict[str, Any]]:
    """Every point's episode on the execution layer (:func:`ptw_env.jobs.run_jobs`: serial, local processes or
    Dask; ``results``: the JSON-lines file a rerun resumes from); the rows in the order of ``points``."""
    from ptw_env.jobs import run_jobs

    jobs = [((p["controller"], p["scenario"], p["speed_kmh"], ";".join(p["effects"]), p["seed"]), (p, vehicle))
            for p in points]
    done = run_jobs(sweep_job, jobs, workers=workers, scheduler=scheduler, results=results, progress=progress,
                    desc="episodes")
    return list(done.values())


def sweep_table(rows: list[dict[str, Any]]) -> str:
    """A sweep's rows as CSV text (:data:`SWEEP_COLUMNS`)."""
    import csv
    import io

    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=SWEEP_COLUMNS, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: ("" if r[k] is None else r[k]) for k in SWEEP_COLUMNS})
    return buf.getvalue()


def sweep_summary(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per (controller, scenario, speed, effects): episodes, mean and max roll RMSE [deg], falls."""
    groups: dict[tuple, list[dict[str, Any]]] = {}
    for r in rows:
        groups.setdefault((r["controller"], r["scenario"], r["speed_kmh"], r["effects"]), []).append(r)
    out = []
    for (c, sc, v, ef), rs in groups.items():
        rm = [r["roll_rmse_deg"] for r in rs]
        out.append({"controller": c, "scenario": sc, "speed_kmh": v, "effects": ef, "episodes": len(rs),
                    "roll_rmse_deg_mean": float(np.mean(rm)), "roll_rmse_deg_max": float(np.max(rm)),
                    "falls": int(sum(r["fell"] for r in rs)), "diverged": int(sum(r["diverged"] for r in rs))})
    return out


def plot_sweep(rows: list[dict[str, Any]], path) -> None:
    """Roll-tracking RMSE per episode against the cruise speed, one panel per scenario, one colour per
    controller (the mean over seeds as a line); falls marked with a cross."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scen = sorted({r["scenario"] for r in rows})
    ctrls = sorted({r["controller"] for r in rows})
    fig, axs = plt.subplots(1, len(scen), figsize=(5.5 * len(scen), 4.2), constrained_layout=True, squeeze=False)
    for ax, sc in zip(axs[0], scen):
        for i, c in enumerate(ctrls):
            rs = [r for r in rows if r["scenario"] == sc and r["controller"] == c]
            xs = [r["speed_kmh"] if r["speed_kmh"] is not None else 0.0 for r in rs]
            ax.scatter(xs, [r["roll_rmse_deg"] for r in rs], s=12, color=f"C{i}", alpha=0.5,
                       marker="o", label=c)
            fx = [x for x, r in zip(xs, rs) if r["fell"]]
            if fx:
                ax.scatter(fx, [r["roll_rmse_deg"] for r in rs if r["fell"]], s=40, color=f"C{i}", marker="x")
            means = sorted({x: float(np.mean([r["roll_rmse_deg"] for x2, r in zip(xs, rs) if x2 == x]))
                            for x in set(xs)}.items())
            if means:
                ax.plot([m[0] for m in means], [m[1] for m in means], color=f"C{i}")
        ax.set(title=sc, xlabel="cruise speed [km/h] (0: the scenario's own)", ylabel="roll RMSE [deg]")
        ax.set_yscale("log")
        ax.legend(fontsize=8)
    fig.suptitle(f"sweep of {len(rows)} episodes (x: fell)")
    fig.savefig(path, dpi=110)
    plt.close(fig)


__all__ = ["CONTROLLERS", "Episode", "EvaluationError", "aggregate", "make_controller", "metrics_table",
           "plot_episode", "run_episode", "gym", "SWEEP_COLUMNS", "sweep_points", "load_sweep_file", "sweep_job",
           "run_sweep", "sweep_table", "sweep_summary", "plot_sweep"]
