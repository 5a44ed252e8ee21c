"""The instrumented scooter: what its sensors report about the true state.

Implements the sensor realism of ``shared/spec/logs.md`` ("Sensor realism the
simulator offers") and the three sensor effects of ``shared/spec/effects.md``
(``gyro_bias``, ``ay_frame``, ``sensor_delay``). The vehicle dynamics are not
touched here: :meth:`SensorModel.measure` maps a true state (from
:mod:`ptw_env.integrate`) and the true model-frame lateral acceleration
(:meth:`ptw_env.dynamics.Plant.ay`) to one row of a ride log.

Measured channels (log-column names of logs.md, in :data:`CHANNELS` order)

=====  ============  =======  ======================  ==========================
index  channel       unit     true quantity           sensor
=====  ============  =======  ======================  ==========================
0      delta         rad      ``x[1]`` delta          10-bit absolute encoder
1      delta_rate    rad/s    ``x[5]`` delta_dot      encoder rate channel
2      yaw_rate      rad/s    ``x[3]`` r              IMU gyro
3      roll_rate     rad/s    ``x[4]`` phi_dot        IMU gyro
4      ay            m/s^2    ``(Fyf+Fyr)/(M+m)``     IMU accelerometer
5      roll          rad      ``x[0]`` phi            high-end IMU attitude filter
6      vx            m/s      forward speed           GPS, 10 Hz, sample-and-hold
=====  ============  =======  ======================  ==========================

Sampling model
--------------
:meth:`SensorModel.measure` is called once per control period ``dt``, at the
sample instant ``t_k = k dt`` (``k = 0`` is the first call after
:meth:`SensorModel.reset`), on the true state at ``t_k``. One call is one row
of a 100 Hz ride log. The GPS speed is refreshed at the calls whose time
``t_k`` starts a new GPS period (``floor(t_k * gps_rate_hz)`` changes, so at
100 Hz and 10 Hz the calls ``k = 0, 10, 20, ...``) and held in between.

Order of operations (per call)
------------------------------
1. true channels ``delta, delta_dot, r, phi_dot, ay, phi`` at ``t_k``;
2. ``ay_frame`` (effects.md):
   ``ay_meas = ay + gain (ay cos(phi) - g sin(phi) - ay)`` with the true
   ``phi`` at ``t_k``;
3. ``sensor_delay`` (effects.md): the six IMU and encoder channels (not ``vx``,
   which is an input like ``tau``) are read ``delay_s`` in the past from a ring
   buffer of step-2 vectors, linearly interpolated between samples for a delay
   that is not a multiple of ``dt``; before enough history exists the oldest
   sample (``k = 0``) stands in;
4. bias: ``gyro_bias`` adds ``yaw_rate_bias`` and ``roll_rate_bias``;
   :attr:`SensorConfig.bias` adds its per-channel offsets;
5. steering encoder quantisation ``delta_q = q round(delta / q)`` and white
   Gaussian noise of standard deviation ``noise_std[channel]``. By default the
   angle is quantised first and the noise added after (``delta_q + n``), which
   is how the reference logs of ``shared/data`` were made (their sidecars:
   "delta quantised 2*pi/1024 + 0.001 rad"; the residual of
   ``nominal_urban.csv`` against its noise-free twin about the quantised angle
   has std 0.00101 rad, and 87 % of its readings are off the encoder grid).
   ``SensorConfig(noise_before_quantisation=True)`` gives the other physical
   reading, ``q round((delta + n) / q)`` (a noisy angle read by an ideal
   encoder), whose outputs lie exactly on the grid.

``vx`` is ``true vx + bias + noise`` sampled and held at the GPS rate, with no
delay and no quantisation.

References
----------
``shared/spec/logs.md`` (channels, 10-bit encoder, 10 Hz GPS, percent-of-range
noise), ``shared/spec/effects.md`` (sensor effects), sidecars of
``shared/data/*.json`` (default noise levels).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Mapping

import numpy as np
from numba import njit

from .effects import Effects, EffectError, as_effects
from .vehicle import DELTA, DELTA_DOT, G, PHI, PHI_DOT, R

#: Measured channels, in the order :meth:`SensorModel.measure` returns them (log columns, logs.md).
CHANNELS: tuple[str, ...] = ("delta", "delta_rate", "yaw_rate", "roll_rate", "ay", "roll", "vx")
#: Units of :data:`CHANNELS`.
CHANNEL_UNITS: tuple[str, ...] = ("rad", "rad/s", "rad/s", "rad/s", "m/s^2", "rad", "m/s")
#: The IMU and encoder channels: the ones ``sensor_delay`` delays and ``from_percent`` scales.
DELAYED_CHANNELS: tuple[str, ...] = CHANNELS[:6]

#: Full-scale range per channel, the "100 %" of percent-of-range noise
#: (:meth:`SensorConfig.from_percent`). Chosen as the round value just above the
#: largest magnitude in the reference urban ride (``shared/data/nominal_urban.csv``:
#: |delta| 0.046 rad, |delta_rate| 0.16 rad/s, |yaw_rate| 0.43 rad/s,
#: |roll_rate| 0.74 rad/s, |ay| 5.1 m/s^2, |roll| 0.52 rad), i.e. the amplitude of
#: the signal in an everyday ride, which is how the papers quote "5 % noise".
#: ``vx`` is listed for completeness (the scooter's vmax, 40 m/s) but a scalar
#: percent does not apply to it: GPS speed keeps its physical noise.
CHANNEL_RANGES: Mapping[str, float] = MappingProxyType(
    {
        "delta": 0.05,  # rad
        "delta_rate": 0.2,  # rad/s
        "yaw_rate": 0.5,  # rad/s
        "roll_rate": 1.0,  # rad/s
        "ay": 5.0,  # m/s^2
        "roll": 0.5,  # rad
        "vx": 40.0,  # m/s
    }
)

def channel_ranges(vehicle: Any = None) -> Mapping[str, float]:
    r"""The "100 %" of percent-of-range noise for ``vehicle`` (default: the reference scooter, :data:`CHANNEL_RANGES`).

    :data:`CHANNEL_RANGES` is the amplitude of the reference scooter's signals in an everyday ride. Another
    vehicle ridden at the same lateral acceleration ``a_y`` (the envelope is the road's friction, not the
    vehicle's) at the middle ``v`` of its design range (:attr:`ptw_env.vehicle.Vehicle.control_range`) turns
    with the kinematics of a steady turn: roll ``atan(a_y / g)`` and ``a_y`` itself are the same, the yaw rate
    ``a_y / v`` scales as ``1 / v``, the steer angle as the kinematic steer ``L a_y / v^2`` (``L = lf_slip +
    lr_slip``, the wheelbase); the roll and steer rates are those amplitudes over the manoeuvre's time scale,
    which is the rider's (a lane change takes a second or two on any two-wheeler), so they scale like their
    angles; ``vx`` as the valid top speed:

    .. math::  R_c(\text{vehicle}) = R_c(\text{ref}) \, k_c, \quad k_{yaw} = v_0 / v, \;
               k_\delta = k_{\dot\delta} = (L / v^2) / (L_0 / v_0^2), \; k_\phi = k_{\dot\phi} = k_{a_y} = 1,

    with ``v_0``, ``L_0`` the reference scooter's: every ratio is exactly 1 for it. Checked against the
    linear model's steady turn (``r / a_y = 1 / v``, ``phi / a_y = 1 / g`` within 4 % on every preset) and
    against the 14 measured robot-bicycle rides (their largest |signals|: delta 0.30 rad, delta_rate 2.0
    rad/s, yaw rate 0.84 rad/s, roll rate 0.59 rad/s, a_y 3.5 m/s^2; these ranges are 1.0 rad, 4.1 rad/s,
    2.7 rad/s, 1.0 rad/s, 5 m/s^2: of the same order, larger, as those rides are gentle), in
    ``tests/test_sensors.py``.
    """
    from .vehicle import REFERENCE_SCOOTER

    ref = REFERENCE_SCOOTER
    if vehicle is None or vehicle is ref:
        return CHANNEL_RANGES
    v0, v = (0.5 * sum(x.control_range) for x in (ref, vehicle))
    L0, L = (x.tires.lf_slip + x.tires.lr_slip for x in (ref, vehicle))
    k_delta = (L / v**2) / (L0 / v0**2)
    k = {"delta": k_delta, "delta_rate": k_delta, "yaw_rate": v0 / v, "roll_rate": 1.0, "ay": 1.0,
         "roll": 1.0, "vx": vehicle.vmax / ref.vmax}
    return MappingProxyType({c: CHANNEL_RANGES[c] * k[c] for c in CHANNEL_RANGES})


#: Default white-noise standard deviations, physical units, equal to the sidecars
#: of the reference logs (``shared/data/*.json``, "notes").
DEFAULT_NOISE_STD: Mapping[str, float] = MappingProxyType(
    {
        "delta": 0.001,  # rad (plus quantisation)
        "delta_rate": 0.01,  # rad/s
        "yaw_rate": 0.005,  # rad/s
        "roll_rate": 0.005,  # rad/s
        "ay": 0.1,  # m/s^2
        "roll": 0.005,  # rad
        "vx": 0.05,  # m/s, at the GPS rate
    }
)

#: Resolution of the 10-bit absolute steering encoder [rad per step] (logs.md).
ENCODER_QUANTUM = 2.0 * math.pi / 1024.0

#: Default GPS update rate [Hz] (logs.md).
GPS_RATE_HZ = 10.0

#: Noise is drawn in blocks of this many samples (one generator call per block). Any block length gives
#: the same readings within a recording, but a reset draws from the generator after the last block, so
#: every sensor set that must follow the same stream (single and vector environment) uses this one.
NOISE_BLOCK = 512
# delays within this many samples of an integer are treated as that integer
_DELAY_SNAP = 1e-9


class SensorConfigError(ValueError):
    """A sensor setting that is unknown or outside its physical range."""


class SensorResetError(RuntimeError):
    """:meth:`SensorModel.measure` was called before :meth:`SensorModel.reset`."""


def _channel_map(name: str, values: Mapping[str, Any] | None, *, allow_negative: bool) -> Mapping[str, float]:
    """Validate a per-channel mapping; complete it with zeros for the channels left out."""
    if values is None:
        values = {}
    if not isinstance(values, Mapping):
        raise SensorConfigError(f"{name} must be a mapping channel -> value, got {values!r}")
    out = {c: 0.0 for c in CHANNELS}
    for c, v in values.items():
        if c not in out:
            raise SensorConfigError(f"{name}: unknown channel {c!r}; known: {', '.join(CHANNELS)}")
        try:
            f = float(v)
        except (TypeError, ValueError):
            raise SensorConfigError(f"{name}[{c!r}] must be a number, got {v!r}") from None
        if not math.isfinite(f):
            raise SensorConfigError(f"{name}[{c!r}] must be finite, got {v!r}")
        if f < 0.0 and not allow_negative:
            raise SensorConfigError(f"{name}[{c!r}] must be >= 0, got {v!r}")
        out[c] = f
    return MappingProxyType(out)


@dataclass(frozen=True)
class SensorConfig:
    """Noise, bias and resolution of the instrumented scooter's sensors (immutable).

    Parameters
    ----------
    noise_std : mapping channel -> float
        White Gaussian noise standard deviation per channel, in the channel's
        physical unit (:data:`CHANNEL_UNITS`). A channel left out is noise-free.
        Default: :data:`DEFAULT_NOISE_STD`, the reference logs' levels. For
        ``vx`` it is the noise of each GPS fix.
    bias : mapping channel -> float
        Constant offset per channel, physical units (default: none).
    delta_quantum : float or None
        Steering encoder step [rad]; default ``2 pi / 1024`` (10-bit absolute
        encoder, logs.md). ``None`` disables quantisation.
    gps_rate_hz : float
        GPS update rate [Hz] of the ``vx`` channel (sample-and-hold); default 10.
        A rate at or above the control rate, e.g. ``math.inf``, refreshes every
        sample.
    noise_before_quantisation : bool
        ``False`` (default, as the reference logs): ``delta = q round(delta/q) + n``.
        ``True``: ``delta = q round((delta + n)/q)``.

    Notes
    -----
    To change one channel keep the others explicitly, e.g.
    ``dataclasses.replace(cfg, noise_std={**cfg.noise_std, "ay": 0.2})``.
    The stored mappings always hold all seven channels.

    Examples
    --------
    >>> SensorConfig().noise_std["ay"]
    0.1
    >>> SensorConfig.from_percent(5).noise_std["roll_rate"]
    0.05
    >>> SensorConfig.noiseless().delta_quantum is None
    True
    """

    noise_std: Mapping[str, float] = field(default_factory=lambda: dict(DEFAULT_NOISE_STD))
    bias: Mapping[str, float] = field(default_factory=dict)
    delta_quantum: float | None = ENCODER_QUANTUM
    gps_rate_hz: float = GPS_RATE_HZ
    noise_before_quantisation: bool = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "noise_std", _channel_map("noise_std", self.noise_std, allow_negative=False))
        object.__setattr__(self, "bias", _channel_map("bias", self.bias, allow_negative=True))
        if self.delta_quantum is not None:
            try:
                q = float(self.delta_quantum)
            except (TypeError, ValueError):
                raise SensorConfigError(f"delta_quantum must be a number or None, got {self.delta_quantum!r}") from None
            if not (math.isfinite(q) and q > 0.0):
                raise SensorConfigError(
                    f"delta_quantum must be a finite step > 0 rad (or None), got {self.delta_quantum!r}"
                )
            object.__setattr__(self, "delta_quantum", q)
        try:
            rate = float(self.gps_rate_hz)
        except (TypeError, ValueError):
            raise SensorConfigError(f"gps_rate_hz must be a number, got {self.gps_rate_hz!r}") from None
        if not rate > 0.0:  # also rejects NaN
            raise SensorConfigError(f"gps_rate_hz must be a rate > 0 Hz (inf: every sample), got {self.gps_rate_hz!r}")
        object.__setattr__(self, "gps_rate_hz", rate)
        if not isinstance(self.noise_before_quantisation, (bool, np.bool_)):
            raise SensorConfigError(
                f"noise_before_quantisation must be True or False, got {self.noise_before_quantisation!r}"
            )
        object.__setattr__(self, "noise_before_quantisation", bool(self.noise_before_quantisation))

    # frozen dataclass with MappingProxyType fields: make pickling explicit
    def __reduce__(self):
        return (
            SensorConfig,
            (
                dict(self.noise_std),
                dict(self.bias),
                self.delta_quantum,
                self.gps_rate_hz,
                self.noise_before_quantisation,
            ),
        )

    @classmethod
    def noiseless(cls, gps_rate_hz: float = math.inf) -> "SensorConfig":
        """No noise, no bias, no quantisation; by default ``vx`` refreshed every sample.

        Every channel then equals its true value at ``t_k`` (sensor effects,
        which belong to the vehicle's :class:`~ptw_env.effects.Effects`, still
        apply).
        """
        return cls(noise_std={}, bias={}, delta_quantum=None, gps_rate_hz=gps_rate_hz)

    @classmethod
    def from_percent(
        cls,
        pct: float | Mapping[str, float],
        *,
        vx_std: float = DEFAULT_NOISE_STD["vx"],
        bias: Mapping[str, float] | None = None,
        delta_quantum: float | None = ENCODER_QUANTUM,
        gps_rate_hz: float = GPS_RATE_HZ,
        noise_before_quantisation: bool = False,
        vehicle: Any = None,
    ) -> "SensorConfig":
        """Noise as a percentage of each channel's range (the papers' "5 % noise").

        ``noise_std[c] = pct / 100 * R_c`` for the six IMU and
        encoder channels (:data:`DELAYED_CHANNELS`), ``R = channel_ranges(vehicle)``
        (:data:`CHANNEL_RANGES` for the reference scooter, the default); ``vx`` keeps the physical
        ``vx_std`` [m/s].

        Parameters
        ----------
        pct : float or mapping channel -> float
            Percent of range, one value for all six channels or one per channel
            (channels left out are noise-free). Must be finite and >= 0.
        vx_std : float
            GPS speed noise [m/s].
        bias, delta_quantum, gps_rate_hz, noise_before_quantisation
            As :class:`SensorConfig`.
        vehicle : Vehicle, optional
            Whose channel ranges (:func:`channel_ranges`).
        """
        ranges = channel_ranges(vehicle)
        if isinstance(pct, Mapping):
            pcts = dict(pct)
            if "vx" in pcts:
                raise SensorConfigError("pct['vx']: the percent form does not apply to vx (GPS); pass vx_std in m/s")
        else:
            pcts = {c: pct for c in DELAYED_CHANNELS}
        stds: dict[str, float] = {}
        for c, p in pcts.items():
            if c not in CHANNEL_RANGES:
                raise SensorConfigError(f"pct: unknown channel {c!r}; known: {', '.join(DELAYED_CHANNELS)}")
            try:
                f = float(p)
            except (TypeError, ValueError):
                raise SensorConfigError(f"pct[{c!r}] must be a number, got {p!r}") from None
            if not (math.isfinite(f) and f >= 0.0):
                raise SensorConfigError(f"pct[{c!r}] must be a finite percentage >= 0, got {p!r}")
            stds[c] = f / 100.0 * ranges[c]
        stds["vx"] = vx_std
        return cls(
            noise_std=stds,
            bias=bias,
            delta_quantum=delta_quantum,
            gps_rate_hz=gps_rate_hz,
            noise_before_quantisation=noise_before_quantisation,
        )


def _scalar_effect(effects: Effects, cause: str, param: str) -> float:
    v = effects.value(cause, param)
    if np.ndim(v) != 0:
        raise SensorConfigError(
            f"effect {cause}:{param} is array-valued (shape {np.shape(v)}); a SensorModel measures one vehicle"
        )
    return float(v)


@njit(cache=True)
def sense_into(x, vx, ay, gain, n_delay, frac, hist, offset, noise, counters, held, q, q_first, gps_step, true, out):
    """One log row of one sensor set (the module docstring's steps 1-5), the one implementation that
    :meth:`SensorModel.measure` and the vector environment (:mod:`ptw_env.vector`) call.

    ``x`` (8,) true state, ``vx`` [m/s], ``ay`` [m/s^2] model-frame lateral acceleration at ``t_k``;
    ``gain`` the ay_frame gravity gain; ``n_delay`` whole and ``frac`` fractional samples of sensor delay;
    ``hist`` (cap, 6) ring buffer of step-2 vectors; ``offset`` (7,) biases; ``noise`` (B, 7) the current
    block of scaled noise rows ((0, 7): noise-free), the caller refills it when ``counters[2] == B``;
    ``counters`` int64 ``[k, gps_index, j]``; ``held`` (1,) the GPS speed held; ``q`` encoder step [rad]
    (0: none); ``q_first`` quantise before adding noise; ``gps_step`` GPS periods per control period.
    Writes the true channels to ``true`` (7,) and the measured row to ``out`` (7,), CHANNELS order."""
    phi = x[PHI]
    true[0] = x[DELTA]
    true[1] = x[DELTA_DOT]
    true[2] = x[R]
    true[3] = x[PHI_DOT]
    true[4] = ay
    true[5] = phi
    true[6] = vx
    for i in range(6):
        out[i] = true[i]
    if gain != 0.0:  # effects.md, ay_frame
        out[4] = ay + gain * (ay * np.cos(phi) - G * np.sin(phi) - ay)
    k = counters[0]
    counters[0] = k + 1
    cap = hist.shape[0]
    if cap > 2 or frac != 0.0:  # effects.md, sensor_delay: y(t_k - delay_s)
        for i in range(6):
            hist[k % cap, i] = out[i]
        j = k - n_delay
        a = (j if j > 0 else 0) % cap
        if frac != 0.0:
            b = (j - 1 if j > 1 else 0) % cap
            for i in range(6):
                out[i] = hist[a, i] + frac * (hist[b, i] - hist[a, i])
        else:
            for i in range(6):
                out[i] = hist[a, i]
    for i in range(6):
        out[i] += offset[i]
    has_noise = noise.shape[0] > 0
    jn = counters[2]
    # GPS speed: refreshed when a new GPS period starts, held otherwise
    m = k if gps_step >= 1.0 else int(np.floor(k * gps_step + 1e-9))
    if m != counters[1]:
        counters[1] = m
        held[0] = vx + offset[6] + (noise[jn, 6] if has_noise else 0.0)
    if has_noise:
        if q > 0.0 and q_first:
            out[0] = q * np.rint(out[0] / q) + 0.0  # + 0.0: no -0.0
        for i in range(6):
            out[i] += noise[jn, i]
        if q > 0.0 and not q_first:
            out[0] = q * np.rint(out[0] / q) + 0.0  # + 0.0: no -0.0
        counters[2] = jn + 1
    elif q > 0.0:
        out[0] = q * np.rint(out[0] / q) + 0.0  # + 0.0: no -0.0
    out[6] = held[0]


def draw_noise(rng: np.random.Generator, std: np.ndarray, out: np.ndarray) -> None:
    """A new block of noise rows into ``out`` (B, 7): ``rng.standard_normal(out.shape) * std`` [channel units];
    zeros, drawing nothing, when every ``std`` is 0 (a noise-free sensor set uses no random numbers)."""
    if np.any(std > 0.0):
        out[:] = rng.standard_normal(out.shape) * std
    else:
        out[:] = 0.0


def sensor_terms(config: SensorConfig, effects: Effects, n: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(offset, std, gravity_gain)`` of :func:`sense_into` for a sensor configuration and sensor effects:
    ``offset_c = bias_c (+ gyro_bias on the two gyros)``, ``std_c = noise_std_c``, the ay_frame gain, CHANNELS
    order. With ``n``, the effects may hold arrays of ``n`` values (one sensor set each) and the results have
    a leading axis ``n``; without, they must be scalars."""
    shape = () if n is None else (n,)

    def value(cause: str, param: str) -> np.ndarray:
        v = np.asarray(effects.value(cause, param), dtype=float)
        if n is None and v.ndim:
            raise SensorConfigError(f"effect {cause}:{param} is array-valued (shape {v.shape}); a SensorModel "
                                    f"measures one vehicle")
        return np.broadcast_to(v, shape)

    offset = np.empty(shape + (len(CHANNELS),))
    for j, c in enumerate(CHANNELS):
        offset[..., j] = config.bias[c]
    offset[..., CHANNELS.index("yaw_rate")] += value("gyro_bias", "yaw_rate_bias")
    offset[..., CHANNELS.index("roll_rate")] += value("gyro_bias", "roll_rate_bias")
    std = np.empty(shape + (len(CHANNELS),))
    for j, c in enumerate(CHANNELS):
        std[..., j] = config.noise_std[c]
    return offset, std, value("ay_frame", "gravity_gain").copy()


class SensorModel:
    """Streaming sensor model of one instrumented scooter (see the module docstring).

    Parameters
    ----------
    config : SensorConfig
        Noise, bias, encoder step and GPS rate.
    effects : Effects, optional
        Only its sensor effects are used (``gyro_bias``, ``ay_frame``,
        ``sensor_delay``); dynamic effects belong to the plant and are ignored.
    dt : float
        Control period [s] between two calls of :meth:`measure`.

    Examples
    --------
    >>> import numpy as np
    >>> x = np.array([0.1, 0.01, 0.0, 0.25, 0.0, 0.0, 0.0, 0.0])
    >>> sm = SensorModel(SensorConfig.noiseless(), Effects({"gyro_bias": {"yaw_rate_bias": 0.25}}))
    >>> sm.reset(np.random.default_rng(0))
    >>> sm.measure(x, vx=15.0, ay=3.0).tolist()
    [0.01, 0.0, 0.5, 0.0, 3.0, 0.1, 15.0]
    >>> noisy = SensorModel(SensorConfig(), dt=0.01)
    >>> noisy.reset(np.random.default_rng(0))
    >>> np.round(noisy.measure(x, vx=15.0, ay=3.0), 2).tolist()
    [0.01, -0.0, 0.25, 0.0, 2.95, 0.1, 15.07]
    """

    __slots__ = (
        "config", "effects", "dt", "delay_s", "gravity_gain",
        "n_delay", "frac_delay", "hist_len", "offset", "std", "quantum", "quantise_first", "gps_step",
        "_rng", "_noise", "_hist", "_counters", "_held", "_true", "_measured",
    )  # fmt: skip

    def __init__(self, config: SensorConfig | None = None, effects: Effects | None = None, dt: float = 0.01) -> None:
        if config is None:
            config = SensorConfig()
        if not isinstance(config, SensorConfig):
            raise SensorConfigError(f"config must be a SensorConfig, got {type(config).__name__}")
        try:
            eff = as_effects(effects).sensor
        except EffectError as e:
            raise SensorConfigError(f"effects: {e}") from None
        try:
            dtf = float(dt)
        except (TypeError, ValueError):
            raise SensorConfigError(f"dt must be a number of seconds, got {dt!r}") from None
        if not (math.isfinite(dtf) and dtf > 0.0):
            raise SensorConfigError(f"dt must be a finite period > 0 s, got {dt!r}")
        self.config = config
        self.effects = eff
        self.dt = dtf
        offset, std, gain = sensor_terms(config, eff)
        self.gravity_gain = float(gain)
        self.delay_s = _scalar_effect(eff, "sensor_delay", "delay_s")
        d = self.delay_s / dtf
        if abs(d - round(d)) < _DELAY_SNAP:
            d = float(round(d))
        #: whole samples of delay, and the fractional part (weight of the older sample)
        self.n_delay = int(math.floor(d))
        self.frac_delay = d - self.n_delay
        #: length of the ring buffer of step-2 vectors (:func:`sense_into`)
        self.hist_len = self.n_delay + 2
        #: per-channel offsets (bias and gyro_bias), CHANNELS order
        self.offset = offset
        #: per-channel noise standard deviations, CHANNELS order
        self.std = std
        #: encoder step [rad], 0 for none
        self.quantum = 0.0 if config.delta_quantum is None else float(config.delta_quantum)
        self.quantise_first = not config.noise_before_quantisation
        #: GPS periods per control period
        self.gps_step = dtf * config.gps_rate_hz
        self._rng: np.random.Generator | None = None
        self._measured = False

    @property
    def delay_samples(self) -> float:
        """``delay_s / dt``: the sensor delay in control periods."""
        return self.n_delay + self.frac_delay

    @property
    def noisy(self) -> bool:
        """True when some channel has noise (the model then draws from its generator)."""
        return bool(np.any(self.std > 0.0))

    @property
    def true_channels(self) -> np.ndarray | None:
        """The 7 channels of the last :meth:`measure` call before any sensor effect,
        bias, noise or quantisation (the exact values at ``t_k``; ``ay`` in the
        model frame; ``vx`` the true speed). ``None`` before the first call."""
        return self._true.copy() if self._measured else None

    def reset(self, rng: np.random.Generator | int) -> None:
        """Start a new recording: clear the delay history and the GPS hold.

        Parameters
        ----------
        rng : numpy.random.Generator or int
            The only source of randomness of the noise (an ``int`` is a seed
            for ``np.random.default_rng``). Noise is drawn from it in blocks of
            512 samples, so the same generator state gives the same readings
            (``standard_normal`` fills an array in order, so any block length
            gives the same readings as long as nothing else draws in between).
        """
        if isinstance(rng, (int, np.integer)) and not isinstance(rng, bool):
            rng = np.random.default_rng(int(rng))
        if not isinstance(rng, np.random.Generator):
            raise SensorConfigError(f"reset needs a numpy Generator or an integer seed, got {rng!r}")
        self._rng = rng
        self._hist = np.zeros((self.hist_len, 6))
        self._noise = np.zeros((NOISE_BLOCK if self.noisy else 0, len(CHANNELS)))
        self._counters = np.array([0, -1, NOISE_BLOCK], dtype=np.int64)  # k, GPS index, noise row
        self._held = np.full(1, math.nan)
        self._true = np.zeros(len(CHANNELS))
        self._measured = False

    def measure(self, x: np.ndarray, vx: float, ay: float) -> np.ndarray:
        """One log row: the 7 channels (:data:`CHANNELS` order) at the sample instant ``t_k``.

        Parameters
        ----------
        x : ndarray, shape (8,)
            True state at ``t_k`` (model.md order).
        vx : float
            True forward speed [m/s] at ``t_k``.
        ay : float
            True model-frame lateral acceleration [m/s^2] at ``t_k``,
            ``plant.ay(x)`` (the caller's plant knows the payload mass).

        Returns
        -------
        ndarray, shape (7,)
            ``[delta, delta_rate, yaw_rate, roll_rate, ay, roll, vx]`` as measured.
        """
        if self._rng is None:
            raise SensorResetError("SensorModel.measure called before reset(rng)")
        if len(x) != 8:
            raise SensorConfigError(f"measure: x must be the 8 states of model.md, got {len(x)} values")
        noise = self._noise
        if noise.shape[0] and self._counters[2] >= noise.shape[0]:
            draw_noise(self._rng, self.std, noise)
            self._counters[2] = 0
        out = np.empty(len(CHANNELS))
        sense_into(np.asarray(x, dtype=float), float(vx), float(ay), self.gravity_gain, self.n_delay,
                   self.frac_delay, self._hist, self.offset, noise, self._counters, self._held, self.quantum,
                   self.quantise_first, self.gps_step, self._true, out)
        self._measured = True
        return out

    def measure_series(self, x: np.ndarray, vx: np.ndarray, ay: np.ndarray) -> np.ndarray:
        """:meth:`measure` over a trajectory (continuing the current stream).

        ``x`` has shape (T, 8); ``vx`` and ``ay`` shape (T,) or scalars.
        Returns shape (T, 7).
        """
        x = np.asarray(x, dtype=float)
        if x.ndim != 2 or x.shape[1] != 8:
            raise SensorConfigError(f"measure_series: x must have shape (T, 8), got {x.shape}")
        T = x.shape[0]
        try:
            vx = np.broadcast_to(np.asarray(vx, dtype=float), (T,))
            ay = np.broadcast_to(np.asarray(ay, dtype=float), (T,))
        except ValueError:
            raise SensorConfigError(
                f"measure_series: vx and ay must be scalars or have shape ({T},), got {np.shape(vx)} and {np.shape(ay)}"
            ) from None
        out = np.empty((T, len(CHANNELS)))
        for i in range(T):
            out[i] = self.measure(x[i], vx[i], ay[i])
        return out
