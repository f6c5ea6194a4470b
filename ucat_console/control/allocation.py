"""Fin force allocation: the body demand split into each fin's force target.

Two allocations, one per body layer (``BodyConfig.layer``, control.md section 7):

* the paper's (section IV.B): F_x*, F_y* and a yaw thrust differential, in the fin model's
  terms, heave and yaw on the front pair, no limits (:func:`fin_targets`, :func:`allocate`);
* the designed layer's (:func:`allocate_wrench`): a physical body wrench (surge force X,
  heave force Z, yaw moment N) onto the four fins, each fin's deliverable force as its
  limit, a priority between the axes, and what was cut reported.

Fin indexing is the paper's: fins 0 and 1 are the front pair, 2 and 3 the rear pair;
0 and 2 are on the starboard side, 1 and 3 on the port side (``robot.fins.PAPER_SIDES``). The plant
and the drivers use the robot's order (``robot.fins``, which holds the one map between them).

Sign conventions. Forces are those of the fin model (control.md section 1): forward thrust
is ``f_x < 0``; ``f_y`` is the force in the fin's working plane perpendicular to x (vertical
on U-CAT), ``f_y > 0`` lifts. Body frame x forward, y starboard, z down, so a positive yaw
rate is clockwise seen from above (a turn to starboard). A fin's model force ``(f_x, f_y)``
acts on the hull as ``(-f_x cos(alpha), s_y f_x sin(alpha), -f_y)`` with a yaw moment
``s_lat arm_yaw f_x`` (``robot.geometry``).

The paper's allocation. ``f_x,i = F_x*/4`` for every fin, plus the yaw differential ``m``
on the front pair: ``f_x,0 += m/2`` (starboard), ``f_x,1 -= m/2`` (port), a clockwise yaw
moment ``arm m`` for m > 0; ``f_y,0 = f_y,1 = F_y*/2``, rear ``f_y = 0``.

The designed allocation. The body wrench is physical; so are the fins' forces until the
last step:

1. heave: ``f_y,i = -Z h_i``, the share ``h`` of the front fins ``(1 - r)/2`` and of the rear
   ``r/2`` (``BodyConfig.heave_rear_share`` r; 0.5: all alike, no pitch moment). When a fin
   would need more than its deliverable force F, Z is cut to fit (*heave cut*);
2. yaw: each yaw fin adds ``s_lat sgn(N) y`` to its forward force, ``y = |N| / (n arm)``
   over the n yaw fins (all four, no sway force; the front pair in sync mode, where the rear
   fins run one plan, or when ``yaw_on_rear`` is off). A fin's force must stay within F:
   with its heave share taken, its x-force lies in ``[-g c_i, c_i]``, ``c_i = sqrt(F^2 -
   f_y,i^2)``, where forward force counts ``g`` times (``BodyConfig.thrust_gain``: the fins
   push forward g times harder than the model says). y is cut to the largest for which a
   common surge force exists (*yaw cut*);
3. surge: every fin adds ``a = -X / (4 cos(alpha))``, clipped to what the fins have left
   (*surge cut*). Braking: the fins never push against the direction of travel the
   velocity setpoint asks for: to slow down, the thrust drops and the hull's drag brakes
   (*coasting*; turning the fins round to push backwards means swinging the stroke centres
   through about 3 rad at the force the model gives backwards, 1/g of the forward one, while
   the hull's drag brakes with 6.5 N per m/s). A negative setpoint (reverse) mirrors this.
4. The fins' physical x-forces become the fin model's: forward ones divided by g.

Priority: heave, then yaw, then surge: depth is safety (the surface, the bottom), heading
keeps the robot on its line, and speed is the cheapest to give up. What was cut is a bit
set (``CUT_*``) the body layer feeds back to its loops (anti-windup) and onto the
telemetry.

Sync mode: the rear pair is one logical actuator; the allocation then returns three
logical targets (front starboard, front port, rear pair) and the logical -> physical map.
A logical target is the force *each* of its physical fins must produce.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from math import isfinite

import numpy as np
from numba.extending import register_jitable

from ucat_console.control.argcheck import finite, in_range
from ucat_console.robot.fins import N_FINS, PAPER_SIDES

FRONT_STARBOARD, FRONT_PORT, REAR_STARBOARD, REAR_PORT = 0, 1, 2, 3

#: logical -> physical fins
INDEPENDENT_FINS: tuple[tuple[int, ...], ...] = ((0,), (1,), (2,), (3,))
SYNC_FINS: tuple[tuple[int, ...], ...] = (
    (FRONT_STARBOARD,),
    (FRONT_PORT,),
    (REAR_STARBOARD, REAR_PORT),
)

#: what the designed allocation cut (bits)
CUT_HEAVE, CUT_YAW, CUT_SURGE, CUT_COAST = 1, 2, 4, 8
#: the names of the cut bits, as the telemetry lists them
CUT_NAMES = ((CUT_HEAVE, "heave"), (CUT_YAW, "yaw"), (CUT_SURGE, "surge"), (CUT_COAST, "coast"))

# the designed allocation's parameters (one array; layout A_*)
A_FMAX = 0  # a fin's deliverable force by the fin model (N)
A_GAIN = 1  # thrust gain g
A_COS = 2  # cos of the fins' mounting angle
A_ARM = 3  # yaw moment arm (m)
A_REAR = 4  # the rear pair's share of the heave
A_YAW_REAR = 5  # 1.0: the rear pair makes yaw moment too
NA = 6
# what it writes (one array; layout W_*): each paper fin's model target (f_x, f_y), then
# the applied wrench
W_TARGETS = 0
W_X, W_Z, W_N = 8, 9, 10
NW = 11


@dataclass(frozen=True)
class Allocation:
    """Per-logical-actuator force targets ``(f_x, f_y)`` (N) and the physical fins of each."""

    targets: tuple[tuple[float, float], ...]
    fins: tuple[tuple[int, ...], ...]

    @property
    def sync(self) -> bool:
        return len(self.targets) < N_FINS

    def per_fin(self) -> tuple[tuple[float, float], ...]:
        """The target of every physical fin, in paper order 0..3."""
        out: list[tuple[float, float]] = [(0.0, 0.0)] * N_FINS
        for target, fins in zip(self.targets, self.fins):
            for i in fins:
                out[i] = target
        return tuple(out)


@register_jitable
def fin_targets(fx: float, fy: float, m: float) -> tuple[float, float, float, float, float, float]:
    """The paper's allocation (section IV.B): (f_x, f_y) of the front starboard fin, the
    front port fin and each rear fin, for F_x* ``fx``, F_y* ``fy`` and the yaw
    differential ``m`` (see the module docstring). The one definition: :func:`allocate`
    runs it as Python, the closed loop's compiled core compiled."""
    axial = 0.25 * fx
    return axial + 0.5 * m, 0.5 * fy, axial - 0.5 * m, 0.5 * fy, axial, 0.0


