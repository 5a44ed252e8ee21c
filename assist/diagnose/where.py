"""Where a replay residual lives: channels, speeds, lean angles, frequency bands, steady vs transient.

For a residual ``e`` (measured minus predicted, scored samples only) and the
noise level ``sigma_c`` of each channel, the *excess* of a set of samples is
the RMS of the residual beyond the noise, in units of the noise,

.. math::

    \\text{excess} = \\sqrt{\\max\\left(0,\\;
        \\overline{(e_c/\\sigma_c)^2} - 1\\right)} ,

0 for a residual that is pure noise, 1 for a model error as large as the
noise. Samples are grouped by channel; by speed (:data:`SPEED_BINS`, m/s); by
lean angle ``|phi|`` (:data:`LEAN_BINS_DEG`; the logged roll, or the
replayed roll when the log has no roll column); by frequency band
(:data:`BANDS_HZ`, from the periodogram of each window, pooled over channels:
the noise's share of a band is its share of the bandwidth); and steady
(``|roll_rate| <`` :data:`STEADY_ROLL_RATE` and ``|delta_rate| <``
:data:`STEADY_STEER_RATE`, both low-passed over 0.5 s) vs transient.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.ndimage import uniform_filter1d

from .data import Windows

#: Speed bins [m/s].
SPEED_BINS = (3.0, 8.0, 12.0, 16.0, 20.0, 25.0, 40.0)
#: Lean-angle bins [deg].
LEAN_BINS_DEG = (0.0, 5.0, 15.0, 25.0, 90.0)
#: Frequency bands [Hz] (the last ends at Nyquist).
BANDS_HZ = (0.0, 0.5, 2.0, 5.0, 15.0, math.inf)
#: Steady riding: low-passed |roll rate| [rad/s] and |steer rate| [rad/s] below these.
STEADY_ROLL_RATE = 0.05
STEADY_STEER_RATE = 0.02
#: Smallest share of the samples a bin needs to be reported.
MIN_SHARE = 0.02


def _r(x: float, nd: int = 3) -> float:
    return float(round(float(x), nd))


def _excess(ms: float) -> float:
    return math.sqrt(max(0.0, ms - 1.0))


def _group(label: str, mask: np.ndarray, z2: np.ndarray, score: np.ndarray, total: int) -> dict | None:
    m = score & mask[..., None]
    n = int(m.sum())
    if n == 0 or n / total < MIN_SHARE:
        return None
    return {"bin": label, "share": _r(n / total), "excess": _r(_excess(float(z2[m].mean())))}


def breakdown(win: Windows, residual: np.ndarray, sigma: np.ndarray, roll: np.ndarray) -> dict:
    """Where the residual concentrates (module docstring).

    Parameters
    ----------
    win : Windows
    residual : ndarray, shape (W, n, C)
        Measured minus predicted, physical units (values outside ``win.score`` are ignored).
    sigma : ndarray, shape (C,)
        Noise level per channel.
    roll : ndarray, shape (W, n)
        Roll angle per sample [rad] for the lean bins.

    Returns
    -------
    dict
        ``{"channels": {c: {"rmse", "noise", "excess"}}, "speed_mps": [...], "lean_deg": [...],
        "frequency_hz": [...], "riding": [...], "summary": str}``.
    """
    score = win.score
    z2 = np.where(score, (residual / sigma) ** 2, 0.0)
    total = int(score.sum())
    out: dict = {"channels": {}}
    for i, c in enumerate(win.channels):
        s = score[..., i]
        ms = float(z2[..., i][s].mean()) if s.any() else 0.0
        out["channels"][c] = {"rmse": float(f"{sigma[i] * math.sqrt(ms):.4g}"), "noise": float(f"{sigma[i]:.4g}"),
                              "excess": _r(_excess(ms))}
    groups = []
    for lo, hi in zip(SPEED_BINS[:-1], SPEED_BINS[1:]):
        groups.append(_group(f"{lo:g}-{hi:g}", (win.speed >= lo) & (win.speed < hi), z2, score, total))
    out["speed_mps"] = [g for g in groups if g]
    lean = np.degrees(np.abs(roll))
    groups = [_group(f"{lo:g}-{hi:g}" if hi < 90 else f">{lo:g}", (lean >= lo) & (lean < hi), z2, score, total)
              for lo, hi in zip(LEAN_BINS_DEG[:-1], LEAN_BINS_DEG[1:])]
    out["lean_deg"] = [g for g in groups if g]
    # frequency: periodogram of the scored part of each window, noise-normalised, pooled over channels
    e = np.where(score, residual / sigma, 0.0)[:, win.lead:, :]
    n = e.shape[1]
    P = (np.abs(np.fft.rfft(e, axis=1)) ** 2).mean(axis=(0, 2)) / n  # unit white noise: 1 in every bin
    f = np.fft.rfftfreq(n, win.dt)
    frac = float(score[:, win.lead:, :].mean())
    bands = []
    for lo, hi in zip(BANDS_HZ[:-1], BANDS_HZ[1:]):
        sel = (f >= lo) & (f < hi)
        if not sel.any():
            continue
        ms = float(P[sel].mean()) / max(frac, 1e-9)
        label = f"{lo:g}-{hi:g}" if math.isfinite(hi) else f">{lo:g}"
        bands.append({"bin": label, "share": _r(sel.sum() / len(f)), "excess": _r(_excess(ms))})
    out["frequency_hz"] = bands
    ch = {c: i for i, c in enumerate(win.channels)}
    k = max(1, int(round(0.5 / win.dt)))
    rr = np.abs(uniform_filter1d(win.Y[..., ch["roll_rate"]], k, axis=1))
    dr = np.abs(uniform_filter1d(win.Y[..., ch["delta_rate"]], k, axis=1))
    steady = (rr < STEADY_ROLL_RATE) & (dr < STEADY_STEER_RATE)
    groups = [_group("steady", steady, z2, score, total), _group("transient", ~steady, z2, score, total)]
    out["riding"] = [g for g in groups if g]
    out["summary"] = summarise(out)
    return out


def summarise(b: dict) -> str:
    """One sentence: the channels and the bins where the excess is largest."""
    chans = sorted(b["channels"].items(), key=lambda kv: -kv[1]["excess"])
    top = [f"{c} ({v['excess']:.2g} x noise)" for c, v in chans if v["excess"] >= 0.2][:3]
    if not top:
        return "the residual is at the noise level in every channel"
    parts = ["residual beyond noise in " + ", ".join(top)]
    names = {"speed_mps": ("speeds", "m/s"), "lean_deg": ("lean angles", "deg"), "frequency_hz": ("frequencies", "Hz"),
             "riding": ("", "")}
    for key, (what, unit) in names.items():
        g = b.get(key) or []
        if len(g) < 2:
            continue
        best = max(g, key=lambda x: x["excess"])
        rest = [x["excess"] for x in g if x is not best]
        if best["excess"] >= 0.2 and best["excess"] >= 1.3 * max(rest):
            parts.append(f"{what} {best['bin']} {unit}".strip() if what else f"{best['bin']} riding")
    return "; ".join(parts)


__all__ = ["breakdown", "summarise"]
