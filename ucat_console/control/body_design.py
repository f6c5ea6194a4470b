"""The designed body layer's gains: from the hull's linearised dynamics and the fins' delay.

Each axis the body layer holds is, linearised about rest, a mass on a damper driven by the
fins' force through a delay::

    heave:    M_z  z''   + D_z z'   = Z          (M_z = m - Z_wdot, D_z = -Z_w)
    yaw:      J_z  psi'' + D_r psi' = N          (J_z = I_zz - N_rdot, D_r = -N_r)
    surge:    M_x  u'    + D_x u    = X          (M_x = m - X_udot, D_x = -X_u - 2 X_uu u0)

The delay ``tau`` is the fins': a new force target enters at the next cycle a planner
makes, and that cycle's force acts over its duration, so a change reaches the hull about
one cycle later. The shipped gains are designed for 1.25 s (``control.params.DESIGN_DELAY``):
the MPC's cycles last 1.1-1.2 s (median) at 0.2 m/s, 1.7-1.9 s at 0.1 m/s, the baseline's
0.5 s (``bench tracking``); a loop designed for the longer delay stays stable with the
shorter one, while one designed for the baseline's delay rings with the MPC's.

Each loop is designed for the closed-loop bandwidth ``w_b = 1 / (k tau)`` (``k`` = 4 by
default, ``control.params.DESIGN_FACTOR``): at ``w_b`` the delay costs ``1/k`` rad (14
degrees) of phase, so the delay does not make the loop ring or limit-cycle. The heading
loop is faster, ``k`` = :data:`HEADING_FACTOR` (1.7: 0.47 rad/s, 34 degrees of the delay's
phase): the fins' cycles make yaw moments the body layer does not model (each stroke of the
simulated fin pushes across its cycle's direction in turn, uneven or open cycles turn their
force by up to 20 degrees, and fins of a pair running cycles of different lengths make
different true forces for the same modelled one), and only the loop's stiffness holds them:
at 0.2 rad/s they turned the robot 5-8 degrees going straight under the paper's MPC, at 0.35
rad/s up to 3.2 going straight and 7.0 at 0.3 m/s (the worst of 20 seeds, ``bench
tracking``); at 0.47 rad/s 2.6 and 3.3. Measured from 2.3 down to 1.6 (``docs/control.md``),
each step faster held the MPC modes' worst cases closer and none rang: a 0.25 N m push of 2 s
at 0.2 m/s turns the robot 6.4-6.7 degrees at 0.47 rad/s (7.8-8.4 at 0.35) and it is back
within 2.1 degrees 40 s on.

* Position loops (depth, heading), ``u = kp e - kd x' + ki int e``: when the hull damps the
  axis enough by itself (``D >= 2 M w_b``: heave) the loop is proportional, with the slower
  closed-loop pole at ``w_b``: ``kp = D w_b - M w_b^2`` (no overshoot, the faster pole
  beyond it); otherwise (yaw) it is a critically damped PD with both poles at ``w_b``:
  ``kp = M w_b^2``, ``kd = 2 M w_b - D``. The heading loop's damping is on the gyro's rate
  (``kd (r_ref - r)``), not on a differentiated heading.
* The velocity loop, ``X = X_ff(u_ref) + kp e + ki int e``, is a PI whose closed loop with the
  first-order surge has a double pole at ``w_b``: ``kp = 2 M w_b - D``, ``ki = M w_b^2``;
  the feed-forward ``X_ff`` is the hull's drag at the setpoint, so the integral only takes
  the model's error.
* The velocity loop closes on the DVL speed low-passed (first order) with its corner at
  five times the bandwidth (``speed_filter``: 1.0 s with the defaults; 11 degrees of phase at
  ``w_b``). Each fin samples its force target once a cycle, at its own time; without the
  low-pass the DVL's noise (5 mm/s at 8 Hz, about 0.08 N of surge demand through kp) reaches
  the four fins as four different samples and, on a fin controller with long cycles, turns
  the robot (going straight under the paper's MPC the heading wandered up to 8 degrees).
* The position loops' integrals (buoyancy, trim, a steady moment) have their zero at
  ``w_b / 8``: ``ki = kp w_b / 8`` (closer to the bandwidth, the integral winds up while a
  push holds the robot off and overshoots on its way back); the depth loop's at ``3 w_b / 8``
  (:data:`DEPTH_INTEGRAL_ZERO`): at speed the fins leave a steady heave force the model does
  not predict (the stream's lift on a plate turned for heave), which the slower integral
  took a minute to find (3-7 cm off 45 s after a 1 m step; 2-5 cm at 3/8, overshoot under
  5 %; at 6/8 the MPC's depth overshoots 5-7 %).

The fins' cycles are not always 1.25 s: the MPC's run up to 3 s at 0.1 m/s, a slow baseline
gait (0.5 Hz) 2 s, and loops designed for 1.25 s then get their fins' force later than they
were designed for. The body layer can therefore schedule its loops on the period of the
cycles the fins actually execute (``BodyConfig.schedule``, off by default: measured, it
steadies slow gaits but costs the MPC modes heading; ``docs/control.md``): each fin's time
from one cycle's first stroke to the next's, bounded (``schedule_min_delay``,
``schedule_max_delay``), is followed by the delay ``tau`` low-passed, a longer one within
seconds (``schedule_rise``), a shorter one slowly (``schedule_filter``), so that the loops
are designed for the longest of the fins' recent cycles and their gains move smoothly;
before any cycle is known ``tau`` is the longest (a loop designed for a longer delay stays
stable with a shorter one). Each loop's
configured gains are scaled by :func:`gain_schedule` (the gains designed for ``tau`` over
those designed for the shipped 1.25 s); with the shortest delay at the design delay (the
default), cycles of 1.25 s or shorter run the configured gains. Moving what the proportional
and damping terms lose into the integral at each change (bumpless transfer) was measured
worse: the slow integral then holds that push for tens of seconds, a heading offset of up
to 14 degrees at 0.1 m/s. The speed low-pass is not scheduled: following the bandwidth
(1.6 s at 2 s cycles) it put a 0.5 Hz baseline's speed within its band 82 % of the time at
0.1 m/s, against 95 % with the 1-s low-pass.

With the defaults (eeUVsim's hull, 1.25 s, k = 4: ``w_b`` = 0.2 rad/s; the heading's 0.47
rad/s) the depth loop is kp 5.16 N/m, ki 0.387 N/(m s); the heading loop kp 0.666 N m/rad,
kd 2.52 N m s/rad, ki 0.039 N m/(rad s); the velocity loop kp 17.1 N s/m, ki 2.48 N/m
(:func:`designed_gains`; ``docs/control.md`` works them through).
"""

