"""The paper's numbers and claims that the experiments are compared with (one place)."""

from __future__ import annotations

#: Table IV: N -> (sampling cost, sampling ms, two-stage cost, two-stage ms)
TABLE_IV: dict[int, tuple[float, float, float, float]] = {
    250: (2.1690, 0.36, 1.8697, 38.58),
    500: (2.0948, 0.61, 1.8347, 37.89),
    1000: (2.0525, 0.98, 1.8340, 39.93),
    1500: (2.0112, 1.14, 1.8327, 37.99),
    2000: (1.9833, 1.29, 1.7909, 39.93),
    5000: (1.9899, 2.87, 1.7889, 37.55),
}
#: refinement lowers the mean cost by this much (%), low and high
E1_REDUCTION_PCT = (10.0, 15.0)

#: Table III: configuration -> (force error N, St deviation, in-range %, command stability)
TABLE_III: dict[str, tuple[float, float, float, float]] = {
    "full": (0.1559, 0.0285, 88.0, 1.625),
    "no_strouhal": (0.1466, 0.1227, 34.7, 1.761),
    "no_amplitude": (0.1541, 0.0320, 86.0, 1.801),
    "no_strouhal_amplitude": (0.1323, 0.1259, 30.0, 1.981),
    "no_smoothness": (0.1488, 0.0261, 89.3, 2.177),
}

#: Fig. 6: MPC keeps St in the corridor with a force error below this (N)
E2_FORCE_ERROR_N = 0.2

#: Table V: v_ref -> controller -> (power W, saving %, velocity MAE m/s, St MAE); None: not reached
TABLE_V: dict[float, dict[str, tuple[float, float, float, float] | None]] = {
    0.1: {"baseline": (1.900, 0.0, 0.0446, 0.3632), "mpc": (1.612, 15.1, 0.0465, 0.2402),
          "mpc_sync": (1.732, 8.8, 0.0486, 0.2626)},
    0.2: {"baseline": (3.251, 0.0, 0.0355, 0.9507), "mpc": (2.212, 32.0, 0.0321, 0.1918),
          "mpc_sync": (2.262, 30.4, 0.0426, 0.2349)},
    0.3: {"baseline": (3.724, 0.0, 0.0234, 0.3780), "mpc": (3.049, 18.1, 0.0389, 0.0558),
          "mpc_sync": (2.686, 27.9, 0.0370, 0.0544)},
    0.4: {"baseline": None, "mpc": (3.341, float("nan"), 0.0754, 0.0247),
          "mpc_sync": (3.386, float("nan"), 0.0654, 0.0370)},
}

#: Fig. 8 (field): velocity within about +-0.025 m/s
E5_VELOCITY_BAND = 0.025
