"""``ptw-assist risk LOG.csv [--plot OUT.png] [--json FILE]``: the risk warning offline on a ride log (cli.md).

Registered into the one command line of :mod:`ptw_env.cli` (``build_parser``
imports this module). The log goes through :func:`assist.risk.offline.assess_log`
(the friction filter, then the risk monitor); with a ``kappa`` column the
road ahead is previewed from it, otherwise only the curve being ridden is
known. ``--json`` holds ``{"mu_hat_final", "warnings": [{"t", "level",
"reason", "until"}], ...}``. A simulated log with truth columns also gets
the true friction and the true saturation instants (``|F_ss| >= 0.95 Fmax``)
in the summary and the figure; the assessment itself never reads them. Before the
warning runs, readings at a sensor's limit are set aside
(:func:`ptw_env.logs.without_clipped`) and the sensor offsets and drifts the data
determine are removed where the model with them explains the log
(:func:`assist.estimation.identification.correct_offsets`, ``--offsets``), each said in
a note: a yaw-gyro offset would otherwise read as a road bank.
"""

from __future__ import annotations

import argparse

from ptw_env.cli import CLIError, road_bank_or_auto, check_outputs, NOISE_PCT, command, number, vehicle_for_log, add_vehicle_option, emit

from assist.cli.offsets import OFFSETS_HELP, filter_sensors, noise_pct_given, offset_error_note, offset_notes, offsets_option

#: ``--offsets`` default of risk: the offset channels the friction filter does not carry
#: (:data:`assist.estimation.identification.OFFSET_CHANNELS` without
#: :data:`assist.estimation.friction_imm.CARRIED_OFFSETS`; written out so that building the parser stays light,
#: tested equal).
RISK_OFFSETS = ("delta", "roll_rate")