from __future__ import annotations

from dataclasses import dataclass

from ucat_console.robot import hull as H
from ucat_console.typedconf import Config, param


@dataclass(frozen=True)
class HullModel(Config):
    """The controller's model of the hull (positive masses and damping; from the robot's
    description, ``robot/hull.py``, unless identified or configured otherwise)."""

    surge_mass: float = param(H.MASS - H.X_UDOT, lo=0.0, hi=1000.0, lo_open=True, unit="kg",
                              doc="mass with added mass in surge, m - X_udot")
    heave_mass: float = param(H.MASS - H.Z_WDOT, lo=0.0, hi=1000.0, lo_open=True, unit="kg",
                              doc="mass with added mass in heave, m - Z_wdot")
    yaw_inertia: float = param(H.IZZ - H.N_RDOT, lo=0.0, hi=100.0, lo_open=True, unit="kg m2",
                               doc="yaw inertia with added inertia, I_zz - N_rdot")
    surge_damping: float = param(-H.X_U, lo=0.0, hi=1000.0, unit="N s/m", doc="linear surge damping -X_u")
    surge_damping_quad: float = param(-H.X_UU, lo=0.0, hi=1000.0, unit="N s2/m2",
                                      doc="quadratic surge damping -X_uu")
    heave_damping: float = param(-H.Z_W, lo=0.0, hi=1000.0, unit="N s/m", doc="linear heave damping -Z_w")
    heave_damping_quad: float = param(-H.Z_WW, lo=0.0, hi=1000.0, unit="N s2/m2",
                                      doc="quadratic heave damping -Z_ww")
    yaw_damping: float = param(-H.N_R, lo=0.0, hi=100.0, unit="N m s", doc="linear yaw damping -N_r")
    yaw_damping_quad: float = param(-H.N_RR, lo=0.0, hi=100.0, unit="N m s2", doc="quadratic yaw damping -N_rr")

    def surge_drag(self, u: float) -> float:
        """The hull's drag at forward speed ``u`` (N, against the motion)."""
        return self.surge_damping * u + self.surge_damping_quad * u * abs(u)

    def heave_drag(self, w: float) -> float:
        """The hull's drag at heave rate ``w`` (N, against the motion)."""
        return self.heave_damping * w + self.heave_damping_quad * w * abs(w)

    def yaw_drag(self, r: float) -> float:
        """The hull's yaw damping moment at yaw rate ``r`` (N m, against the turn)."""
        return self.yaw_damping * r + self.yaw_damping_quad * r * abs(r)