def allocate(fx_body: float, fy_body: float, yaw: float, *, sync: bool = False) -> Allocation:
    """Split the body demand into fin targets by the paper's allocation.

    ``fx_body`` is F_x* (N, forward < 0), ``fy_body`` is F_y* (N), ``yaw`` the front-pair
    thrust differential (N, > 0 turns to starboard). See the module docstring for signs.
    """
    fx, fy, m = float(fx_body), float(fy_body), float(yaw)
    if not (isfinite(fx) and isfinite(fy) and isfinite(m)):
        finite("fx_body", fx)
        finite("fy_body", fy)
        finite("yaw", m)
    sx, sy, px, py, rx, ry = fin_targets(fx, fy, m)
    return _logical(((sx, sy), (px, py), (rx, ry), (rx, ry)), sync)


def _logical(per_fin: tuple[tuple[float, float], ...], sync: bool) -> Allocation:
    if sync:
        return Allocation(targets=per_fin[:3], fins=SYNC_FINS)
    return Allocation(targets=per_fin, fins=INDEPENDENT_FINS)


@register_jitable
def allocate_wrench(x: float, z: float, n: float, direction: float, sync: bool, a: np.ndarray,
                    out: np.ndarray) -> int:
    """The designed allocation (module docstring) of surge force ``x`` (N, forward > 0),
    heave force ``z`` (N, down > 0) and yaw moment ``n`` (N m, clockwise from above > 0):
    each paper fin's model target and the wrench applied into ``out`` (layout ``W_*``), the
    cut bits returned. ``direction``: the velocity setpoint's sign (> 0 forward, < 0 reverse, 0
    at rest); ``a``: the parameters (layout ``A_*``)."""
    fmax, g, cos_a, arm = a[A_FMAX], a[A_GAIN], a[A_COS], a[A_ARM]
    rear = a[A_REAR]
    cut = 0
    # 1. heave
    h_front, h_rear = 0.5 * (1.0 - rear), 0.5 * rear
    h_max = max(h_front, h_rear)
    if abs(z) * h_max > fmax:
        z = math.copysign(fmax / h_max, z)
        cut |= CUT_HEAVE
    fy_front, fy_rear = -z * h_front, -z * h_rear
    c_front = math.sqrt(max(0.0, fmax * fmax - fy_front * fy_front))
    c_rear = math.sqrt(max(0.0, fmax * fmax - fy_rear * fy_rear))
    # 2. yaw: sigma_i in {-1, 0, 1} per fin, y >= 0 the per-fin share
    yaw_rear = a[A_YAW_REAR] > 0.5 and not sync
    n_yaw = 4 if yaw_rear else 2
    sign_n = 1.0 if n >= 0.0 else -1.0
    y = abs(n) / (n_yaw * arm)
    sig0 = PAPER_SIDES[0] * sign_n
    sig1 = PAPER_SIDES[1] * sign_n
    sig2 = PAPER_SIDES[2] * sign_n if yaw_rear else 0.0
    sig3 = PAPER_SIDES[3] * sign_n if yaw_rear else 0.0
    sig = (sig0, sig1, sig2, sig3)
    cap = (c_front, c_front, c_rear, c_rear)
    # each fin's physical x-force lies in [-g cap, cap]; under way, never against the travel
    k_fwd = 0.0 if direction < 0.0 else g
    k_back = 0.0 if direction > 0.0 else 1.0
    y_max = math.inf
    for i in range(4):
        for j in range(4):
            ds = sig[j] - sig[i]
            if ds > 0.0:
                y_max = min(y_max, (k_back * cap[j] + k_fwd * cap[i]) / ds)
    if y > y_max:
        y = y_max
        cut |= CUT_YAW
    # 3. surge: the common per-fin share, within what every fin has left
    lo, hi = -math.inf, math.inf
    for i in range(4):
        lo = max(lo, -k_fwd * cap[i] - sig[i] * y)
        hi = min(hi, k_back * cap[i] - sig[i] * y)
    share = -x / (4.0 * cos_a)
    if (direction >= 0.0 and share > 0.0) or (direction < 0.0 and share < 0.0):
        share = 0.0
        cut |= CUT_COAST
    clipped = min(hi, max(lo, share))
    if clipped != share:
        cut |= CUT_SURGE
    # 4. the fin model's targets
    for i in range(4):
        fx = clipped + sig[i] * y
        if fx < 0.0:
            fx /= g
        out[W_TARGETS + 2 * i] = fx
        out[W_TARGETS + 2 * i + 1] = fy_front if i < 2 else fy_rear
    out[W_X] = -4.0 * cos_a * clipped
    out[W_Z] = z
    out[W_N] = sign_n * y * n_yaw * arm
    return cut


