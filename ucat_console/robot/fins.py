"""The four fins: how many, their names, their order, their sides and signs.

Two orders are in use, and this is the one map between them:

* the robot's order (the plant's, the drivers', the telemetry's): 0 front-right,
  1 back-right, 2 back-left, 3 front-left (:data:`FIN_NAMES`);
* the paper's order (the allocation's, the planners', the executors'): 0 and 1 are the front
  pair, 2 and 3 the rear pair, 0 and 2 on the starboard side.

``PAPER_TO_ROBOT[k]`` is the robot fin of paper fin ``k``: paper 0 -> FR 0, paper 1 -> FL 3,
paper 2 -> BR 1, paper 3 -> BL 2; ``ROBOT_TO_PAPER`` is its inverse.
"""

from __future__ import annotations

N_FINS = 4

#: robot fin order
FIN_NAMES: tuple[str, str, str, str] = ("front_right", "back_right", "back_left", "front_left")

#: robot fin of each paper fin index 0..3 (paper 0, 1 = front pair)
PAPER_TO_ROBOT: tuple[int, int, int, int] = (0, 3, 1, 2)
#: paper fin index of each robot fin
ROBOT_TO_PAPER: tuple[int, int, int, int] = tuple(PAPER_TO_ROBOT.index(i) for i in range(N_FINS))  # type: ignore[assignment]

#: side of each robot fin: +1 starboard, -1 port
SIDES: tuple[float, float, float, float] = (1.0, 1.0, -1.0, -1.0)
#: end of each robot fin: +1 front, -1 rear
ENDS: tuple[float, float, float, float] = (1.0, -1.0, -1.0, 1.0)
#: side of each paper fin: +1 starboard, -1 port
PAPER_SIDES: tuple[int, int, int, int] = tuple(int(SIDES[r]) for r in PAPER_TO_ROBOT)  # type: ignore[assignment]


def fin_signs(fin: int) -> tuple[float, float, float]:
    """(s_lat, s_long, s_y) of a robot fin: +1 starboard / +1 front / lateral sign of x_m.

    x_m = (-cos(alpha), s_y sin(alpha), 0) in the body frame; s_y = -s_lat * s_long, so the
    front fins' x_m points inwards and the rear fins' outwards.
    """
    if fin not in range(N_FINS):
        raise ValueError(f"fin: {fin!r} is not a plant fin index 0..3")
    s_lat, s_long = SIDES[fin], ENDS[fin]
    return s_lat, s_long, -s_lat * s_long
