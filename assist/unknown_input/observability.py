"""Strong observability of the reference scooter with unknown inputs: the cases of the HOSM observer.

What ``ptw-assist observability`` prints and writes (``shared/spec/cli.md``).
The model is the linearisation at the upright, ``x' = E^-1 A(vx) x + E^-1 B tau``
(:meth:`ptw_env.vehicle.Vehicle.state_matrix`, ``input_matrix``), with
``x = [phi, delta, vy, r, phi_dot, delta_dot, Fyf, Fyr]``. An unknown input is
either the rider torque ``tau`` (its column ``E^-1 B`` becomes ``D``) or the
roll angle ``phi``, *rearranged* as in Nehaoua et al. [1]_ sec. III-A eq. (5):
the state ``phi`` and its equation ``phi' = phi_dot`` are removed and its
column of ``E^-1 A`` becomes ``D``; the remaining 7 states
``x_p = [delta, vy, r, phi_dot, delta_dot, Fyf, Fyr]`` keep their order.
(**Correction to [1]_**: eq. (5) lists ``x_p = [vy, r, phi_dot, delta_dot,
Fyf, Fyr]`` — six states — while the text says ``n = 7`` and the output is
``delta = C_p x_p``; ``delta`` belongs to ``x_p``.) Outputs are states of the
(rearranged) model or ``ay = (Fyf + Fyr)/M`` (:meth:`Vehicle.ay_row`).

Cases (:data:`CASES`):

* ``a_torque_delta`` — [1]_ sec. III-A: ``tau`` unknown, output ``delta``
  (paper: one unstable zero, ``r = 2``; neither observable nor detectable);
* ``b_roll_delta`` — [1]_ eq. (5): ``phi`` unknown (rearranged), ``tau``
  known, output ``delta`` (paper: ``r = 2``, 5 stable zeros);
* ``c_roll_torque_delta_r`` — [1]_ eq. (10): ``phi`` and ``tau`` unknown,
  outputs ``delta`` and ``r`` (paper: ``r = [2, 1]``, 4 stable zeros);
* ``d_roll_torque_delta_r_phidot`` and ``e_roll_torque_deltadot_r_phidot``
  — the paper's pair plus the roll-rate gyro of the same IMU (no invariant zero:
  strongly observable), found by :func:`measurement_search`.

On the reference scooter with model.md's corrected ``a45 = +3.665 vx``: case
(c), the paper's working case, is strongly detectable at every speed of 5-40
m/s (4 stable zeros, the slowest -0.43 1/s at 5 m/s); case (a) has its
unstable real zero only below about 19 m/s (+3.53 1/s at 8 m/s); case (b) is
detectable only at about 6-20 m/s.

The analysis itself is :func:`assist.unknown_input.structure.analyse`.

References
----------
.. [1] L. Nehaoua, D. Ichalal, H. Arioui, J. Davila, S. Mammar, L. Fridman,
   IEEE Trans. Vehicular Technology 63(7), 3116-3127, 2014.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from ptw_env.vehicle import PHI, REFERENCE_SCOOTER, STATE_NAMES, Vehicle

from assist.unknown_input.structure import StructureReport, analyse

#: Names an unknown input may take.
UNKNOWN_INPUT_NAMES = ("phi", "tau")
#: Output names besides the states.
EXTRA_OUTPUTS = ("ay",)
#: Sensors of the instrumented scooter usable by the observer (the roll angle is what we estimate).
SENSOR_OUTPUTS = ("delta", "delta_dot", "r", "phi_dot", "ay")
#: Default speed grid [m/s] of the analysis (the issue's 8-33 m/s).
DEFAULT_SPEEDS = tuple(float(v) for v in np.arange(8.0, 33.0 + 1e-9, 1.0))


class ObservabilityError(ValueError):
    """An unknown input, output or speed that the scooter case analysis cannot take."""


@dataclass(frozen=True, eq=False)
class PTWTriplet:
    """The scooter model arranged for unknown-input analysis at one speed.

    ``x' = A x + B u + D zeta``, ``y = C x`` with ``x`` named by
    :attr:`state_names`, known inputs :attr:`known_inputs` (``B``, possibly
    no column) and unknown inputs :attr:`unknown_inputs` (``D``).
    """

    vx: float
    A: np.ndarray
    B: np.ndarray
    D: np.ndarray
    C: np.ndarray
    state_names: tuple[str, ...]
    known_inputs: tuple[str, ...]
    unknown_inputs: tuple[str, ...]
    outputs: tuple[str, ...]

    @property
    def n(self) -> int:
        return self.A.shape[0]


def ptw_triplet(vx: float, unknown_inputs: Sequence[str], outputs: Sequence[str],
                vehicle: Vehicle | None = None) -> PTWTriplet:
    """Arrange the linearised scooter at speed ``vx`` [m/s] with the given unknown inputs and outputs.

    See the module docstring for the rearrangement of ``phi``. Nothing here
    writes a model entry: ``A``, ``D`` and ``B`` are columns/rows of
    ``Vehicle.state_matrix(vx)`` and ``Vehicle.input_matrix()``, the ``ay``
    row is ``Vehicle.ay_row()``.
    """
    v = REFERENCE_SCOOTER if vehicle is None else vehicle
    ui = tuple(unknown_inputs)
    outs = tuple(outputs)
    if not ui:
        raise ObservabilityError("give at least one unknown input ('phi' and/or 'tau')")
    for u in ui:
        if u not in UNKNOWN_INPUT_NAMES:
            raise ObservabilityError(f"unknown input {u!r} is not one of {UNKNOWN_INPUT_NAMES}")
    if len(set(ui)) != len(ui):
        raise ObservabilityError(f"unknown inputs repeated: {ui}")
    if not outs:
        raise ObservabilityError("give at least one output")
    if len(set(outs)) != len(outs):
        raise ObservabilityError(f"outputs repeated: {outs}")
    try:
        vx = float(vx)
    except (TypeError, ValueError):
        raise ObservabilityError(f"vx must be a number of m/s, got {vx!r}") from None
    if not (v.vmin <= vx <= v.vmax):
        raise ObservabilityError(f"vx = {vx} m/s is outside the vehicle's range [{v.vmin}, {v.vmax}] m/s")
    A8 = v.state_matrix(vx)
    B8 = v.input_matrix()
    keep = [i for i in range(8) if not ("phi" in ui and i == PHI)]
    names = tuple(STATE_NAMES[i] for i in keep)
    A = A8[np.ix_(keep, keep)]
    dcols, bcols = [], []
    for u in ui:
        dcols.append(A8[keep, PHI] if u == "phi" else B8[keep, 0])
    known = tuple(u for u in UNKNOWN_INPUT_NAMES if u not in ui and u == "tau")
    if known:
        bcols.append(B8[keep, 0])
    D = np.stack(dcols, axis=1)
    B = np.stack(bcols, axis=1) if bcols else np.zeros((len(keep), 0))
    rows = []
    ay = v.ay_row()[keep]
    for o in outs:
        if o in EXTRA_OUTPUTS:
            rows.append(ay)
        elif o in names:
            c = np.zeros(len(keep))
            c[names.index(o)] = 1.0
            rows.append(c)
        else:
            raise ObservabilityError(
                f"output {o!r} is not a state of the model with unknown inputs {ui} (states {names}) nor one of {EXTRA_OUTPUTS}"
            )
    C = np.array(rows)
    return PTWTriplet(vx=vx, A=A, B=B, D=D, C=C, state_names=names, known_inputs=known, unknown_inputs=ui, outputs=outs)


@dataclass(frozen=True)
class Case:
    """One analysis case: unknown inputs, outputs, and what the paper says about it."""

    name: str
    unknown_inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    description: str
    paper_claim: str


CASES: tuple[Case, ...] = (
    Case("a_torque_delta", ("tau",), ("delta",),
         "torque unknown, steering angle measured (paper sec. III-A)",
         "relative degree 2, one unstable invariant zero: neither strongly observable nor detectable"),
    Case("b_roll_delta", ("phi",), ("delta",),
         "roll angle rearranged as unknown input, torque known, steering angle measured (paper eq. 5)",
         "relative degree 2, 5 stable invariant zeros: strongly detectable"),
    Case("c_roll_torque_delta_r", ("phi", "tau"), ("delta", "r"),
         "roll angle and torque unknown, steering angle and yaw rate measured (paper eq. 10)",
         "vector relative degree [2, 1], 4 stable invariant zeros: strongly detectable"),
    Case("d_roll_torque_delta_r_phidot", ("phi", "tau"), ("delta", "r", "phi_dot"),
         "roll angle and torque unknown; steering angle, yaw rate and roll rate measured (ours)",
         "(not in the paper)"),
    Case("e_roll_torque_deltadot_r_phidot", ("phi", "tau"), ("delta_dot", "r", "phi_dot"),
         "roll angle and torque unknown; steering rate, yaw rate and roll rate measured (ours)",
         "(not in the paper)"),
)
#: The case the observer of :mod:`assist.unknown_input.hosm` uses by default.
WORKING_CASE = "d_roll_torque_delta_r_phidot"


def _case(name: str) -> Case:
    for c in CASES:
        if c.name == name:
            return c
    raise ObservabilityError(f"unknown case {name!r}; cases: {[c.name for c in CASES]}")


def analyse_triplet(tr: PTWTriplet, stability_margin: float = 0.0) -> StructureReport:
    """:func:`assist.unknown_input.structure.analyse` of a :class:`PTWTriplet`."""
    return analyse(tr.A, tr.D, tr.C, stability_margin=stability_margin)


def _speeds(speeds, vehicle: Vehicle = REFERENCE_SCOOTER) -> list[float]:
    if speeds is None:  # 26 speeds across the vehicle's design range (8-33 m/s by 1 m/s for the scooter)
        lo, hi = vehicle.control_range
        return [round(float(x), 6) for x in np.linspace(lo, hi, len(DEFAULT_SPEEDS))]
    sp = speeds
    try:
        out = [float(s) for s in np.atleast_1d(np.asarray(sp, dtype=float))]
    except (TypeError, ValueError):
        raise ObservabilityError(f"speeds must be numbers of m/s, got {speeds!r}") from None
    if not out:
        raise ObservabilityError("speeds is empty")
    return out


def _verdict(speeds: list[float], reps: list[StructureReport]) -> str:
    det = [r.strongly_detectable for r in reps]
    obs = [r.strongly_observable for r in reps]
    if all(obs):
        return "strongly observable at every speed (no invariant zero)"
    if all(det):
        worst = max(r.max_zero_real for r in reps)
        return f"strongly detectable at every speed (slowest zero Re = {worst:.3g} 1/s)"
    if not any(r.left_invertible for r in reps):
        return "not left-invertible: the unknown inputs cannot be told apart from these outputs"
    bad = [(s, r.max_zero_real) for s, r in zip(speeds, reps) if not r.strongly_detectable]
    worst_s, worst_z = max(bad, key=lambda b: b[1])
    good = [s for s, d in zip(speeds, det) if d]
    where = f"; detectable only at {min(good):g}-{max(good):g} m/s" if good else ""
    return (f"NOT strongly detectable at {len(bad)} of {len(speeds)} speeds: unstable zero up to "
            f"Re = +{worst_z:.3g} 1/s (at {worst_s:g} m/s){where}")


def analyse_case(case: Case | str, speeds=None, vehicle: Vehicle | None = None) -> dict[str, Any]:
    """One entry of the report's ``"cases"`` list (cli.md keys and more)."""
    c = _case(case) if isinstance(case, str) else case
    sp = _speeds(speeds, REFERENCE_SCOOTER if vehicle is None else vehicle)
    reps = [analyse_triplet(ptw_triplet(s, c.unknown_inputs, c.outputs, vehicle)) for s in sp]
    tr = ptw_triplet(sp[0], c.unknown_inputs, c.outputs, vehicle)
    return {
        "name": c.name,
        "description": c.description,
        "paper_claim": c.paper_claim,
        "unknown_inputs": list(c.unknown_inputs),
        "known_inputs": list(tr.known_inputs),
        "outputs": list(c.outputs),
        "states": list(tr.state_names),
        "speeds": sp,
        "relative_degree": [[None if r is None else int(r) for r in rep.relative_degree] for rep in reps],
        "invariant_zeros": [[[float(z.real), float(z.imag)] for z in rep.zeros] for rep in reps],
        "n_zeros": [int(rep.zeros.size) for rep in reps],
        "max_zero_real": [float(rep.max_zero_real) if np.isfinite(rep.max_zero_real) else None for rep in reps],
        "rank_D": [int(rep.rank_D) for rep in reps],
        "normal_rank": [int(rep.normal_rank) for rep in reps],
        "left_invertible": [bool(rep.left_invertible) for rep in reps],
        "decoupling_rank": [int(rep.decoupling_rank) for rep in reps],
        "strongly_observable": [bool(rep.strongly_observable) for rep in reps],
        "strongly_detectable": [bool(rep.strongly_detectable) for rep in reps],
        "reason": [rep.reason for rep in reps],  # "", "marginal zero ...", "unstable zero ...", "not left-invertible"
        "verdict": _verdict(sp, reps),
    }