#: the speed low-pass's corner as a multiple of the bandwidth
SPEED_FILTER_CORNER = 5.0
#: the speed the surge is linearised about (m/s): the middle of the paper's 0.1-0.4 m/s
DESIGN_SPEED = 0.2
#: the position loops' integral zero, as a fraction of the bandwidth; the depth loop's
INTEGRAL_ZERO = 1.0 / 8.0
DEPTH_INTEGRAL_ZERO = 3.0 / 8.0
#: the heading loop's bandwidth factor (the others': the caller's)
HEADING_FACTOR = 1.7


@dataclass(frozen=True)
class AxisGains:
    kp: float
    ki: float
    kd: float


def position_gains(mass: float, damping: float, bandwidth: float,
                   integral_zero: float = INTEGRAL_ZERO) -> AxisGains:
    """Gains of a position loop on ``mass x'' + damping x' = u`` (module docstring), its
    integral's zero at ``integral_zero`` times the bandwidth."""
    w = bandwidth
    if damping >= 2.0 * mass * w:
        kp, kd = damping * w - mass * w * w, 0.0
    else:
        kp, kd = mass * w * w, 2.0 * mass * w - damping
    return AxisGains(kp=kp, ki=kp * w * integral_zero, kd=kd)


def velocity_gains(mass: float, damping: float, bandwidth: float) -> AxisGains:
    """PI gains of a velocity loop on ``mass u' + damping u = X``: a double pole at the
    bandwidth (module docstring)."""
    w = bandwidth
    return AxisGains(kp=max(0.0, 2.0 * mass * w - damping), ki=mass * w * w, kd=0.0)


def speed_filter(delay: float, factor: float) -> float:
    """The speed low-pass's time constant (s) for an actuation ``delay`` and bandwidth
    ``factor`` (module docstring): its corner at SPEED_FILTER_CORNER times the bandwidth."""
    return factor * delay / SPEED_FILTER_CORNER


def gain_schedule(hull: HullModel, delay: float, design_delay: float, factor: float) -> dict[str, AxisGains]:
    """Each loop's gains designed for an actuation ``delay`` as multiples of those designed
    for ``design_delay`` (a gain designed 0 at ``design_delay`` keeps its multiple 1): how
    the body layer scales its configured gains when the fins' cycles run longer than the
    delay they were designed for (``BodyConfig.schedule``)."""
    now, ref = designed_gains(hull, delay, factor), designed_gains(hull, design_delay, factor)

    def ratio(a: float, b: float) -> float:
        return a / b if b > 0.0 else 1.0

    return {k: AxisGains(kp=ratio(now[k].kp, g.kp), ki=ratio(now[k].ki, g.ki), kd=ratio(now[k].kd, g.kd))
            for k, g in ref.items()}


def designed_gains(hull: HullModel, delay: float, factor: float) -> dict[str, AxisGains]:
    """The three loops' gains ("velocity", "depth", "heading") for an actuation ``delay``
    (s) and bandwidth ``factor`` k, the heading loop's at :data:`HEADING_FACTOR` (module
    docstring)."""
    if not delay > 0.0 or not factor > 0.0:
        raise ValueError(f"delay, factor: expected > 0, got {delay!r}, {factor!r}")
    w = 1.0 / (factor * delay)
    surge_d = hull.surge_damping + 2.0 * hull.surge_damping_quad * DESIGN_SPEED
    return {
        "velocity": velocity_gains(hull.surge_mass, surge_d, w),
        "depth": position_gains(hull.heave_mass, hull.heave_damping, w, DEPTH_INTEGRAL_ZERO),
        "heading": position_gains(hull.yaw_inertia, hull.yaw_damping, 1.0 / (HEADING_FACTOR * delay)),
    }