def wrench_params(fmax: float, thrust_gain: float, mounting_angle_deg: float, arm_yaw: float,
                  heave_rear_share: float, yaw_on_rear: bool) -> np.ndarray:
    """The designed allocation's parameter array (layout ``A_*``)."""
    a = np.zeros(NA)
    a[A_FMAX], a[A_GAIN] = fmax, thrust_gain
    a[A_COS], a[A_ARM] = math.cos(math.radians(mounting_angle_deg)), arm_yaw
    a[A_REAR], a[A_YAW_REAR] = heave_rear_share, 1.0 if yaw_on_rear else 0.0
    return a


@dataclass(frozen=True)
class WrenchAllocation:
    """What :func:`allocate_wrench` made of a body wrench: the fins' targets, the wrench
    applied (surge N, heave N, yaw N m) and the axes cut (names of ``CUT_NAMES``)."""

    allocation: Allocation
    applied: tuple[float, float, float]
    cut: tuple[str, ...]


def cut_names(bits: int) -> tuple[str, ...]:
    return tuple(name for bit, name in CUT_NAMES if bits & bit)


def allocate_body_wrench(x: float, z: float, n: float, params: np.ndarray, *, direction: float = 0.0,
                         sync: bool = False) -> WrenchAllocation:
    """:func:`allocate_wrench` as Python: surge ``x`` (N), heave ``z`` (N, down > 0) and yaw
    moment ``n`` (N m) into the fins' targets."""
    for name, v in (("x", x), ("z", z), ("n", n)):
        finite(name, v)
    out = np.zeros(NW)
    bits = allocate_wrench(float(x), float(z), float(n), float(direction), bool(sync), params, out)
    per_fin = tuple((float(out[2 * i]), float(out[2 * i + 1])) for i in range(N_FINS))
    return WrenchAllocation(_logical(per_fin, sync), (float(out[W_X]), float(out[W_Z]), float(out[W_N])),
                            cut_names(bits))


#: the widest envelope: no configuration allows setpoints beyond these (m/s, m, rad/s)
MAX_VELOCITY, MAX_DEPTH, MAX_YAW_RATE = 5.0, 1000.0, 10.0


@dataclass(frozen=True)
class BodySetpoints:
    """Setpoints: forward velocity (m/s), depth (m, positive down), yaw rate (rad/s).

    Always inside the widest envelope; :meth:`within` checks a configured one (the one
    setpoint range check: the loop, the supervisor and the experiments all call it).
    """

    velocity: float = 0.0
    depth: float = 0.0
    yaw_rate: float = 0.0

    def __post_init__(self) -> None:
        self.within(MAX_VELOCITY, MAX_DEPTH, MAX_YAW_RATE)

    def within(self, max_velocity: float, max_depth: float, max_yaw_rate: float) -> BodySetpoints:
        """``self`` if |velocity| <= max_velocity, 0 <= depth <= max_depth and
        |yaw_rate| <= max_yaw_rate, else ValueError naming the value and the range."""
        in_range("velocity", self.velocity, -max_velocity, max_velocity, unit="m/s")
        in_range("depth", self.depth, 0.0, max_depth, unit="m")
        in_range("yaw_rate", self.yaw_rate, -max_yaw_rate, max_yaw_rate, unit="rad/s")
        return self