def measurement_search(speeds=None, vehicle: Vehicle | None = None, unknown_inputs: Sequence[str] = ("phi", "tau"),
                       sensors: Sequence[str] = SENSOR_OUTPUTS, max_outputs: int = 3) -> list[dict[str, Any]]:
    """Every set of ``len(unknown_inputs)..max_outputs`` sensors, with its worst case over ``speeds``.

    Returns a list of ``{"outputs", "left_invertible_all", "strongly_observable_all",
    "strongly_detectable_all", "worst_zero_real"}`` (``worst_zero_real`` [1/s]: the largest real part of
    an invariant zero over the speeds, None when there is none or the set is not left-invertible), sorted:
    strongly observable first, then detectable, then by the number of sensors and the worst zero.
    """
    sp = _speeds(speeds, REFERENCE_SCOOTER if vehicle is None else vehicle)
    ui = tuple(unknown_inputs)
    rows = []
    for k in range(len(ui), max_outputs + 1):
        for combo in itertools.combinations(sensors, k):
            reps = [analyse_triplet(ptw_triplet(s, ui, combo, vehicle)) for s in sp]
            worst = max(r.max_zero_real for r in reps)  # -inf: no zero; +inf: not left-invertible
            entry = {
                "outputs": list(combo),
                "left_invertible_all": all(r.left_invertible for r in reps),
                "strongly_observable_all": all(r.strongly_observable for r in reps),
                "strongly_detectable_all": all(r.strongly_detectable for r in reps),
                "worst_zero_real": float(worst) if np.isfinite(worst) else None,
            }
            rows.append(((not entry["strongly_observable_all"], not entry["strongly_detectable_all"], k, worst), entry))
    rows.sort(key=lambda kv: kv[0])
    return [entry for _, entry in rows]


