"""Ride a scenario with the scenario's rider and record a ride log (what ``ptw-assist simulate`` does).

The rider is :class:`ptw_env.rider.LQRRider`: a gain-scheduled LQR with
integral roll action on the *true* state (a human perceives his own motion),
designed on the nominal model, plus band-limited random torque that excites
the dynamics as a real rider's corrections do. The ride goes through
:class:`ptw_env.env.PTWRollEnv` step by step, so the log holds exactly what
the environment's sensors produce.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .env import PTWRollEnv
from .logs import RideLog, write_log
from .rider import LQRRider, bank_lean
from .sensors import CHANNELS, SensorConfig
from .vehicle import STATE_NAMES
from .vehicle_files import sidecar_vehicle


@dataclass
class RideResult:
    """A ridden scenario: the log, the truth, and a few figures of merit."""

    log: RideLog
    states: np.ndarray  #: true states, shape (K, 8), at the log's sample instants
    phi_ref: np.ndarray  #: reference roll [rad], shape (K,)
    fell: bool
    reason: str
    scenario: str

    @property
    def duration_s(self) -> float:
        return float(self.log.duration_s)

    @property
    def roll_rmse_deg(self) -> float:
        return float(np.degrees(np.sqrt(np.mean((self.states[:, 0] - self.phi_ref) ** 2))))

    def summary(self) -> dict[str, Any]:
        return {
            "scenario": self.scenario,
            "duration_s": round(self.duration_s, 4),
            "fell": self.fell,
            "end_reason": self.reason,
            "samples": len(self.log.t),
            "roll_rmse_deg": round(self.roll_rmse_deg, 4),
            "roll_max_deg": round(float(np.degrees(np.abs(self.states[:, 0]).max())), 3),
            "torque_rms_nm": round(float(np.sqrt(np.mean(self.log.columns["tau"] ** 2))), 4),
        }


#: Standard deviation of the rider's random torque [N m] on the reference scooter; another vehicle's
#: rider takes it times :attr:`ptw_env.vehicle.Vehicle.torque_ratio` (0.16 N m on the robot bicycle).
RIDER_NOISE_NM = 3.0

def ride_scenario(
    scenario: str = "double_lane_change",
    speed_kmh: float | None = None,
    effects=None,
    noise_pct: float | None = None,
    sensors: SensorConfig | None = None,
    seed: int = 0,
    rider_noise_nm: float | None = None,
    hold_line: bool = False,
    **env_kwargs: Any,
) -> RideResult:
    """Ride ``scenario`` with the LQR rider and return the ride log and the truth.

    Row ``k`` of the log holds ``t_k``, the torque ``tau_k`` and measured
    speed held over ``[t_k, t_k + dt)``, and the sensor channels sampled at
    ``t_k`` (logs.md); the true state ``x_k`` goes to extra columns ``x_phi``
    ... ``x_Fyr`` and the true speed to ``vx_true``, as in the reference logs;
    with ``friction=`` (a :class:`~ptw_env.friction.FrictionSchedule`, passed
    to the environment) the true road friction goes to ``mu_true``.

    ``hold_line``: on a banked road (effects.md ``road_bank``) the rider adds to the scenario's roll
    reference the lean at which the vehicle runs straight there (:func:`ptw_env.rider.bank_lean`,
    about the bank: upright in gravity), as a rider holding the road's line does; by default
    (False) the rider keeps the road-relative roll of the scenario and the vehicle turns slowly
    downhill on a banked straight (a yaw rate of -0.5 to -0.6 times the bank [rad/s] on the
    reference scooter's urban rides, measured through ``assist.risk.BankEstimate``).
    """
    env_kwargs.setdefault("step_speeds", "vehicle")  # the logs' step: sized for the vehicle's range (env docstring)
    env = PTWRollEnv(scenario=scenario, speed_kmh=speed_kmh, effects=effects, noise_pct=noise_pct,
                     sensors=sensors, **env_kwargs)
    prior = env.get_prior()
    if rider_noise_nm is None:  # 3 N m on the reference scooter, in proportion on another vehicle
        rider_noise_nm = RIDER_NOISE_NM * prior.vehicle.torque_ratio
    rider = LQRRider(vehicle=prior.vehicle, torque_noise_nm=rider_noise_nm, tau_max=env.tau_max, dt=env.dt)
    obs, info = env.reset(seed=seed)
    rider.reset(np.random.default_rng(np.random.SeedSequence([seed, 1])))
    rows_y, rows_x, taus, vxs, refs, ts, mus = [], [], [], [], [], [], []
    reason, fell = "scenario_end", False
    bank = float(env.effects.value("road_bank", "bank_rad")) if hold_line and env.effects.has("road_bank") else 0.0
    leans: dict[float, float] = {}
    while True:
        x = info["state"]
        lean = 0.0
        if bank:
            key = round(float(info["vx"]), 1)
            if key not in leans:
                leans[key] = bank_lean(prior.vehicle, bank, max(key, 0.1))
            lean = leans[key]
        tau = rider.torque(x, info["vx"], info["phi_ref"] + lean)
        rows_y.append(info["measurement"])
        rows_x.append(x)
        taus.append(tau)
        vxs.append(info["vx"])
        refs.append(info["phi_ref"])
        ts.append(info["t"])
        mus.append(info.get("friction", np.nan))
        action = np.array([tau / env.tau_max if env.normalize_action else tau], dtype=np.float32)
        obs, _, terminated, truncated, info = env.step(action)
        if terminated or truncated:
            reason = info.get("reason", "scenario_end")
            fell = reason == "fell"
            break
    Y = np.asarray(rows_y)
    X = np.asarray(rows_x)
    cols: dict[str, np.ndarray] = {"t": np.asarray(ts), "tau": np.asarray(taus)}
    for i, ch in enumerate(CHANNELS):
        cols[ch] = Y[:, i]
    cols["vx_true"] = np.asarray(vxs)
    for i, nm in enumerate(STATE_NAMES):
        cols[f"x_{nm}"] = X[:, i]
    if env.friction is not None:
        cols["mu_true"] = np.asarray(mus)
    meta = {
        **sidecar_vehicle(env.vehicle),
        "sample_rate_hz": round(1.0 / env.dt, 9),
        "generator": "ptw-assist simulate (ptw_env.ride.ride_scenario)",
        "scenario": env.scenario.name,
        "speed_kmh": speed_kmh,
        "duration_s": round(len(ts) * env.dt, 6),  # N dt, as the reference sidecars
        "seeds": {"env": seed},
        "truth": {"causes": env.effects.to_causes(),
                  **({} if env.friction is None else {"friction": env.friction.to_json()})},
        "noise_pct": noise_pct,
        "rider_noise_nm": rider_noise_nm,
        "fell": fell,
        "notes": "tau and vx held over each sample (zero-order hold); x_* columns are the true state at t; "
        "vx is the measured (GPS) speed, vx_true the true one.",
    }
    log = RideLog(t=cols["t"], columns=cols, meta=meta, path=None)
    env.close()
    return RideResult(log=log, states=X, phi_ref=np.asarray(refs), fell=fell, reason=reason, scenario=env.scenario.name)


def save_ride(result: RideResult, path: str | Path, overwrite: bool = False) -> Path:
    """Write the ride's log (and its JSON sidecar) to ``path``; refuses to overwrite unless asked."""
    path = Path(path)
    write_log(path, result.log, meta=result.log.meta, overwrite=overwrite)
    return path


def plot_ride(result: RideResult, path: str | Path | None = None):
    """Figure of a ride: roll vs reference, torque, speed, steering, and the path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    c = result.log.columns
    t = c["t"]
    fig, axs = plt.subplots(2, 2, figsize=(11, 6.5), constrained_layout=True)
    ax = axs[0, 0]
    ax.plot(t, np.degrees(result.phi_ref), "--", color="C0", label="reference roll")
    ax.plot(t, np.degrees(result.states[:, 0]), color="C3", label="true roll")
    if "roll" in c:
        ax.plot(t, np.degrees(c["roll"]), color="0.6", lw=0.6, label="roll sensor")
    ax.set(xlabel="t [s]", ylabel="roll [deg]", title=f"{result.scenario}: roll tracking")
    ax.legend(loc="best", fontsize=8)
    ax = axs[0, 1]
    ax.plot(t, c["tau"], color="C2")
    ax.set(xlabel="t [s]", ylabel="steering torque [N m]", title="rider torque")
    ax = axs[1, 0]
    ax.plot(t, c["vx"] * 3.6, color="0.5", lw=0.8, label="GPS speed")
    if "vx_true" in c:
        ax.plot(t, c["vx_true"] * 3.6, color="C0", label="true speed")
    ax2 = ax.twinx()
    ax2.plot(t, np.degrees(c["delta"]), color="C1", lw=0.8)
    ax2.set_ylabel("steer angle [deg]", color="C1")
    ax.set(xlabel="t [s]", ylabel="speed [km/h]", title="speed and steering")
    ax.legend(loc="best", fontsize=8)
    ax = axs[1, 1]
    vx = c.get("vx_true", c["vx"])
    psi = np.cumsum(np.r_[0.0, result.states[:-1, 3]]) * float(np.median(np.diff(t)))
    dtv = float(np.median(np.diff(t)))
    X = np.cumsum(vx * np.cos(psi) - result.states[:, 2] * np.sin(psi)) * dtv
    Y = np.cumsum(vx * np.sin(psi) + result.states[:, 2] * np.cos(psi)) * dtv
    ax.plot(X, Y, color="C3")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set(xlabel="X [m]", ylabel="Y [m]", title="path ridden (top view)")
    if path is not None:
        fig.savefig(path, dpi=110)
    return fig
