"""``ptw-assist estimate``: states and tire stiffnesses from a ride log (cli.md).

Registered into the one command line of :mod:`ptw_env.cli` (the lead imports
this module in ``build_parser``). The methods are those of
:func:`assist.estimation.identification.estimate`: ``adaptive`` (the LPV adaptive
observer of Fouka et al.), ``direct`` (eq. 12), ``inversion`` (eq. 13) and
``ukf`` (the joint extended Kalman filter; ``ekf`` is accepted as an alias).
The figure of cli.md is the mean stiffness over the log's final third [N/rad].
"""

from __future__ import annotations

import argparse
import math
from typing import Any

import numpy as np

from ptw_env.cli import CLIError, road_bank, check_outputs, NOISE_PCT, command, number, vehicle_for_log, add_vehicle_option, emit

from assist.cli.offsets import OFFSETS_HELP, filter_sensors, noise_pct_given, offset_error_note, offset_notes, offsets_option

METHOD_CHOICES = ("adaptive", "direct", "inversion", "ukf", "ekf")


#: Why the default design is the default (printed and in the JSON as ``design_why``).
DEFAULT_DESIGN_WHY = (
    "Kalman vertex gains with one stiffness scale per axle (the default): the most accurate design with a "
    "certificate (stable for the linear LPV model over the speed range); on the disclosed logs within 1 % of "
    "every stiffness (nominal_urban, friction_urban; bank_lane_change with --road-bank), where the paper's "
    "Theorem-2 design (--gains theorem2 --parametrisation stiffness, certified for the nonlinear model within "
    "+-10 % stiffness) is off by up to 8 % on the nominal logs and 18 % on the bank lane change "
    "(docs/results/adaptive/disclosed_logs.md); one scale per axle is what friction and wear change, and four "
    "separate stiffnesses cannot be told within 5 % in 15 s of riding by any unbiased estimator (Cramer-Rao "
    "bound, README)")


#: A stiffness whose final-third mean is within this fraction of an edge of the adaptive observer's band
#: (the projection clips at the edge itself) is said to be held by the band.
BAND_EDGE = 0.01


def resolve_design(a: argparse.Namespace) -> str:
    """Fill ``a.gains`` and ``a.parametrisation`` left at their defaults; return why this design runs."""
    if a.law == "paper":
        a.gains = a.gains or "theorem2"
        a.parametrisation = a.parametrisation or "stiffness"
        return "the paper's adaptive law (eq. 18) with its Theorem-2 gains and four stiffnesses (--law paper)"
    if a.gains is None and a.parametrisation is None:
        a.gains, a.parametrisation = "kalman", "axle"
        return DEFAULT_DESIGN_WHY
    a.gains = a.gains or "kalman"
    a.parametrisation = a.parametrisation or "axle"
    return f"--gains {a.gains} --parametrisation {a.parametrisation} as asked"


