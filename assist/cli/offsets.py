"""Sensor offsets on the command line, shared by ``ptw-assist estimate`` and ``risk``: the ``--offsets`` option,
the filter's assumed noise, and the notes saying what was estimated, removed or kept
(:func:`assist.estimation.identification.correct_offsets`)."""

from __future__ import annotations

import argparse
from typing import Any

from ptw_env.logs import sidecar_noise_pct

#: What ``--offsets`` does (help of both commands). Its numbers are those of
#: :mod:`assist.estimation.identification` (``OFFSET_CHANNELS``, ``OFFSET_SIGNIFICANCE``, ``NIS_EXPLAINED``; a test
#: holds them equal), written out so that the parser does not import the estimators.
OFFSETS_HELP = ("sensor offsets as nuisance parameters, estimated first by a joint EKF with the states and stiffness: "
                "each offset beyond 3 of its standard deviations is removed from the log if the filter with the "
                "offsets explains every channel (mean normalised innovation at most 3), else reported, not removed; "
                "a second filter with linearly drifting offsets replaces the first where a drift stands out and it "
                "explains the log (the offsets are then removed as lines over the log): all (delta, yaw_rate, "
                "roll_rate, ay), none, or a comma-separated list of those channels")


def offsets_option(text: str) -> tuple[str, ...]:
    """``--offsets``: ``all``, ``none`` or a comma-separated list of channels
    (:func:`assist.estimation.identification.offset_channels` checks them)."""
    from assist.estimation.identification import IdentificationError, offset_channels

    if text == "none":
        return ()
    try:
        return offset_channels("all" if text == "all" else tuple(c.strip() for c in text.split(",")))
    except IdentificationError as exc:
        raise argparse.ArgumentTypeError(f"expected all, none or a list; {exc}") from None


def offset_notes(offsets: dict[str, dict[str, Any]], nis: dict[str, float | None], method: str,
                 before: str = "the estimate") -> list[str]:
    """The notes ``estimate`` prints for the sensor offsets it estimated (``info["offsets"]`` and
    ``info["offset_filter_nis"]`` of :func:`assist.estimation.identification.estimate`): those removed (as
    constants, or as lines over the log where they drift), those found but kept (the filter's model does not
    explain the log even with them: its worst channels named), those estimated jointly (``ukf``), and drifts
    read but not used. ``before``: what runs on the corrected log (``risk``: the warning)."""
    from assist.estimation.identification import NIS_EXPLAINED, OFFSET_SIGNIFICANCE, drift_used, stands_out

    def fmt(items):  # a drift is printed wherever it is part of the offset (a line, removed with it)
        return ", ".join(f"{c} {e['value']:+.4g} {e['unit']} (std {e['std']:.2g}"
                         + (f"; drifting {e['drift']['value']:+.3g} {e['drift']['unit']}, std {e['drift']['std']:.2g}"
                            if drift_used(e) else "") + ")" for c, e in items)

    unused = [(c, e) for c, e in offsets.items() if "drift" in e and not drift_used(e) and e["drift"]["significant"]]
    extra = ([f"linear drift(s) beyond {OFFSET_SIGNIFICANCE:g} standard deviations read but not used: "
              + ", ".join(f"{c} {e['drift']['value']:+.3g} {e['drift']['unit']} (std {e['drift']['std']:.2g})"
                          for c, e in unused)
              + " (the filter with drifting offsets does not explain the log either, so no line is taken off)"]
             if unused else [])
    sig = [(c, e) for c, e in offsets.items() if stands_out(e)]
    if not sig:
        return extra
    beyond = f"beyond {OFFSET_SIGNIFICANCE:g} standard deviations"
    how = (" (each a line over the log: a constant offset and a linear drift, the filter with drifting offsets "
           "explaining the log)" if any(drift_used(e) for _, e in sig) else "")
    if method == "ukf":
        return [f"sensor offset(s) {beyond}, estimated jointly with the states and stiffness{how}: {fmt(sig)} (an "
                "offset, or a model error it stands in for: 'ptw-assist diagnose' tells them apart)"] + extra
    removed = [(c, e) for c, e in sig if e.get("removed")]
    if removed:
        bank = "--road-bank" if method == "adaptive" else "--method adaptive --road-bank"
        return [f"sensor offset(s) {beyond} removed from the log before {before}{how}: {fmt(removed)} (the filter "
                f"with them explains every channel: mean squared innovation at most {NIS_EXPLAINED:g} times its "
                f"predicted variance; a road bank the model lacks reads much the same at a steady speed: if the road "
                f"is banked, give {bank})"] + extra
    worst = sorted(((v, c) for c, v in nis.items() if v is not None), reverse=True)[:2]
    return [f"sensor offset(s) {beyond} found but not removed: {fmt(sig)}; the model does not explain "
            "the log even with them (mean normalised innovation " + ", ".join(f"{c} {v:.1f}" for v, c in worst)
            + f"; at most {NIS_EXPLAINED:g} when it does), so they would stand in for a model error: "
              "'ptw-assist diagnose' says which part of the model misses"] + extra


def filter_sensors(pct: float | None, vehicle: Any):
    """The sensor noise the identification filters assume on a log (``estimate``, and the offsets' correction of
    ``risk``): ``pct`` percent of the vehicle's channel ranges when the user or the sidecar gives a noise level,
    else the reference sensors (:class:`ptw_env.sensors.SensorConfig`)."""
    from ptw_env.sensors import SensorConfig

    return SensorConfig.from_percent(pct, vehicle=vehicle) if pct is not None else SensorConfig()


def noise_pct_given(option: float | None, meta: dict) -> float | None:
    """The sensor noise [% of range] the user states: ``--noise``, else the sidecar's ``noise_pct``, else None."""
    if option is not None:
        return float(option)
    return sidecar_noise_pct(meta)


def offset_error_note(error: str, before: str = "the estimate") -> str:
    """The note when the offsets' filter diverged (:func:`assist.estimation.identification.correct_offsets`)."""
    return f"sensor offsets not estimated ({error}): {before} runs on the log as it is"
