"""From a ride log to the short replay windows the diagnosis works on.

A log (``shared/spec/logs.md``) is cut into consecutive windows of
``window_s`` seconds. Each window is replayed from its own initial state
(:mod:`assist.diagnose.replay`), so it starts ``lead_s`` earlier than the
part that is scored: the lead lets a delayed sensor (effects.md,
``sensor_delay``) read samples from before the scored part, exactly as a real
sensor does. Scored parts tile the log; even windows are used to fit effect
sizes, odd windows to score them (held-out data).

Inputs of the replay
--------------------
* ``tau`` [N m]: the logged torque, held over each sample (zero-order hold,
  as logs.md and the simulator do).
* ``vx`` [m/s]: the logged speed is a GPS reading refreshed at a lower rate
  (10 Hz) and held in between, with noise. The replay uses a reconstruction:
  the GPS fixes (the samples where the reading changes) are joined linearly at
  the instants they were taken and smoothed with a Gaussian kernel of
  standard deviation :data:`VX_SMOOTH_S` (not when the fixes show no noise,
  :data:`NOISELESS_SPEED`). Using the held reading directly
  would lag the true speed by half a GPS period (up to 0.15 m/s at 3 m/s^2).

A window whose input has a dropout (NaN) or whose speed leaves the model's
valid range is left out; a measured channel's dropout only removes that
sample from the comparison.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter1d

from ptw_env.logs import RideLog, held_speed, speed_fixes

from .measurement import CHANNELS

#: Standard deviation of the Gaussian smoothing of the GPS speed [s].
VX_SMOOTH_S = 0.15
#: GPS fix jitter [m/s] below which the speed channel is taken as noise-free and not smoothed.
NOISELESS_SPEED = 1e-3


#: Replay windows the automatic window length aims at (half of them held out; the support test of
#: :mod:`assist.diagnose.selection` leaves the two most improved held-out windows out).
TARGET_WINDOWS = 16
#: Fewest replay windows a diagnosis accepts: 4 fitted, 4 held out (the support test then leaves one
#: held-out window out). Real rides can be short (6-8 s segments of the robot bicycle); below
#: :data:`TARGET_WINDOWS` the report says the held-out evidence is thin.
MIN_WINDOWS = 8
#: Default and shortest automatic window length [s].
WINDOW_S = 2.0
MIN_WINDOW_S = 0.5


def auto_window(duration_s: float, lead_s: float) -> float:
    """Window length [s]: :data:`WINDOW_S`, shortened (not below :data:`MIN_WINDOW_S`) so that a
    short log still gives :data:`TARGET_WINDOWS` windows."""
    fit = (duration_s - lead_s) / TARGET_WINDOWS
    return float(min(WINDOW_S, max(MIN_WINDOW_S, math.floor(fit * 10.0) / 10.0)))


class DiagnoseInputError(ValueError):
    """A log the diagnosis cannot use (too short, no usable window, a bad option); the message says what and where."""


def reconstruct_speed(t: np.ndarray, vx: np.ndarray, smooth_s: float = VX_SMOOTH_S) -> np.ndarray:
    """Speed at each sample from a held, noisy GPS channel (module docstring).

    Parameters
    ----------
    t, vx : ndarray, shape (K,)
        Sample times [s] and the logged speed [m/s] (NaN: dropout).
    smooth_s : float
        Gaussian smoothing standard deviation [s].

    Returns
    -------
    ndarray, shape (K,)
        The reconstructed speed [m/s].
    """
    ok = np.isfinite(vx)
    if ok.sum() < 2:
        raise DiagnoseInputError("column 'vx': fewer than two speed readings (the replay needs the forward speed)")
    tf, vf = speed_fixes(t, vx)  # ptw_env.logs: the one reconstruction of the held speed
    v = held_speed(t, vx)
    if len(vf) >= 5:
        # jitter of the fixes about a straight line through their neighbours (robust, m/s)
        d2 = vf[1:-1] - (vf[:-2] * (tf[2:] - tf[1:-1]) + vf[2:] * (tf[1:-1] - tf[:-2])) / (tf[2:] - tf[:-2])
        jitter = 1.4826 * float(np.median(np.abs(d2))) / np.sqrt(1.5)
        if jitter < NOISELESS_SPEED:
            return v  # a noise-free speed channel: nothing to smooth
    dt = float(np.median(np.diff(t)))
    return gaussian_filter1d(v, smooth_s / dt, mode="nearest") if smooth_s > 0 else v


@dataclass(frozen=True)
class Windows:
    """Replay windows cut from one log (all arrays read-only by convention).

    Attributes
    ----------
    dt : float
        Sample period [s].
    lead : int
        Samples at the start of each window that are simulated but not scored.
    starts : ndarray, shape (W,)
        Index in the log of each window's first sample (where its state is estimated).
    tau, vx : ndarray, shape (W, n - 1)
        Inputs held over each sample [N m], [m/s].
    speed : ndarray, shape (W, n)
        Reconstructed speed at each sample [m/s] (for the residual breakdown).
    Y : ndarray, shape (W, n, C)
        Measured channels (0 at a dropout).
    valid : ndarray of bool, shape (W, n, C)
        Readings that are not dropouts.
    score : ndarray of bool, shape (W, n, C)
        Samples that are compared (after the lead, not a dropout).
    channels : tuple of str
        The C channels of ``Y``.
    train : ndarray of bool, shape (W,)
        Windows used to fit effect sizes (the others are held out).
    t0 : ndarray, shape (W,)
        Log time of each window's first sample [s].
    """

    dt: float
    lead: int
    starts: np.ndarray
    tau: np.ndarray
    vx: np.ndarray
    speed: np.ndarray
    Y: np.ndarray
    valid: np.ndarray
    score: np.ndarray
    channels: tuple[str, ...]
    train: np.ndarray
    t0: np.ndarray

    @property
    def t_mid(self) -> float:
        """Log time of the middle of the span the windows cover [s] (the reference of a sensor drift closure,
        :class:`assist.diagnose.params.ClosureTerm`)."""
        return float(0.5 * (self.t0.min() + self.t0.max() + (self.n - 1) * self.dt))

    @property
    def t_half(self) -> float:
        """Half the span the windows cover [s] (a sensor drift closure's time scale)."""
        return float(0.5 * (self.t0.max() - self.t0.min() + (self.n - 1) * self.dt))

    @property
    def n(self) -> int:
        """Samples per window (lead included)."""
        return int(self.Y.shape[1])

    def __len__(self) -> int:
        return int(self.Y.shape[0])


def make_windows(log: RideLog, window_s: float, lead_s: float, vmin: float, vmax: float,
                 source: str = "log") -> tuple[Windows, list[str]]:
    """Cut ``log`` into replay windows (module docstring).

    Returns
    -------
    windows : Windows
    notes : list of str
        Why windows were left out (dropouts in ``tau``, speed out of range).

    Raises
    ------
    DiagnoseInputError
        When fewer than :data:`MIN_WINDOWS` usable windows remain.
    """
    dt = log.dt
    K = len(log)
    L = int(round(window_s / dt))
    lead = int(math.ceil(lead_s / dt - 1e-9))
    if L < 10:
        raise DiagnoseInputError(f"window_s = {window_s} s holds fewer than 10 samples at dt = {dt:g} s")
    channels = tuple(c for c in CHANNELS if log.has(c))
    Yall = np.column_stack([log[c] for c in channels])
    tau = log["tau"]
    raw_v = log["vx"]
    speed = reconstruct_speed(log.t, raw_v)
    # a measured speed outside the range (standstill, a sensor reading 0 or less) is trimmed, never smoothed over
    raw_out = np.isfinite(raw_v) & ((raw_v < vmin) | (raw_v > vmax))
    starts, notes = [], []
    if getattr(log, "ignored_columns", ()):
        notes.append(f"column(s) {', '.join(log.ignored_columns)} ignored: extra columns holding text (logs.md)")
    bad_tau = bad_v = 0
    for s in range(0, K - lead - L + 1, L):
        sl = slice(s, s + lead + L)
        if not np.all(np.isfinite(tau[s : s + lead + L - 1])):
            bad_tau += 1
            continue
        v = speed[sl]
        if v.min() < vmin or v.max() > vmax or raw_out[sl].any():
            bad_v += 1
            continue
        starts.append(s)
    if bad_tau:
        notes.append(f"{bad_tau} window(s) left out: unread samples in column 'tau' (dropouts, or readings at "
                     "a clipped limit)")
    if bad_v:
        k = np.flatnonzero(raw_out)
        first = (f"; measured vx = {raw_v[k[0]]:g} m/s at sample {k[0]} (t = {log.t[k[0]]:g} s), "
                 f"{k.size} such sample(s)") if k.size else ""
        notes.append(f"{bad_v} window(s) left out: speed outside the model's range [{vmin}, {vmax}] m/s{first}")
    if len(starts) < MIN_WINDOWS:
        need = MIN_WINDOWS * L + lead
        raise DiagnoseInputError(
            f"{source}: {len(starts)} usable replay window(s) of {window_s:g} s; the diagnosis needs at least "
            f"{MIN_WINDOWS} (a log of at least {need * dt:.1f} s with the speed in [{vmin}, {vmax}] m/s and no "
            f"torque dropouts)"
            + (f"; {'; '.join(notes)}" if notes else "")
        )
    if len(starts) < TARGET_WINDOWS:
        notes.append(f"only {len(starts)} replay windows of {window_s:g} s (a diagnosis aims at {TARGET_WINDOWS}): "
                     "the held-out evidence is thin")
    st = np.array(starts)
    idx = st[:, None] + np.arange(lead + L)[None, :]
    Y = Yall[idx]
    score = np.isfinite(Y)
    score[:, :lead] = False
    train = np.arange(len(st)) % 2 == 0
    w = Windows(
        dt=dt, lead=lead, starts=st, tau=tau[idx[:, :-1]], vx=speed[idx[:, :-1]], speed=speed[idx],
        Y=np.where(np.isfinite(Y), Y, 0.0), valid=np.isfinite(Y), score=score, channels=channels, train=train,
        t0=log.t[st],
    )  # fmt: skip
    return w, notes


__all__ = ["DiagnoseInputError", "auto_window", "MIN_WINDOWS", "Windows", "make_windows", "reconstruct_speed",
           "VX_SMOOTH_S"]
