"""Controller parameters: one frozen dataclass per block, defaults from control.md.

Every default below is the single definition of that value in the project. Names follow
the paper's symbols (``lam_st`` is lambda_St, ``w`` is omega).
"""

from __future__ import annotations

from dataclasses import dataclass

from ucat_console.control.body_design import HullModel, designed_gains, speed_filter
from ucat_console.robot.geometry import FIN_AREA, FIN_R_C
from ucat_console.robot.hull import FIN_INERTIA
from ucat_console.robot.servo import FIN_ACCELERATION, FIN_MAX_RATE
from ucat_console.robot.units import RHO_TABLE_I
from ucat_console.typedconf import Config, param, require_below

#: the actuation delay (s) and bandwidth factor the designed body layer's default gains are
#: designed for (control.body_design)
DESIGN_DELAY, DESIGN_FACTOR = 1.25, 4.0

#: the MPC's cost formulations: the paper's eq 17, and the closed-stroke cost
#: (``control.cost``: strokes that close, the Strouhal penalty per stroke, an energy term)
FORMULATIONS = ("paper", "closed_stroke")
#: the fin force models the MPC plans with: the analytic model, or a table of it (or of a file)
FORCE_MODELS = ("analytic", "table")


@dataclass(frozen=True)
class MpcConfig(Config):
    """The fin MPC (control.md sections 1-5, paper Table I)."""

    formulation: str = param(
        "paper", choices=FORMULATIONS,
        doc="cost: the paper's eq 17, or closed strokes with a per-stroke St penalty and an energy term",
    )
    # cost weights (eq 17)
    lam_f: float = param(1.5, lo=0.0, hi=100.0, doc="weight of the force tracking error")
    lam_st: float = param(5.0, lo=0.0, hi=100.0, doc="weight of the Strouhal penalty")
    lam_a: float = param(1.0, lo=0.0, hi=100.0, doc="weight of the amplitude penalty")
    lam_d: float = param(1.0, lo=0.0, hi=100.0, doc="weight of the smoothness penalty")
    # weights of the closed-stroke formulation only
    lam_c: float = param(
        0.3, lo=0.0, hi=100.0, unit="1/rad",
        doc="closed_stroke: weight of the opening |d_1 + d_2| of a cycle that does not close",
    )
    lam_e: float = param(
        1.0, lo=0.0, hi=1000.0, unit="1/W",
        doc="closed_stroke: weight of the cycle's mechanical energy per second (the model's drag and inertia)",
    )
    # horizon and solver
    horizon: int = param(2, choices=(2,), doc="strokes per cycle H (the solver is built for H=2)")
    n_samples: int = param(500, lo=1, hi=100_000, doc="stage-1 samples N")
    max_iter: int = param(60, lo=0, hi=10_000, doc="stage-2 iteration limit k_max")
    refine_starts: int = param(
        6, lo=1, hi=64, doc="best samples refined by the production solver (the paper refines 1)"
    )
    refine_screen: int = param(
        4, lo=0, hi=10_000,
        doc="iterations every refined sample gets before the refine_keep best go on to max_iter",
    )
    refine_keep: int = param(2, lo=1, hi=64, doc="refined samples that go on to max_iter")
    solver: str = param("numba", choices=("numba", "scipy"), doc="stage-2 implementation")
    force_model: str = param("analytic", choices=FORCE_MODELS, doc="fin force model")
    table_path: str | None = param(None, doc="force table file (.npz); None: built from the model")
    table_n_d: int = param(241, lo=2, hi=4001, doc="force table nodes along the stroke d")
    table_n_w: int = param(121, lo=2, hi=4001, doc="force table nodes along the rate w")
    # fluid and fin (Table I)
    rho: float = param(RHO_TABLE_I, lo=1.0, hi=2000.0, lo_open=True, unit="kg/m3", doc="water density")
    fin_area: float = param(FIN_AREA, lo=0.0, hi=1.0, lo_open=True, unit="m2", doc="fin planform A_f")
    fin_length: float = param(0.10, lo=0.0, hi=2.0, lo_open=True, unit="m", doc="effective fin length L_f")
    r_c: float = param(FIN_R_C, lo=0.0, hi=2.0, lo_open=True, unit="m", doc="radius of gyration r_c")
    c_d: float = param(0.70, lo=0.0, hi=20.0, doc="drag coefficient C_D")
    c_l: float = param(0.25, lo=0.0, hi=20.0, doc="lift coefficient C_L")
    fin_inertia: float = param(
        FIN_INERTIA, lo=0.0, hi=1.0, unit="kg m2",
        doc="closed_stroke: the inertia about the fin's shaft the energy term charges each stroke for spinning "
        "up from rest (the drive does not get it back); the blade's by default. With what the drive really spins "
        "up, the blade, the water it carries and the rotor (robot.fin_plate.STROKE_INERTIA, 0.0347), the plans "
        "take long strokes and the energy per metre no longer depends on the seed, but they hold the heading "
        "less well (docs/findings.md)",
    )
    # Strouhal surrogate (eqs 10-12)
    st_opt: float = param(0.30, lo=0.01, hi=2.0, doc="optimal Strouhal number")
    eta_max: float = param(1.0, lo=0.0, hi=10.0, lo_open=True, doc="surrogate scale")
    st_low: float = param(0.25, lo=0.0, hi=2.0, doc="St corridor lower edge (reporting)")
    st_high: float = param(0.35, lo=0.0, hi=2.0, doc="St corridor upper edge (reporting)")
    v_floor: float = param(0.05, lo=0.0, hi=5.0, lo_open=True, unit="m/s", doc="speed floor for St")
    # bounds (eq 18)
    d_max: float = param(1.2, lo=0.0, hi=3.14159, lo_open=True, unit="rad", doc="stroke limit")
    d_eps: float = param(0.05, lo=0.0, hi=3.14159, lo_open=True, unit="rad", doc="shortest stroke")
    w_min: float = param(0.5, lo=0.0, hi=100.0, lo_open=True, unit="rad/s", doc="slowest mean rate")
    w_max: float = param(8.0, lo=0.0, hi=100.0, lo_open=True, unit="rad/s", doc="fastest mean rate")
    a_min: float = param(0.03, lo=0.0, hi=1.0, unit="m", doc="amplitude penalty threshold A_min")
    # beyond the paper: the cycle's orientation
    centre_rate: float = param(
        0.0, lo=0.0, hi=100.0, unit="rad/s",
        doc="turn each planned cycle (its oscillation centre) so its mean force points along the "
        "target, at most this fast (0: the paper's MPC, the cycle as solved)",
    )
    max_cycle: float = param(
        0.0, lo=0.0, hi=60.0, unit="s",
        doc="with centre_rate > 0: the longest cycle the centred plan may take, as the drives time it "
        "(0: no limit; the shortest candidate when none is within it)",
    )
    align: float = param(
        0.0, lo=0.0, hi=1.0,
        doc="with centre_rate > 0: among the centred cycles costing at most this fraction more than the best, "
        "the one that ends closest to when the fin across the hull begins its next cycle, so that the two "
        "take up a new target together (0: the best cycle, each fin on its own beat)",
    )
    centre_grid: int = param(
        12, lo=0, hi=64,
        doc="with centre_rate > 0: the centred cycle is the one of least cost among the solver's and a grid of "
        "this many amplitudes by as many rates, then a finer grid about the best (0: the solver's amplitude "
        "and rates)",
    )

    def _check(self) -> None:
        require_below(self, "d_eps", "d_max")
        require_below(self, "w_min", "w_max")
        require_below(self, "st_low", "st_high")
        if self.formulation == "closed_stroke" and self.solver != "numba":
            raise ValueError(
                "solver: the closed_stroke formulation is solved by the compiled solver only "
                f"(solver = 'numba'), got {self.solver!r}"
            )

    @property
    def weights(self) -> tuple[float, float, float, float]:
        return (self.lam_f, self.lam_st, self.lam_a, self.lam_d)