def observability_report(speeds=None, vehicle: Vehicle | None = None, search: bool = True) -> dict[str, Any]:
    """The structural analysis of :data:`CASES` over ``speeds`` [m/s] (default 26 speeds across the vehicle's design
    range, :attr:`ptw_env.vehicle.Vehicle.control_range`: 8-33 m/s by 1 m/s for the reference scooter).

    Returns the dictionary of ``shared/spec/cli.md`` (``{"cases": [{"name",
    "unknown_inputs", "outputs", "speeds", "relative_degree",
    "invariant_zeros", "strongly_detectable"}]}``; per-speed lists; zeros as
    ``[re, im]`` pairs [1/s]) plus ``"vehicle"``, ``"working_case"``,
    per-case ``"verdict"``, ranks and flags, and (``search=True``) the
    ``"measurement_search"`` over sets of the scooter's sensors with ``phi``
    and ``tau`` unknown.
    """
    v = REFERENCE_SCOOTER if vehicle is None else vehicle
    sp = _speeds(speeds, v)
    rep: dict[str, Any] = {
        "vehicle": v.name,
        "model": "E^-1 A(vx), E^-1 B linearised at phi = 0 (shared/spec/model.md); phi as unknown input rearranged "
                 "as in Nehaoua et al. 2014 eq. (5)",
        "speeds": sp,
        "cases": [analyse_case(c, sp, v) for c in CASES],
        "working_case": WORKING_CASE,
    }
    if search:
        rep["measurement_search"] = measurement_search(sp, v)
    return rep


