"""Speed of the LPV adaptive observer: one update in microseconds vs one environment step; design time.

Usage::

    python scripts/bench_adaptive.py [--repeat 5] [--json OUT.json]

Prints (and optionally writes) the median over ``--repeat`` runs of:

* the LMI design (Lipschitz SDP + the two-stage Theorem-2 problem), seconds;
* one observer update through :meth:`AdaptiveObserver.update` (Python call included)
  for both adaptive laws, and per sample of :meth:`AdaptiveObserver.run` on a whole log;
* one step of the joint EKF (per sample of a whole log);
* one update of the friction filter of the risk warning (:class:`assist.estimation.friction_imm.FrictionIMM`,
  six models; Python call included);
* one :meth:`ptw_env.env.PTWRollEnv.step` (the plant the observer rides along with).

Timings depend on the machine; they are not asserted anywhere.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from assist.estimation.adaptive_design import design_adaptive_observer  # noqa: E402
from assist.estimation.adaptive_observer import AdaptiveObserver  # noqa: E402
from assist.estimation.friction_imm import FrictionIMM  # noqa: E402
from assist.estimation.identification import JointEKF  # noqa: E402
from ptw_env.env import PTWRollEnv  # noqa: E402
from ptw_env.ride import ride_scenario  # noqa: E402
from _outputs import add_overwrite, output_file  # noqa: E402  (scripts/_outputs.py)


def _median(f, repeat: int) -> float:
    out = []
    for _ in range(repeat):
        out.append(f())
    return float(np.median(out))


def _updates_us(est, Y, tau, vx, n: int = 2000) -> float:
    """Microseconds per ``est.update(y, tau, vx)`` (Python call included) over the first ``n`` samples, from a
    reset."""
    est.reset()
    t0 = time.perf_counter()
    for k in range(n):
        est.update(Y[k], tau[k], vx[k])
    return (time.perf_counter() - t0) / n * 1e6


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--json", default=None)
    add_overwrite(ap)
    a = ap.parse_args(argv)
    if a.repeat < 1:
        ap.error(f"--repeat must be >= 1, got {a.repeat}")
    output_file(ap, "--json", a.json, a.overwrite)
    res: dict[str, float] = {}

    def design_s() -> float:
        t0 = time.perf_counter()
        design_adaptive_observer()
        return time.perf_counter() - t0

    design_adaptive_observer()  # warm-up (imports, cvxpy canonicalisation caches)
    res["design_s"] = _median(design_s, a.repeat)
    design = design_adaptive_observer()

    r = ride_scenario("urban", noise_pct=5, seed=0)
    c = r.log.columns
    Y = np.column_stack([c[n] for n in ("delta", "yaw_rate", "roll_rate", "delta_rate", "ay")])
    K = len(Y)
    for law in ("sensitivity", "paper", "none"):
        obs = AdaptiveObserver(design, law=law)
        obs.run_log(r.log)  # compile

        def per_sample_run() -> float:
            t0 = time.perf_counter()
            obs.run_log(r.log)
            return (time.perf_counter() - t0) / K * 1e6

        res[f"observer_update_us[{law}]"] = _median(lambda: _updates_us(obs, Y, c["tau"], c["vx"]), a.repeat)
        res[f"observer_run_us_per_sample[{law}]"] = _median(per_sample_run, a.repeat)

    JointEKF().fit(r.log)

    def ekf_per_sample() -> float:
        t0 = time.perf_counter()
        JointEKF().fit(r.log)
        return (time.perf_counter() - t0) / K * 1e6

    res["joint_ekf_us_per_sample"] = _median(ekf_per_sample, a.repeat)

    imm = FrictionIMM()
    imm.update(Y[0], c["tau"][0], c["vx"][0])  # compile

    res["friction_filter_update_us"] = _median(lambda: _updates_us(imm, Y, c["tau"], c["vx"]), a.repeat)

    env = PTWRollEnv(scenario="urban", noise_pct=5)
    env.reset(seed=0)
    act = np.array([0.0], dtype=np.float32)

    def env_step() -> float:
        env.reset(seed=0)
        n = 2000
        t0 = time.perf_counter()
        for _ in range(n):
            env.step(act)
        return (time.perf_counter() - t0) / n * 1e6

    res["env_step_us"] = _median(env_step, a.repeat)
    res["observer_update_over_env_step[sensitivity]"] = res["observer_update_us[sensitivity]"] / res["env_step_us"]
    res["friction_filter_update_over_env_step"] = res["friction_filter_update_us"] / res["env_step_us"]
    for k, v in res.items():
        print(f"{k:45s} {v:10.2f}")
    if a.json:
        Path(a.json).write_text(json.dumps(res, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