#: the baseline's inverse models: the controller's fin model, or the paper's eq 19
BASELINE_INVERSES = ("fin_model", "eq19")


@dataclass(frozen=True)
class BaselineConfig(Config):
    """The fixed-frequency inverse model of Remmas et al. (control.md section 6)."""

    frequency: float = param(2.0, lo=0.05, hi=10.0, unit="Hz", doc="fixed fin-beat frequency")
    inverse_model: str = param(
        "fin_model", choices=BASELINE_INVERSES,
        doc="amplitude for a force: the controller's fin model with the drives' stroke timing, or the "
        "paper's eq 19 (4.65 times the fin model's force at the paper's coefficients)",
    )
    phase_gain: float = param(
        0.1, lo=0.0, hi=0.5,
        doc="the share of a fin's lag behind the other fins' beat taken off its next cycle (at most "
        "a twentieth of the cycle), so that the four fins beat in phase; 0: each fin's cycles follow "
        "from its last alone",
    )


#: the paper's baseline (its eq 19), for the experiments that reproduce it
PAPER_BASELINE = BaselineConfig(inverse_model="eq19")


@dataclass(frozen=True)
class PidGains(Config):
    kp: float = param(0.0, lo=0.0, hi=1000.0, doc="proportional gain")
    ki: float = param(0.0, lo=0.0, hi=1000.0, doc="integral gain")
    kd: float = param(0.0, lo=0.0, hi=1000.0, doc="derivative gain")
    limit: float = param(
        1.0, lo=0.0, hi=1000.0, lo_open=True, unit="N",
        doc="output limit (N; N m for the designed layer's heading loop, which also never asks "
        "for more than the fins can deliver)",
    )