def _zeros_str(zs: list[list[float]], limit: int = 6) -> str:
    parts = []
    for re_, im in zs[:limit]:
        parts.append(f"{re_:.3g}" if abs(im) < 1e-9 else f"{re_:.3g}{'+' if im > 0 else '-'}{abs(im):.3g}j")
    if len(zs) > limit:
        parts.append("...")
    return ", ".join(parts) if parts else "none"


def format_report(report: dict[str, Any], speeds_shown: Sequence[float] | None = None) -> str:
    """Human-readable table of :func:`observability_report` (a few speeds per case, then the verdict)."""
    lines = [f"Strong observability of {report.get('vehicle', '?')} with unknown inputs "
             f"({len(report['speeds'])} speeds, {min(report['speeds']):g}-{max(report['speeds']):g} m/s)"]
    for c in report["cases"]:
        sp = c["speeds"]
        show = speeds_shown
        if show is None:
            idx = sorted({0, len(sp) // 3, (2 * len(sp)) // 3, len(sp) - 1})
        else:
            idx = [int(np.argmin(np.abs(np.asarray(sp) - s))) for s in show]
        lines.append("")
        lines.append(f"[{c['name']}] unknown {c['unknown_inputs']}, outputs {c['outputs']}"
                     + (f", known {c['known_inputs']}" if c.get("known_inputs") else ""))
        lines.append(f"  paper: {c.get('paper_claim', '')}")
        lines.append(f"  {'vx m/s':>7}  {'r':>10}  {'rank R':>6}  {'#z':>3}  {'SO':>3}  {'SD':>3}  zeros [1/s]")
        for i in idx:
            rd = "[" + ",".join("-" if r is None else str(r) for r in c["relative_degree"][i]) + "]"
            lines.append(
                f"  {sp[i]:7.1f}  {rd:>10}  {c['normal_rank'][i]:>6}  {c['n_zeros'][i]:>3}  "
                f"{'yes' if c['strongly_observable'][i] else 'no':>3}  {'yes' if c['strongly_detectable'][i] else 'no':>3}  "
                f"{_zeros_str(c['invariant_zeros'][i])}"
            )
        lines.append(f"  => {c['verdict']}")
    if "measurement_search" in report:
        good = [m for m in report["measurement_search"] if m["strongly_detectable_all"]]
        lines.append("")
        lines.append(f"Measurement sets with phi and tau unknown that are strongly detectable at every speed: {len(good)}")
        for m in good:
            kind = "strongly observable" if m["strongly_observable_all"] else f"detectable, worst zero {m['worst_zero_real']:.3g}"
            lines.append(f"  {', '.join(m['outputs']):<30} {kind}")
        if not any(len(m["outputs"]) == 2 for m in good):
            lines.append("  (no two-sensor set works: every pair has an unstable invariant zero somewhere in the range)")
    lines.append("")
    lines.append(f"Observer case: {report.get('working_case')}")
    return "\n".join(lines)


def plot_report(report: dict[str, Any], path=None):
    """Figure: slowest invariant zero vs speed per case, and the zeros in the complex plane.

    Returns the matplotlib figure (saved to ``path`` if given).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cases = report["cases"]
    fig, axs = plt.subplots(1, 2, figsize=(12, 4.8), constrained_layout=True)
    ax = axs[0]
    none = []
    for k, c in enumerate(cases):
        mz = [np.nan if m is None else m for m in c["max_zero_real"]]
        if all(np.isnan(mz)):
            none.append(c["name"])
            continue
        ax.plot(c["speeds"], mz, "o-", ms=3, color=f"C{k}", label=c["name"])
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set_yscale("symlog", linthresh=1.0)
    ax.set_yticks([-100, -10, -1, 0, 1, 10, 100])
    ax.set_yticklabels(["-100", "-10", "-1", "0", "1", "10", "100"])
    if none:
        ax.text(0.02, 0.02, "no invariant zero (strongly observable):\n" + "\n".join(none), transform=ax.transAxes,
                fontsize=7, va="bottom")
    ax.set(xlabel="vx [m/s]", ylabel="max Re(invariant zero) [1/s]",
           title="slowest invariant zero (> 0: not strongly detectable)")
    ax.legend(fontsize=7, loc="best")
    ax = axs[1]
    for k, c in enumerate(cases):
        pts = [(z[0], z[1], s) for s, zs in zip(c["speeds"], c["invariant_zeros"]) for z in zs]
        if not pts:
            continue
        P = np.array(pts)
        ax.scatter(P[:, 0], P[:, 1], s=8 + 20 * (P[:, 2] - P[:, 2].min()) / max(1e-9, np.ptp(P[:, 2])),
                   color=f"C{k}", alpha=0.6, label=c["name"])
    ax.axvline(0.0, color="k", lw=0.8)
    ax.set_xscale("symlog", linthresh=1.0)
    ax.set(xlabel="Re [1/s] (symlog)", ylabel="Im [rad/s]", title="invariant zeros (marker size grows with speed)")
    ax.legend(fontsize=7, loc="best")
    if path is not None:
        fig.savefig(path, dpi=110)
    return fig


__all__ = [
    "CASES",
    "Case",
    "DEFAULT_SPEEDS",
    "ObservabilityError",
    "PTWTriplet",
    "SENSOR_OUTPUTS",
    "WORKING_CASE",
    "analyse_case",
    "analyse_triplet",
    "format_report",
    "measurement_search",
    "observability_report",
    "plot_report",
    "ptw_triplet",
]
