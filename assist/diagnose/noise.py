"""How much of a replay residual is sensor noise: the noise level per channel, from the log itself.

A log need not say how noisy its sensors are, so the noise level is
measured, not assumed:

* **white noise**: the residual of the replay is sensor noise plus model
  error, and model error of a lateral-dynamics model sits at the frequencies
  of the rider and the vehicle modes (below ~15 Hz at 100 Hz sampling). The
  average periodogram of the windowed residual over the top of the band,
  ``[HIGH_BAND * fs/2, fs/2]``, is the white-noise variance
  (a flat spectrum has the same mean periodogram at every frequency);
* **encoder quantisation**: the steering-angle channel of logs.md comes from
  a 10-bit absolute encoder (``q = 2 pi / 1024`` rad per step). Its
  quantisation error follows the slowly varying angle (in straight running
  the angle reads exactly 0 for seconds), so it is *not* white and the high
  band misses most of it; the variance ``q^2 / 12`` is added. The encoder
  step is the caller's to give; by default it is logs.md's, unless the angle
  channel shows no noise at all (a noise-free simulation), when it is none.
  Detecting the grid from the readings is not reliable: noise of a sixth of a
  step blurs it and the cluster of readings at 0 mimics every coarser grid;
* **resolution floor**: a noise-free log (a simulation) has no noise at all;
  the diagnosis then resolves discrepancies down to :data:`FLOOR_FRACTION` of
  the reference sensors' noise (:data:`ptw_env.sensors.DEFAULT_NOISE_STD`),
  below which the replay's own numerical error (speed reconstruction,
  integration) lives.
"""

from __future__ import annotations

import math

import numpy as np

from ptw_env.sensors import DEFAULT_NOISE_STD, ENCODER_QUANTUM

#: Lower edge of the band used for the white-noise level, as a fraction of the Nyquist frequency.
HIGH_BAND = 0.4
#: Steering encoder step of logs.md [rad] (10-bit absolute encoder).
LOGS_MD_QUANTUM = ENCODER_QUANTUM
#: Resolution floor as a fraction of the reference sensors' noise.
FLOOR_FRACTION = 0.05


def white_noise_std(residual: np.ndarray, score: np.ndarray) -> np.ndarray:
    """White-noise standard deviation per channel from residual windows (module docstring).

    Parameters
    ----------
    residual : ndarray, shape (W, n, C)
        Replay residual in physical units (0 where not scored).
    score : ndarray of bool, shape (W, n, C)
        Scored samples.

    Returns
    -------
    ndarray, shape (C,)
    """
    first = int(np.argmax(score.any(axis=(0, 2))))  # the lead is never scored
    e = residual[:, first:, :]
    n = e.shape[1]
    frac = np.maximum(score[:, first:, :].mean(axis=(0, 1)), 1e-9)  # dropouts lower the power
    P = (np.abs(np.fft.rfft(e, axis=1)) ** 2).mean(axis=0) / n  # (nf, C)
    nf = P.shape[0]
    band = np.arange(nf) >= int(math.ceil(HIGH_BAND * (nf - 1)))
    band[-1] = n % 2 == 1  # the Nyquist bin of an even length has half the white power
    return np.sqrt(P[band].mean(axis=0) / frac)


def noise_levels(residual: np.ndarray, score: np.ndarray, channels: tuple[str, ...],
                 quantum: float | None | str = "auto") -> tuple[dict[str, float], float | None]:
    """Noise level per channel [physical units]: white part, encoder quantisation, floor.

    Parameters
    ----------
    residual, score
        As :func:`white_noise_std`.
    channels : tuple of str
        Channel names of the last axis.
    quantum : float, None or "auto"
        Steering encoder step [rad]; ``"auto"``: :data:`LOGS_MD_QUANTUM` unless the
        angle channel's white noise is below the resolution floor (then ``None``).

    Returns
    -------
    levels : dict channel -> float
    quantum : float or None
        The encoder step used.
    """
    white = white_noise_std(residual, score)
    floor = {c: FLOOR_FRACTION * DEFAULT_NOISE_STD[c] for c in channels}
    if quantum == "auto":
        i = channels.index("delta")
        quantum = LOGS_MD_QUANTUM if white[i] > floor["delta"] else None
    out = {}
    for i, c in enumerate(channels):
        v = float(white[i]) ** 2
        if c == "delta" and quantum is not None:
            v += float(quantum) ** 2 / 12.0
        out[c] = max(math.sqrt(v), floor[c])
    return out, quantum


__all__ = ["white_noise_std", "noise_levels", "FLOOR_FRACTION"]