#: the body layers: the designed one (the default) and the paper's (section IV.B)
BODY_LAYERS = ("designed", "paper")
#: the designed layer's gains, from the default hull model (control.body_design)
_DESIGN = designed_gains(HullModel(), DESIGN_DELAY, DESIGN_FACTOR)
#: the designed layer's speed low-pass (s; control.body_design)
SPEED_FILTER = round(speed_filter(DESIGN_DELAY, DESIGN_FACTOR), 4)
#: the designed loops' own output limits: none (the fins' deliverable force limits them)
_NO_LIMIT = 1000.0


def _designed(loop: str) -> PidGains:
    g = _DESIGN[loop]
    return PidGains(kp=round(g.kp, 4), ki=round(g.ki, 4), kd=round(g.kd, 4), limit=_NO_LIMIT)


@dataclass(frozen=True)
class BodyConfig(Config):
    """The body-frame layer: the loops on speed, depth and heading, and the allocation.

    ``layer = "designed"`` (the default, ``control.body``, ``control.body_design`` and
    ``docs/control.md``): physical forces and moments from loops designed on the hull's
    model, each tracking a reference that closes on its setpoint at a limited rate with the
    hull's model as feed-forward (a velocity PI, a depth PI, a heading PD with integral that
    holds the heading a zero yaw-rate setpoint leaves), allocated to the four fins with each
    fin's deliverable force as its limit and the priority heave, yaw, surge; what is cut goes
    back to the loops (anti-windup) and onto the telemetry.
    ``layer = "paper"``: the paper's section IV.B (``PAPER_BODY``), the loops' outputs in the
    fin model's terms, heave and yaw on the front pair, no limits but the loops' own.

    The three gain blocks are the same three loops in both layers: ``velocity`` (designed:
    surge force, N per m/s), ``depth`` (heave force, N per m) and ``yaw_rate`` (designed:
    the heading loop, N m per rad with ``kd`` on the yaw rate's error; paper: the yaw-rate
    loop, a thrust differential in N).
    """

    layer: str = param("designed", choices=BODY_LAYERS, doc="the designed body layer or the paper's")
    velocity: PidGains = _designed("velocity")
    depth: PidGains = _designed("depth")
    yaw_rate: PidGains = _designed("heading")
    median_window: int = param(5, lo=1, hi=101, doc="median filter length for DVL and depth")
    depth_sign: float = param(
        -1.0, choices=(1.0, -1.0),
        doc="paper layer: F_y* = depth_sign * PID(depth error); -1 because a positive f_y lifts the hull",
    )
    hull: HullModel = HullModel()
    thrust_gain: float = param(
        1.0, lo=0.1, hi=20.0,
        doc="designed layer: forward fin force delivered per unit of the fin model's (soft fins "
        "make more thrust than the quasi-steady model; `ucat-console identify --fit scale` measures it)",
    )
    heave_trim: float = param(
        0.0, lo=-50.0, hi=50.0, unit="N",
        doc="designed layer: heave force (down > 0) that holds the robot at rest (buoyancy and trim; "
        "the depth loop's integral after a hover)",
    )
    heave_rear_share: float = param(
        0.5, lo=0.0, hi=1.0,
        doc="designed layer: share of the heave force on the rear pair (0.5: all four fins alike, "
        "no pitch moment; 0: the front pair, as the paper)",
    )
    yaw_on_rear: bool = param(
        True, doc="designed layer: the rear pair makes yaw moment too (not in sync mode, where its fins "
        "run one plan)",
    )
    speed_filter: float = param(
        SPEED_FILTER, lo=0.0, hi=10.0, unit="s",
        doc="designed layer: time constant of the low-pass on the median-filtered DVL speed the velocity "
        "loop closes on (0: none): the fins sample their force targets once a cycle, so DVL noise in the "
        "surge demand would reach each fin at a different time and turn the robot",
    )
    schedule: bool = param(
        True, doc="designed layer, under a mode whose beat frequency is the operator's choice (the baseline: "
        "backend.loop.modes.Mode.schedules_body): the loops' gains follow the period of the cycles the fins execute "
        "(the configured gains are for the design delay, 1.25 s; control.body_design), between schedule_min_delay "
        "and schedule_max_delay, the period low-passed (schedule_rise, schedule_filter) so that the gains move "
        "smoothly; it steadies slow gaits (a 0.5 Hz baseline). The MPC modes hold their cycles within "
        "mpc.max_cycle and run the configured gains (scheduled, they lost heading: docs/control.md)",
    )
    schedule_min_delay: float = param(
        DESIGN_DELAY, lo=0.1, hi=4.0, unit="s",
        doc="designed layer: the shortest fin delay the loops are scheduled for (the design delay: shorter "
        "cycles keep the configured gains)",
    )
    schedule_max_delay: float = param(
        2.0, lo=0.1, hi=4.0, unit="s",
        doc="designed layer: the longest fin delay the loops are scheduled for (longer cycles keep its gains; "
        "beyond 4 s the designed velocity loop would have no proportional gain)",
    )
    schedule_rise: float = param(
        2.0, lo=0.0, hi=600.0, unit="s",
        doc="designed layer: time constant with which the scheduled delay follows a fin's cycle longer than it "
        "(0: at once)",
    )
    schedule_filter: float = param(
        20.0, lo=0.0, hi=600.0, unit="s",
        doc="designed layer: time constant with which the scheduled delay follows a fin's cycle shorter than it "
        "(0: at once): slow, so the loops stay scheduled for the longest of the fins' recent cycles",
    )
    max_fin_force: float = param(
        0.0, lo=0.0, hi=100.0, unit="N",
        doc="designed layer: the most force the allocation asks of a fin by the fin model (0: what the drives "
        "can make, the fin model's deliverable force; less where the fin planners make less)",
    )
    feed_shortfall: bool = param(
        True, doc="designed layer: add to the loops' demand what the fins' running cycles make short of what "
        "they were asked (each plan's force by the fin model against its target), so that a fin whose planner "
        "cannot make its share does not turn or tilt the robot",
    )
    feed_executed: bool = param(
        True, doc="designed layer: correct each fin's plan force in that feed-forward by what its last executed "
        "cycle (the measured strokes, by the fin model) made short of its plan: a weak or lagging drive's "
        "share goes to the other fins",
    )
    shortfall_filter: float = param(
        0.5, lo=0.0, hi=10.0, unit="s", doc="designed layer: time constant of the low-pass on the fins' shortfall",
    )
    shortfall_limit: float = param(
        0.1, lo=0.0, hi=1.0,
        doc="designed layer: the largest shortfall fed forward, as a share of what the fins deliver on each axis "
        "(a planner that cannot make more than it does would wind it up)",
    )
    force_scale_from: float = param(
        2.0, lo=0.0, hi=20.0,
        doc="designed layer: when the fins make at least this many times the fin model's force (measured from "
        "the surge balance: the hull's model against what the fins were asked), the layer asks them for that "
        "much less on every axis (0: never; a loop designed for the model holds within a factor of 2 of its "
        "gain, beyond it oscillates)",
    )
    force_scale_max: float = param(
        8.0, lo=1.0, hi=20.0, doc="designed layer: the largest measured force scale the layer follows",
    )
    direction_hold: float = param(
        0.05, lo=0.0, hi=10.0, unit="N",
        doc="designed layer: a fin asked for less than this by the fin model keeps the direction of the cycle "
        "it runs, making the part of its target along it (0: never). Such strokes are slow beside the stream "
        "(0.05 N with the paper's coefficients: 0.82 rad/s, 0.08 m/s at the centre of pressure), and a stroke "
        "centre swung round for a force whose direction is noise drags the fin across the stream at its slowest "
        "rate: a rudder the fin model does not know",
    )
    max_heading_lead: float = param(
        0.5, lo=0.01, hi=3.0, unit="rad",
        doc="designed layer: how far the commanded heading may run ahead of the robot's (a turn "
        "faster than the fins can make)",
    )
    reference_rate: float = param(
        round(1.0 / (DESIGN_FACTOR * DESIGN_DELAY), 4), lo=0.01, hi=10.0, unit="1/s",
        doc="designed layer: how fast the loops' references close on a new setpoint (the loops' bandwidth)",
    )
    acceleration_rise: float = param(
        round(2.0 * DESIGN_DELAY, 4), lo=0.0, hi=30.0, unit="s",
        doc="designed layer: how long the speed reference's acceleration takes to rise to max_acceleration "
        "(0: at once); each fin takes up a new surge demand at its own next cycle, so a demand that rises "
        "over two of them reaches the two sides alike",
    )
    max_dive_rate: float = param(
        0.06, lo=0.001, hi=2.0, unit="m/s", doc="designed layer: the depth reference's fastest climb or dive",
    )
    max_acceleration: float = param(
        0.02, lo=0.001, hi=2.0, unit="m/s2", doc="designed layer: the speed reference's largest change per second",
    )
    max_yaw_acceleration: float = param(
        0.02, lo=0.001, hi=2.0, unit="rad/s2",
        doc="designed layer: the yaw-rate reference's largest change per second",
    )

    def _check(self) -> None:
        if self.schedule_min_delay > self.schedule_max_delay:
            raise ValueError(
                f"schedule_min_delay: {self.schedule_min_delay!r} s is above schedule_max_delay "
                f"({self.schedule_max_delay!r} s); allowed: at most schedule_max_delay"
            )
        if self.layer == "designed":
            for loop in ("velocity", "depth", "yaw_rate"):
                if getattr(self, loop).kp <= 0.0:
                    raise ValueError(
                        f"{loop}.kp: {getattr(self, loop).kp!r} leaves the designed layer's {loop} "
                        "loop without a proportional gain; allowed: > 0"
                    )


