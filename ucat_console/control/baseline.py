"""Baseline controller: the fixed-frequency inverse model of Remmas et al. (control.md section 6).

Each fin beats at the fixed frequency ``f`` (:class:`BaselineConfig`); the requested mean
force magnitude ``F`` sets the amplitude ``A`` (the half stroke), and the force direction
is set by moving the oscillation centre. The plan is written in the command format the
MPC uses, so the same execution module runs both controllers.

The amplitude (``BaselineConfig.inverse_model``):

* ``fin_model`` (the default): the controller's fin model inverted, with the strokes timed
  as the drives run them. A sinusoid of amplitude A at f sweeps 2A in half a period, a mean
  rate ``w = 4 A f``; a drive that accelerates at ``a`` cannot make a stroke of 2A faster
  than ``mean_rate_limit(2A)`` (``control.stroke_timing``), so ``w(A) = min(4 A f,
  mean_rate_limit(2A))`` (the beat slows below f where the drive cannot keep up). A
  symmetric stroke pair then makes (below) ``F(A) = q sqrt(C_L^2 + C_D^2) w(A)^2 cos(A)``,
  ``q = rho A_f r_c^2 / 2``, increasing up to its largest value; A is found by bisection,
  and a force beyond the largest gets the amplitude of the largest;
* ``eq19``: the paper's eq 19, ``theta_max = arccos(1 - F / (8 C_D rho A_f (r_c pi f)^2))``
  (argument clipped to [-1, 1], amplitude to ``d_max``). For small amplitudes eq 19's force
  is ``4 C_D rho A_f r_c^2 pi^2 f^2 A^2`` where the fin model's is ``8 rho A_f r_c^2 f^2 A^2
  sqrt(C_L^2 + C_D^2)``: eq 19 expects ``pi^2 C_D / (2 sqrt(C_L^2 + C_D^2))`` = 4.65 times
  the force (the paper's coefficients), so it asks for a stroke that makes 1/4.65 of the
  force the fin model says, in every direction (the plant's thrust gain of 4.6 makes up for
  it forwards only). It is kept for the experiments that reproduce the paper.

Angle convention (the fin model of control.md section 1, where forward thrust is f_x < 0).
A stroke pair about a centre ``c`` (strokes ``+2A`` and ``-2A`` at the same rate ``w``) has
both mid-stroke angles at ``c``; eq 5 gives fin-frame forces whose drag parts along x cancel,
so the cycle-mean body force is::

    f_bar = R(c) (-L cos A, -D cos A) = cos(A) * q w^2 * R(c) (-C_L, -C_D),   q = 0.5 rho A_f r_c^2

i.e. it points at ``c + zero_direction`` with ``zero_direction = atan2(-C_D, -C_L)``
(-1.914 rad, about -110 deg, with the paper's coefficients). The centre that makes the mean
force point along the request ``(f_x*, f_y*)`` is therefore::

    c = atan2(f_y*, f_x*) - atan2(-C_D, -C_L)        (wrapped to (-pi, pi])

(plus pi if the amplitude exceeds pi/2, where cos A changes sign). With the paper's
coefficients a pure forward request (-1, 0) N gives c = -1.228 rad, a pure f_y request
(0, 1) N gives c = -2.798 rad; the benchmark's targets (f_x <= 0, f_y >= 0) map to centres
in [-2.80, -1.23] rad with no wrap in between.

Rate: both strokes run at the mean rate ``w(A)`` above (``4 A f`` with eq 19), floored at
``MpcConfig.w_min`` so that a zero or tiny amplitude never commands a zero profile
velocity. The baseline does not clip ``w`` to ``w_max``: its fixed frequency is what
defines it, and its thrust saturates through the amplitude (which is why it cannot reach
0.4 m/s in the paper).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

from numba import njit
from numba.extending import register_jitable

from ucat_console.control.argcheck import finite, in_range
from ucat_console.control.params import BaselineConfig, ExecutorConfig, MpcConfig
from ucat_console.control.stroke_timing import mean_rate_limit


def wrap_angle(angle: float) -> float:
    """``angle`` wrapped to (-pi, pi]."""
    a = math.remainder(angle, 2.0 * math.pi)  # in [-pi, pi]
    return math.pi if a == -math.pi else a


def baseline_gain(cfg: MpcConfig, bcfg: BaselineConfig) -> float:
    """The force scale of eq 19, ``8 C_D rho A_f (r_c pi f)^2`` (N)."""
    if cfg.c_d <= 0.0:
        raise ValueError(
            f"c_d: {cfg.c_d!r} is out of range for the baseline; allowed: (0.0, 20.0]"
        )
    return 8.0 * cfg.c_d * cfg.rho * cfg.fin_area * (cfg.r_c * math.pi * bcfg.frequency) ** 2


def baseline_amplitude(force_magnitude: float, cfg: MpcConfig, bcfg: BaselineConfig) -> float:
    """Stroke amplitude theta_max (rad) for a mean force magnitude (N), eq 19.

    The arccos argument is clipped to [-1, 1] and the amplitude to ``cfg.d_max``.
    """
    f = in_range("force_magnitude", force_magnitude, 0.0, unit="N")
    arg = 1.0 - f / baseline_gain(cfg, bcfg)
    arg = min(1.0, max(-1.0, arg))
    return min(math.acos(arg), cfg.d_max)


@register_jitable
def model_rate(amplitude: float, frequency: float, acceleration: float, max_rate: float) -> float:
    """Mean rate (rad/s) of a beat of ``amplitude`` at ``frequency`` as the drive can make it:
    ``min(4 A f, mean_rate_limit(2 A))``."""
    return min(4.0 * amplitude * frequency, mean_rate_limit(2.0 * amplitude, acceleration, max_rate))


@register_jitable
def _beat_force(amplitude: float, q: float, frequency: float, acceleration: float, max_rate: float) -> float:
    w = model_rate(amplitude, frequency, acceleration, max_rate)
    return q * w * w * math.cos(amplitude)


@njit(cache=True)
def _beat_amplitude(force: float, peak: float, q: float, frequency: float, acceleration: float,
                    max_rate: float) -> float:
    """Bisection on ``(0, peak]`` for the smallest amplitude whose beat force reaches ``force``
    (``0 < force < F(peak)``); compiled: a plan runs it for every fin."""
    lo, hi = 0.0, peak  # F(lo) < force <= F(hi) throughout
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if mid == lo or mid == hi:  # no amplitude left between them: neither can move
            break
        if _beat_force(mid, q, frequency, acceleration, max_rate) < force:
            lo = mid
        else:
            hi = mid
    return hi


class FinModelInverse:
    """The fin model's beat force ``F(A)`` for one configuration and drive (module docstring),
    and its inverse: the smallest amplitude that makes a force. The configuration's constants
    are taken once; the peak of ``F`` is found once."""

    def __init__(self, cfg: MpcConfig, bcfg: BaselineConfig, acceleration: float, max_rate: float) -> None:
        self._q = 0.5 * cfg.rho * cfg.fin_area * cfg.r_c ** 2 * math.hypot(cfg.c_l, cfg.c_d)
        self._frequency = bcfg.frequency
        self._drive = (acceleration, max_rate)
        lo, hi = 0.0, min(cfg.d_max, 0.5 * math.pi)
        for _ in range(60):  # the force rises to one peak and falls: find the peak
            m1, m2 = lo + (hi - lo) / 3.0, hi - (hi - lo) / 3.0
            if self.force(m1) < self.force(m2):
                lo = m1
            else:
                hi = m2
        #: the amplitude of the largest beat force (rad)
        self.peak = 0.5 * (lo + hi)
        self._peak_force = self.force(self.peak)

    @property
    def peak_force(self) -> float:
        """The largest mean force (N) a beat at this frequency makes (at :attr:`peak`)."""
        return self._peak_force

    def force(self, amplitude: float) -> float:
        """The mean force (N) of a symmetric beat of ``amplitude`` (rad)."""
        return _beat_force(amplitude, self._q, self._frequency, *self._drive)

    def amplitude(self, force_magnitude: float) -> float:
        """The smallest amplitude (rad, at most the peak's) whose beat makes
        ``force_magnitude`` (N), or the peak's amplitude when none does."""
        f = in_range("force_magnitude", force_magnitude, 0.0, unit="N")
        if f == 0.0:
            return 0.0
        if self._peak_force <= f:
            return self.peak
        return _beat_amplitude(f, self.peak, self._q, self._frequency, *self._drive)


@functools.lru_cache(maxsize=64)
def fin_model_inverse(cfg: MpcConfig, bcfg: BaselineConfig, acceleration: float,
                      max_rate: float) -> FinModelInverse:
    """The :class:`FinModelInverse` of one configuration and drive (made once)."""
    return FinModelInverse(cfg, bcfg, acceleration, max_rate)


def zero_direction(cfg: MpcConfig) -> float:
    """Direction (rad, body frame) of a symmetric stroke pair's mean force about centre 0."""
    return math.atan2(-cfg.c_d, -cfg.c_l)


@dataclass(frozen=True)
class BaselinePlan:
    """One baseline cycle, in the MPC's command format.

    ``u = (d_1, d_2, w_1, w_2)`` are the strokes and rates, ``commands =
    (theta_1, w_1, theta_2, w_2)`` the absolute targets for the execution module;
    ``amplitude`` and ``centre`` (rad, centre in (-pi, pi]) are what the console shows.
    """

    target: tuple[float, float]
    amplitude: float
    centre: float
    frequency: float
    u: tuple[float, float, float, float]
    commands: tuple[float, float, float, float]


#: the most a fin's cycle is shortened or lengthened to beat in phase with the others (a share of it)
PHASE_STEP = 0.05


class BaselinePlanner:
    """Per-fin plans of the inverse-model baseline (stateless apart from its configuration).
    ``executor`` gives the drives' timing the fin-model inverse uses."""

    def __init__(self, cfg: MpcConfig, bcfg: BaselineConfig, executor: ExecutorConfig | None = None) -> None:
        baseline_gain(cfg, bcfg)  # rejects C_D = 0 here rather than at the first plan
        self.cfg = cfg
        self.bcfg = bcfg
        ex = executor or ExecutorConfig()
        self._drive = (ex.acceleration, ex.max_rate)
        self._inverse = fin_model_inverse(cfg, bcfg, ex.acceleration, ex.max_rate)

    def amplitude(self, force_magnitude: float) -> float:
        """The beat's amplitude (rad) for a mean force (N), by the configured inverse model."""
        if self.bcfg.inverse_model == "eq19":
            return baseline_amplitude(force_magnitude, self.cfg, self.bcfg)
        return self._inverse.amplitude(force_magnitude)

    def rate(self, amplitude: float) -> float:
        """Mean stroke rate (rad/s) of a beat of ``amplitude`` at the fixed frequency (as the
        drive can make it, with the fin-model inverse)."""
        a = in_range("amplitude", amplitude, 0.0, unit="rad")
        if self.bcfg.inverse_model == "eq19":
            w = 4.0 * a * self.bcfg.frequency
        else:
            w = model_rate(a, self.bcfg.frequency, *self._drive)
        return max(w, self.cfg.w_min)

    def centre(self, fx: float, fy: float, amplitude: float) -> float:
        """Oscillation centre (rad, (-pi, pi]) whose mean force points along (fx, fy)."""
        c = math.atan2(fy, fx) - zero_direction(self.cfg)
        if math.cos(amplitude) < 0.0:
            c += math.pi
        return wrap_angle(c)

    def plan(self, fx: float, fy: float, theta_now: float, lag: float = 0.0) -> BaselinePlan:
        """Cycle plan for the per-fin target (fx, fy) N, starting at the fin angle ``theta_now``.

        The first stroke goes to the extreme of the oscillation farther from ``theta_now``
        (``centre + A`` on a tie), the second to the other extreme, so that in steady state
        successive cycles join without a jump. A zero request holds the fin where it is.

        ``lag`` (s): how long after the other fins' beats this fin's last began (its last
        stroke towards larger angles; < 0: before them). A fin's cycles follow from its own
        last one, so nothing else holds the phase between the fins: an offset a transient
        leaves stays, and the simulated robot swam a gait with its two sides 0.14 of a cycle
        apart for 30 % more energy per metre than in phase. The cycle is therefore shortened
        by ``phase_gain * lag`` (lengthened for a lead), by at most :data:`PHASE_STEP` of its
        length, its strokes' rate scaled to match: a phase lock on the cycles' lengths. Each
        fin corrects a share of its own lag, and the correction acts a cycle later (the plan
        is made during the cycle before), so the offsets shrink for a gain up to 0.5. The
        shipped gain and step are small (0.1, a twentieth): a side beating faster pushes
        harder, and at 0.25 and a fifth the correction after a change from 2 to 0.5 Hz turned
        the robot up to 7.9 degrees (3.5 at 0.1 and a twentieth, 4.4 without the lock).
        """
        fx = finite("fx", fx)
        fy = finite("fy", fy)
        theta_now = finite("theta_now", theta_now)
        lag = finite("lag", lag)
        magnitude = math.hypot(fx, fy)
        amplitude = self.amplitude(magnitude)
        w = self.rate(amplitude)
        if magnitude == 0.0:
            centre = wrap_angle(theta_now)
            first, second = theta_now, theta_now
        else:
            centre = self.centre(fx, fy, amplitude)
            upper, lower = centre + amplitude, centre - amplitude
            if abs(lower - theta_now) > abs(upper - theta_now):
                first, second = lower, upper
            else:
                first, second = upper, lower
        d1 = first - theta_now
        d2 = second - first
        sweep = abs(d1) + abs(d2)
        if lag != 0.0 and sweep > 0.0 and self.bcfg.phase_gain > 0.0:
            duration = sweep / w
            step = min(PHASE_STEP * duration, max(-PHASE_STEP * duration, self.bcfg.phase_gain * lag))
            w = sweep / (duration - step)
        return BaselinePlan(
            target=(fx, fy),
            amplitude=amplitude,
            centre=centre,
            frequency=self.bcfg.frequency,
            u=(d1, d2, w, w),
            commands=(first, w, second, w),
        )
