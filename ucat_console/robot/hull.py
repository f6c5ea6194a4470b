"""The U-CAT's rigid body, hull and fin dynamics as published: the one definition of these numbers.

The TalTech eeUVsim U-CAT model (Centre-for-Biorobotics/eeUVsim_Gazebo,
``eeuv_sim/data/dynamics/UCATDynamics.yaml``, commit 7276ed3; plant.md's table), mass from
the paper's Table II. The plant takes the mass and the inertias (about the centre of gravity)
as the whole robot's: it gives the fins no mass of their own (the URDF, ``robot/urdf.py``,
splits them between the hull and the fins). Fossen's signs: added-mass and damping
coefficients are negative (resistive). The simulated plant takes them as its defaults
(``backend/sim/params.py``) and the controller's model of the hull as its own
(``control.params.HullModel``); either may be configured to other values without the other
seeing it.
"""

from __future__ import annotations

MASS = 22.0  # kg
IXX, IYY, IZZ = 0.1574, 0.66, 0.70  # kg m2, about the centre of gravity
X_UDOT, Y_VDOT, Z_WDOT = -40.0, -21.0, -2.0  # kg
K_PDOT, M_QDOT, N_RDOT = -0.1269, -1.2052, -2.3064  # kg m2
X_U, Y_V, Z_W, N_R = -6.542, -100.7, -30.61, -0.313  # N s/m; N m s
X_UU, Y_VV, Z_WW = -2.98, -260.0, -161.0  # N s2/m2
K_PP, M_QQ, N_RR = -3.4244, -2.1014, -0.7226  # N m s2
#: centre of gravity and of buoyancy, body FRD (m): eeUVsim lists the CG at (0, 0, -0.1) with
#: restoring terms of the opposite sign to Fossen's, i.e. 0.1 m *below* the CB: (0, 0, +0.1) here
CG = (0.0, 0.0, 0.1)
CB = (0.0, 0.0, 0.0)
#: a fin's inertia about its shaft (kg m2, eeUVsim; plant.md)
FIN_INERTIA = 2.8e-5
