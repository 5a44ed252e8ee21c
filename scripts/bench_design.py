"""Benchmark of the TS observer-based controller: LMI design time and per-sample cost.

Measures, in one run:

* the full design (balancing, build and solve of Theorems 1 and 2, numpy
  certificate, sampled-loop check) with Clarabel, repeated with the cache
  cleared;
* the same two theorem problems (same scaled data, same options: the
  problems the Clarabel design solved) with Clarabel and with SCS at its
  default tolerance, in the same run (:func:`assist.control.ts_design.compare_solver`):
  wall time, solver status, whether the returned point passes the numpy
  certificate, and the SCS / Clarabel time ratio;
* one :meth:`assist.control.ts_controller.TSObserverController.update` in
  microseconds, against one :meth:`ptw_env.integrate.Stepper.step` and one
  ``PTWRollEnv.step`` (when the environment is importable).

Not a test: it prints numbers (and writes them with ``--json``). SCS takes
minutes on this problem; ``--no-scs`` skips it.

Example::

    python scripts/bench_design.py --repeat 3 --json bench_design.json
"""

from __future__ import annotations

import argparse
import json
import statistics
import time

import numpy as np

from assist.control import ts_design
from assist.control.ts_controller import TSObserverController
from _outputs import add_overwrite, output_file  # noqa: E402  (scripts/_outputs.py)


def time_design(solver: str, repeat: int, vmin: float, vmax: float) -> dict:
    """Wall time of ``design`` with an empty cache, ``repeat`` times; the outcome of each."""
    times, outcome, parts = [], "certified", None
    for _ in range(repeat):
        ts_design.clear_cache()
        t0 = time.perf_counter()
        try:
            d = ts_design.design(vmin=vmin, vmax=vmax, solver=solver, cache=False)
            parts = d.summary()["timing"]
        except ts_design.DesignError as err:
            outcome = f"DesignError: {err}"
        times.append(time.perf_counter() - t0)
    return {"solver": solver, "wall_s": times, "median_s": statistics.median(times), "outcome": outcome,
            "parts": parts}


def per_call_us(fn, n: int, blocks: int = 5) -> float:
    """Median over ``blocks`` of the mean time of ``n`` calls [us]."""
    out = []
    for _ in range(blocks):
        t0 = time.perf_counter()
        for k in range(n):
            fn(k)
        out.append((time.perf_counter() - t0) / n * 1e6)
    return statistics.median(out)


def time_update(n: int) -> dict:
    from ptw_env.dynamics import compile_plant
    from ptw_env.integrate import Stepper

    d = ts_design.design()
    ctrl = TSObserverController(d)
    rng = np.random.default_rng(0)
    ys = rng.normal(0.0, 0.01, (n, 4))
    refs = 0.1 * np.sin(np.arange(n) * 0.01)
    ctrl.update(ys[0], 15.0, 0.0)  # compile
    res = {"update_us": per_call_us(lambda k: ctrl.update(ys[k], 15.0, refs[k]), n)}
    stepper = Stepper(compile_plant(), 0.01)
    x = np.zeros(8)
    stepper.step(x, 0.0, 15.0)
    res["stepper_step_us"] = per_call_us(lambda k: stepper.step(x, 0.0, 15.0), n)
    try:
        from ptw_env.env import PTWRollEnv
    except ImportError:
        return res
    env = PTWRollEnv(noise_pct=5.0)
    env.reset(seed=0)
    act = np.zeros(1, dtype=np.float32)
    m = min(n, env.max_steps - 10)

    def env_step(k: int) -> None:
        if env._k >= env.max_steps - 1:  # keep inside one episode
            env.reset(seed=0)
        env.step(act)

    res["env_step_us"] = per_call_us(env_step, m)
    return res


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=3, help="Clarabel designs to time (default 3)")
    ap.add_argument("--vmin", type=float, default=ts_design.DEFAULT_SPEED_RANGE[0], help="m/s")
    ap.add_argument("--vmax", type=float, default=ts_design.DEFAULT_SPEED_RANGE[1], help="m/s")
    ap.add_argument("--no-scs", action="store_true", help="skip SCS (it takes minutes)")
    ap.add_argument("--calls", type=int, default=20000, help="calls per timing block of update/step")
    ap.add_argument("--json", metavar="FILE", help="write the numbers to FILE")
    add_overwrite(ap)
    args = ap.parse_args(argv)
    output_file(ap, "--json", args.json, args.overwrite)

    out: dict = {"clarabel": time_design("CLARABEL", args.repeat, args.vmin, args.vmax)}
    c = out["clarabel"]
    print(f"design, Clarabel: median {c['median_s']:.2f} s over {args.repeat} ({c['outcome']}); target < 5 s")
    if c["parts"]:
        for th in ("observer", "controller"):
            p = c["parts"][th]
            print(f"  {th:10s}: balance {p['balance_s']:.2f} s, build {p['build_s']:.2f} s, "
                  f"solve {p['solve_s']:.2f} s ({p['status']})")
    if not args.no_scs:
        dz = ts_design.design(vmin=args.vmin, vmax=args.vmax)
        same = {name: ts_design.compare_solver(dz, name) for name in ("CLARABEL", "SCS")}
        out["same_problem"] = same
        print("the same two theorem problems (scaled data and options of the Clarabel design):")
        for name, r in same.items():
            for th in ("observer", "controller"):
                p = r[th]
                w = p["worst_lmi"]
                cert = "no point returned" if w is None else (
                    f"certificate {'passed' if p['certified'] else 'FAILED'}: worst LMI '{w['lmi']}' vertex "
                    f"{w['vertex']}, largest eigenvalue {w['max_eig']:+.2e} (required < {-dz.options.margin:.0e})")
                print(f"  {name:8s} {th:10s}: {p['wall_s']:7.2f} s, status {p['status']}; {cert}")
        ratio = same["SCS"]["wall_s"] / same["CLARABEL"]["wall_s"]
        out["scs_over_clarabel"] = ratio
        print(f"  SCS / Clarabel time on the same problems: {ratio:.0f}x "
              f"({same['SCS']['wall_s']:.1f} s vs {same['CLARABEL']['wall_s']:.2f} s); "
              f"SCS answer {'certified' if same['SCS']['certified'] else 'rejected by the certificate'}")
    u = time_update(args.calls)
    out["runtime"] = u
    print(f"one observer+controller update: {u['update_us']:.2f} us")
    print(f"one Stepper.step (plant only):  {u['stepper_step_us']:.2f} us")
    if "env_step_us" in u:
        print(f"one PTWRollEnv.step:            {u['env_step_us']:.2f} us")
        print(f"  update / env.step = {u['update_us'] / u['env_step_us']:.2f} (target < 1)")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=1)
    return out


if __name__ == "__main__":
    main()