@command(
    "risk",
    "risk warning offline on a ride log: friction estimate, utilisation, safe lean and curve speed, warnings",
    "ptw-assist simulate --scenario urban --noise 5 --effect tire_saturation:mu_peak=0.9 --log ride.csv && "
    "ptw-assist risk ride.csv --plot risk.png --json risk.json",
)
def _build(p: argparse.ArgumentParser):
    p.add_argument("log", metavar="LOG.csv", help="ride log (logs.md); an extra 'kappa' column [1/m] is the map ahead")
    add_vehicle_option(p, from_log=True)
    p.add_argument("--noise", type=NOISE_PCT, default=None, metavar="PCT",
                   help="sensor noise in percent of range the observer is designed for "
                        "(default: the sidecar's noise_pct, else 5)")
    p.add_argument("--no-map", action="store_true", help="ignore a kappa column (no preview of the road ahead)")
    p.add_argument("--confirm-sigmas", type=number(0, 10), default=None, metavar="K",
                   help="caution also when the grip is not confirmed at K sigma (0-10; default 0, the estimate alone: "
                        "on tires that lose their peak on a wet road the grip is not confirmed short of the limit)")
    p.add_argument("--road-bank", type=road_bank_or_auto, default="auto", metavar="RAD|auto",
                   help="bank (cross-fall) of the road: 'auto' (default) estimates it on line (a state of the "
                        "friction filter); a number in rad fixes it (e.g. from 'ptw-assist diagnose'; 0: level)")
    p.add_argument("--offsets", type=offsets_option, default=RISK_OFFSETS, metavar="CHANNELS",
                   help=OFFSETS_HELP + f" (for risk the default is {','.join(RISK_OFFSETS)}: the friction filter "
                                       "carries the yaw-gyro offset as a state and reads a lateral accelerometer offset "
                                       "as the road bank, while this level-road pre-filter reads a bank as offsets "
                                       "and, with those two channels, can take it off)")
    p.add_argument("--plot", default=None, metavar="OUT.png", help="timeline figure")
    p.add_argument("--json", default=None, metavar="FILE")
    p.add_argument("--overwrite", action="store_true", help="replace existing output files")

    def run(a: argparse.Namespace) -> int:
        import math

        import numpy as np

        from ptw_env.logs import read_log, usable_part

        from assist.risk.evaluation import truth_from_log
        from assist.risk.monitor import RiskConfig, RiskMonitor
        from assist.risk.offline import DEFAULT_NOISE_PCT, assess_log, plot_risk
        from assist.risk.pipeline import RiskPipeline, default_estimator

        check_outputs(a, "plot", "json")
        log, trimmed = usable_part(read_log(a.log))  # clipped readings, standstills, torque dropouts: said
        vehicle = vehicle_for_log(a, log)  # --vehicle, else the sidecar's, else the reference scooter
        dt = float(log.dt)
        given = noise_pct_given(a.noise, log.meta)  # None: not stated
        pct = DEFAULT_NOISE_PCT if given is None else given
        cfg = None if a.confirm_sigmas is None else RiskConfig(confirm_sigmas=a.confirm_sigmas)  # None: the tire's
        try:
            est = default_estimator(pct, dt, vehicle, np.asarray(log.columns["vx"], dtype=float))
        except ValueError as exc:
            raise CLIError(f"{a.log}: the risk estimator cannot be built for this log ({exc})") from None
        if a.offsets:  # sensor offsets and drifts as nuisance parameters, as estimate does (issue 19)
            from assist.estimation.identification import correct_offsets

            known = 0.0 if a.road_bank == "auto" else float(a.road_bank)  # a known bank in the filter's plant
            fixed, offsets, nis, error = correct_offsets(log, a.offsets, sensors=filter_sensors(given, vehicle),
                                                         model=est.model, road_bank=known)
            if error is not None:
                trimmed = trimmed + [offset_error_note(error, before="the warning")]
            else:
                log = fixed
                trimmed = trimmed + offset_notes(offsets, nis, "adaptive", before="the warning")
        pipe = RiskPipeline(est, RiskMonitor(cfg, vehicle=vehicle), road_bank=a.road_bank)
        if pipe.bank_estimate is not None:
            pipe.bank_estimate.record = True  # the estimates, for the report
        res = assess_log(log, pipe, use_kappa=not a.no_map)
        banks = None if pipe.bank_estimate is None else pipe.bank_estimate.summary()
        js = res.to_json()
        js["log"] = str(a.log)
        js["vehicle"] = vehicle.identity()
        js["observer_speed_range"] = [est.model.vmin, est.model.vmax]
        js["noise_pct_assumed"] = pct
        js["road_bank_rad"] = a.road_bank
        if a.offsets and error is None:
            js["sensor_offsets"] = offsets
            js["offset_filter_nis"] = nis
        if banks:
            js["road_bank_estimate_rad"] = banks
        elif a.road_bank == "auto" and getattr(est, "estimates_bank", False):  # the friction filter's own states
            js["road_bank_estimate_rad"] = {"final": est.road_bank}
        if hasattr(est, "yaw_rate_offset"):
            js["yaw_rate_offset_estimate_rad_s"] = est.yaw_rate_offset
        last = res.assessments[-1]
        truth = truth_from_log(log, vehicle)
        print(f"{a.log}: {len(log)} samples, {log.duration_s:.1f} s; vehicle {vehicle.name}; road ahead: "
              f"{res.path_source}")
        if trimmed:
            js["notes"] = trimmed
            for n in trimmed:
                print(f"note: {n}")
        if "yaw_rate_offset_estimate_rad_s" in js:
            print(f"{'road bank and ' if 'road_bank_estimate_rad' in js and not banks else ''}yaw-gyro offset "
                  f"estimated by the friction filter: "
                  f"{f'{est.road_bank:.4f} rad, ' if 'road_bank_estimate_rad' in js and not banks else ''}"
                  f"{est.yaw_rate_offset:+.4f} rad/s at the end")
        if banks:
            e = js["road_bank_estimate_rad"]
            print(f"road bank estimated on line: median {e['median']:.4f} rad (5-95 %: {e['p5']:.4f} to "
                  f"{e['p95']:.4f}), final {e['final']:.4f}")
        print(f"friction at the end: mu_hat = {last.mu_hat:.2f} +- {last.mu_std:.2f} ({last.friction_status}); "
              f"max safe lean {math.degrees(last.max_safe_lean):.0f} deg; "
              f"time in caution {js['time_in_level_s']['caution']:.1f} s, danger {js['time_in_level_s']['danger']:.1f} s")
        if truth is not None:
            mu_t, util, events = truth
            js["truth"] = {"mu_final": float(mu_t[-1]), "max_utilisation": [float(u) for u in util.max(axis=0)],
                           "saturation_t": [float(x) for x in events]}
            print(f"truth (simulator): friction at the end {mu_t[-1]:.2f}; peak |F_ss|/Fmax front "
                  f"{util[:, 0].max():.2f}, rear {util[:, 1].max():.2f}; saturation at "
                  f"{', '.join(f'{x:.2f}' for x in events) + ' s' if len(events) else 'no instant'}")
        w = js["warnings"]
        print(f"{len(w)} warning(s): {js['counts']['caution']} caution, {js['counts']['danger']} danger")
        for e in w[:10]:
            print(f"  t = {e['t']:7.2f} - {e['until']:7.2f} s  {e['reason']}")
        if len(w) > 10:
            print(f"  ... {len(w) - 10} more in --json")
        emit(a, js, {"plot": lambda f: plot_risk(
            res, f, mu_true=None if truth is None else truth[0],
            true_utilisation=None if truth is None else truth[1],
            saturation_t=None if truth is None else truth[2], title=f"risk warning: {a.log}")})
        return 0

    return run