#: the paper's body layer (Table I's PIDs, section IV.B's allocation)
PAPER_BODY = BodyConfig(
    layer="paper",
    velocity=PidGains(kp=40.0, ki=1.0, kd=0.1, limit=2.5),
    depth=PidGains(kp=5.0, ki=0.1, kd=0.005, limit=0.5),
    yaw_rate=PidGains(kp=3.0, ki=0.2, kd=0.0, limit=0.5),
)


@dataclass(frozen=True)
class ExecutorConfig(Config):
    """Execution module (control.md section 8, Algorithm 2)."""

    slow_fin_ratio: float = param(
        1.5, lo=1.0, hi=10.0, lo_open=True,
        doc="a fin whose executed cycles last this many times their plans' duration (the median of its last "
        "five) is reported slow: a weak or lagging drive",
    )
    w_threshold: float = param(
        0.3, lo=0.0, hi=50.0, lo_open=True, unit="rad/s", doc="stroke finished below this rate"
    )
    min_stroke_time: float = param(
        0.02, lo=0.0, hi=5.0, unit="s", doc="ignore completion before this time in a stroke"
    )
    stroke_timeout_factor: float = param(
        3.0, lo=1.0, hi=100.0, doc="a stroke is also finished after this many planned durations"
    )
    stroke_timeout_min: float = param(
        0.1, lo=0.0, hi=10.0, unit="s", doc="a stroke never times out earlier than this"
    )
    acceleration: float = param(
        FIN_ACCELERATION, lo=0.0, hi=100_000.0, lo_open=True, unit="rad/s2",
        doc="the fin drives' profile acceleration: a stroke's profile velocity is chosen so that it "
        "takes the planned time (0x6083 on the EPOS2s)",
    )
    max_rate: float = param(FIN_MAX_RATE, lo=0.0, hi=200.0, lo_open=True, unit="rad/s",
                            doc="the fin drives' largest rate")