@command(
    "estimate",
    "state and tire-stiffness estimation on a ride log (adaptive observer, direct, inversion or joint EKF)",
    "ptw-assist estimate ../shared/data/friction_urban.csv --method adaptive --plot est.png --json est.json",
)
def _build(p: argparse.ArgumentParser):
    p.add_argument("log", metavar="LOG.csv", help="ride log (logs.md); its roll column is never used")
    add_vehicle_option(p, from_log=True)
    p.add_argument("--method", choices=METHOD_CHOICES, default="adaptive",
                   help="adaptive (LPV adaptive observer, default), direct (eq. 12), inversion (eq. 13), "
                        "ukf (joint extended Kalman filter; ekf is an alias)")
    p.add_argument("--noise", type=NOISE_PCT, default=None, metavar="PCT",
                   help="sensor noise in percent of each channel's range that the filters assume "
                        "(default: the sidecar's noise_pct, else the reference logs' sensors)")
    p.add_argument("--law", choices=("sensitivity", "paper"), default="sensitivity",
                   help="adaptive law of the adaptive observer: sensitivity (default) or the paper's eq. (18)")
    p.add_argument("--gains", choices=("theorem2", "kalman"), default=None,
                   help="adaptive observer gains: kalman (vertex Kalman gains, the default: certified for the linear "
                        "LPV model, far more accurate stiffness) or theorem2 (the paper's LMI design, certified for "
                        "the nonlinear model within +-10 %% stiffness)")
    p.add_argument("--parametrisation", choices=("stiffness", "axle", "friction"), default=None,
                   help="what the adaptive observer adapts: one scale per axle (the default), the four stiffnesses "
                        "(the paper's), or one friction scale for all four")
    p.add_argument("--road-bank", type=road_bank, default=0.0, metavar="RAD",
                   help="adaptive: bank (cross-fall) of the road in rad, e.g. from 'ptw-assist diagnose' "
                        "(default 0: level); an unknown bank biases the stiffness estimate")
    p.add_argument("--tau-a", type=number(0, 1e6, unit="s", lo_open=True), default=None, metavar="S",
                   help="paper's law: adaptation time constant [s] (default 10)")
    p.add_argument("--offsets", type=offsets_option, default="all", metavar="CHANNELS",
                   help=OFFSETS_HELP + " (default all; for the other methods; ukf estimates them jointly)")
    p.add_argument("--plot", default=None, metavar="OUT.png")
    p.add_argument("--json", default=None, metavar="FILE")
    p.add_argument("--overwrite", action="store_true", help="replace existing output files")

    def run(a: argparse.Namespace) -> int:
        from ptw_env.logs import read_log, usable_part

        from assist.estimation.adaptive_design import AdaptiveDesignOptions, design_for_vehicle
        from assist.estimation.adaptive_observer import AdaptiveObserver
        from assist.estimation.figures import plot_estimate, truth_scales
        from assist.estimation.identification import estimate
        from assist.estimation.lpv_model import THETA_NAMES, LPVModelError

        check_outputs(a, "plot", "json")
        if a.tau_a is not None and not (math.isfinite(a.tau_a) and a.tau_a > 0):
            raise CLIError(f"--tau-a: expected a positive time in seconds, got {a.tau_a}")
        log, trimmed = usable_part(read_log(a.log))  # clipped readings, standstills, torque dropouts: said
        vehicle = vehicle_for_log(a, log)  # --vehicle, else the sidecar's, else the reference scooter
        why = resolve_design(a)
        dt = float(log.dt)
        pct = noise_pct_given(a.noise, log.meta)
        opts: dict[str, Any] = {"dt": round(dt, 9)}
        if pct is not None:
            opts["noise_pct"] = max(pct, 0.5)
        try:  # over the vehicle's design range, else over the log's speeds
            o = AdaptiveDesignOptions(**opts)
            design = design_for_vehicle(vehicle, o, a.gains, np.asarray(log.columns["vx"], dtype=float))
        except LPVModelError as exc:
            raise CLIError(f"{a.log}: no LPV observer model for the vehicle {vehicle.name!r} ({exc})") from None
        except ValueError as exc:
            raise CLIError(f"{a.log}: the adaptive observer cannot be designed for this log ({exc})") from None
        model = design.model
        if a.tau_a is not None and a.law != "paper":
            raise CLIError("--tau-a applies to --law paper only")
        if a.law == "paper" and (a.gains, a.parametrisation) != ("theorem2", "stiffness"):
            raise CLIError("--law paper adapts the four stiffnesses with Theorem-2 gains: "
                           "use --gains theorem2 --parametrisation stiffness")
        if a.road_bank and a.method != "adaptive":
            raise CLIError("--road-bank applies to --method adaptive only")
        obs = AdaptiveObserver(design, law=a.law, tau_a=10.0 if a.tau_a is None else a.tau_a,
                               parametrisation=a.parametrisation, road_bank=a.road_bank)
        sensors = filter_sensors(pct, vehicle)
        method = "ukf" if a.method == "ekf" else a.method
        try:
            res = estimate(log, method, sensors=sensors, observer=obs, model=model, offsets=a.offsets)
        except ValueError as exc:
            raise CLIError(f"{a.log}: {exc}") from None
        out = res.to_json()
        offsets = res.info.get("offsets")
        if offsets is not None:  # nuisance parameters: what the data say each sensor reads beside the model
            out["sensor_offsets"] = offsets
            out["offset_filter_nis"] = res.info["offset_filter_nis"]
            trimmed = trimmed + offset_notes(offsets, res.info["offset_filter_nis"], method)
        if "offsets_error" in res.info:
            trimmed = trimmed + [offset_error_note(res.info["offsets_error"])]
        out["log"] = str(a.log)
        out["vehicle"] = vehicle.identity()
        out["observer_speed_range"] = [model.vmin, model.vmax]
        if method == "adaptive":
            out.update(law=a.law, gains=a.gains, parametrisation=a.parametrisation, road_bank_rad=a.road_bank,
                       design_why=why)
        nominal = model.theta0
        scales = truth_scales(log.meta)
        truth = None
        mean = res.final_third_mean()
        if scales is not None:
            truth = nominal * np.array([scales[0], scales[0], scales[1], scales[1]])
            out["truth_stiffness"] = {n: float(v) for n, v in zip(THETA_NAMES, truth)}
            out["relative_error"] = {n: float(m / t - 1.0) for n, m, t in zip(THETA_NAMES, mean, truth)}
        print(f"{a.log}: {len(log)} samples, {log.duration_s:.1f} s; method {method}"
              f"{f' ({a.law} law, {a.gains} gains, {a.parametrisation})' if method == 'adaptive' else ''}; "
              f"stiffness = mean over the final third; vehicle {vehicle.name}, observer scheduled on "
              f"[{model.vmin:g}, {model.vmax:g}] m/s")
        if method == "adaptive":  # an estimate held by the projection's band says nothing about the tire
            lo, hi = obs.band
            near_lo, near_hi = lo * (1.0 + BAND_EDGE), hi * (1.0 - BAND_EDGE)
            edge = [f"{n} at {'the lower' if r <= near_lo else 'the upper'} edge of the adaptation band "
                    f"({r:.3f} of nominal; band {lo:g}-{hi:g})"
                    for n, r in zip(THETA_NAMES, mean / model.theta0) if r <= near_lo or r >= near_hi]
            if edge:
                trimmed = trimmed + ["; ".join(edge) + ": held by the band, not determined by the log (a model "
                                     "error the stiffness stands in for, a sensor offset or too little excitation; "
                                     "'ptw-assist diagnose' says which part of the model misses)"]
        if trimmed:
            out["notes"] = trimmed
            for n in trimmed:
                print(f"note: {n}")
        if method == "adaptive":
            print(f"design: {why}")
        print(f"{'parameter':<11} {'estimate':>10} {'C/C0':>7}" + (f" {'truth':>10} {'error':>8}" if truth is not None else ""))
        for j, n in enumerate(THETA_NAMES):
            line = f"{n:<11} {mean[j]:10.1f} {mean[j] / nominal[j]:7.3f}"
            if truth is not None:
                line += f" {truth[j]:10.1f} {100 * (mean[j] / truth[j] - 1):7.2f}%"
            print(line)
        emit(a, out, {"plot": lambda f: plot_estimate(res, log, f, nominal, truth, vehicle.mass)})
        return 0

    return run