@dataclass(frozen=True)
class PowerConfig(Config):
    """Power estimate from encoder positions (control.md section 9), with the fin's own
    coefficients: the controller's model (``MpcConfig``) may be identified or tuned to other
    values, the measured power is not."""

    fin_inertia: float = param(2.8e-5, lo=0.0, hi=1.0, unit="kg m2", doc="fin inertia I")
    rho: float = param(RHO_TABLE_I, lo=1.0, hi=2000.0, lo_open=True, unit="kg/m3", doc="water density")
    fin_area: float = param(FIN_AREA, lo=0.0, hi=1.0, lo_open=True, unit="m2", doc="fin planform A_f")
    r_c: float = param(FIN_R_C, lo=0.0, hi=2.0, lo_open=True, unit="m", doc="fin radius of gyration r_c")
    c_d: float = param(0.70, lo=0.0, hi=20.0, doc="the fin's drag coefficient C_D (of the drag power)")
    filter_tau: float = param(
        0.02, lo=0.0, hi=1.0, unit="s", doc="first-order low-pass on rate and acceleration"
    )


def _check_steps(steps: tuple[tuple[float, float, float], ...]) -> None:
    if not steps:
        raise ValueError("steps: the manoeuvre needs at least one step")
    for i, step in enumerate(steps):
        if len(step) != 3:
            raise ValueError(f"steps[{i}]: expected (centre offset rad, stroke rad, rate rad/s), got {step!r}")
        offset, stroke, rate = step
        if not -1.6 <= offset <= 1.6:
            raise ValueError(f"steps[{i}]: centre offset {offset!r} rad is out of range; allowed: [-1.6, 1.6]")
        if not 0.05 <= stroke <= 3.14159:
            raise ValueError(f"steps[{i}]: stroke {stroke!r} rad is out of range; allowed: [0.05, 3.14159]")
        if not 0.1 <= rate <= 50.0:
            raise ValueError(f"steps[{i}]: rate {rate!r} rad/s is out of range; allowed: [0.1, 50.0]")


@dataclass(frozen=True)
class ManoeuvreConfig(Config):
    """The identification manoeuvre (mode "identify"): fixed strokes, step after step.

    Each step holds a symmetric stroke pair of ``stroke`` rad at the mean rate ``rate`` about
    the forward-thrust centre of the controller's model turned by ``centre offset``, for
    ``step_s`` seconds; several centres are needed to tell C_L from C_D (the mean thrust of
    one centre is one combination of the two), several rates and strokes to span the
    speeds. After the last step the fins hold still.
    """

    steps: tuple[tuple[float, float, float], ...] = param(
        ((0.0, 0.6, 2.0), (0.0, 1.2, 2.0), (0.0, 0.6, 4.0), (0.0, 1.2, 4.0),
         (-0.5, 0.8, 3.0), (0.5, 0.8, 3.0)),
        doc="(centre offset rad, stroke rad, mean rate rad/s) of each step",
    )
    step_s: float = param(20.0, lo=2.0, hi=600.0, unit="s", doc="how long each step is held")

    def _check(self) -> None:
        _check_steps(self.steps)

    @property
    def duration(self) -> float:
        """The whole manoeuvre (s)."""
        return self.step_s * len(self.steps)
