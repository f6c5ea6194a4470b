"""The simulated U-CAT's plant variants, by name: what the experiments, the sweeps and the
benchmarks run the closed loop and the fin rig on.

A name is one of :data:`PLANT_VARIANTS`, a member ``scale<G>_<model>`` of E6's plant family
(:func:`family_hydro`) or a profile-drag plant ``plate_cd<C_D0>`` (:func:`cd0_hydro`; E7's
are :func:`e7_plants`). Each names the fins' hydrodynamics (:class:`FinHydroConfig`); the
rest of the plant is the default's. :func:`plant_config` makes the plant of a name.
"""

from __future__ import annotations

from typing import Any

from ucat_console.backend.sim.params import (
    FIN_MODELS,
    PAPER_COEFFICIENTS,
    FinHydroConfig,
    PlantConfig,
    VehicleConfig,
)

#: plant assumptions the experiments run under (plant.md; docs/fin-plant.md): the plate
#: calibrated to the paper's identified fin (the default), the still-water null plant, and
#: the plate calibrated to eeUVsim's coefficients while the controller keeps the paper's
PLANT_VARIANTS: dict[str, FinHydroConfig] = {
    "plate": FinHydroConfig(),
    "still_water": FinHydroConfig(model="still_water"),
    "eeuvsim": FinHydroConfig(coefficients="eeuvsim"),
}
#: the default plant variant (the shipped configurations' plant)
DEFAULT_PLANT = "plate"

#: E7's plants: the plate over the profile drag C_D0 and the null plant (the plate as if
#: in still water, the thrust's work paid through the shaft)
E7_CD0 = (0.02, 0.05, 0.3)
NULL_PLANT = "still_water"


def family_name(scale: float, model: str) -> str:
    """The name of a member of E6's plant family: ``scale4.6_plate``."""
    return f"scale{scale:g}_{model}"


def family_hydro(name: str) -> FinHydroConfig | None:
    """The hydrodynamics of a family member ``scale<G>_<model>`` (the paper's coefficients
    times G: G times the thrust per w^2, paid with G times the shaft's load); None if
    ``name`` is not of that form."""
    if not name.startswith("scale") or "_" not in name:
        return None
    scale, _, model = name[5:].partition("_")
    try:
        g = float(scale)
    except ValueError:
        return None
    if model not in FIN_MODELS or not 0.0 < g <= 20.0:
        return None
    return FinHydroConfig(model=model, coefficients="custom", custom=PAPER_COEFFICIENTS.scaled(g))


def cd0_name(cd0: float) -> str:
    """The name of a profile-drag plant (E7): ``plate_cd0.1`` (the default plate with the
    profile drag C_D0)."""
    return f"plate_cd{cd0:g}"


def cd0_hydro(name: str) -> FinHydroConfig | None:
    """The hydrodynamics of a plant ``plate_cd<C_D0>``; None if ``name`` is not of that form."""
    if not name.startswith("plate_cd"):
        return None
    try:
        cd0 = float(name[len("plate_cd"):])
    except ValueError:
        return None
    return FinHydroConfig(c_d0=cd0)


def e7_plants() -> list[str]:
    """E7's plants by name: the profile-drag plates of :data:`E7_CD0`, then the null plant."""
    return [cd0_name(c) for c in E7_CD0] + [NULL_PLANT]


def hydro_of(variant: str) -> FinHydroConfig:
    """A named variant's, a family member's or a profile-drag plant's hydrodynamics, or
    ValueError naming it."""
    h = PLANT_VARIANTS.get(variant) or family_hydro(variant) or cd0_hydro(variant)
    if h is None:
        raise ValueError(f"plant: {variant!r} is not one of {', '.join(PLANT_VARIANTS)}, "
                         "scale<G>_plate / scale<G>_still_water or plate_cd<C_D0>")
    return h


def plant_config(variant: str, seed: int, current: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> PlantConfig:
    """The plant of a named variant with the sensor-noise seed and a water current (NED, m/s)."""
    return PlantConfig(hydro=hydro_of(variant), seed=seed, vehicle=VehicleConfig(current_ned=current))


def plant_assumptions(variant: str) -> dict[str, Any]:
    """What the report states about a plant variant: its fin model, the still-water
    coefficients it is calibrated to and the plate's own parameters."""
    h = hydro_of(variant)
    c = h.resolved()
    return {
        "variant": variant, "model": h.model, "coefficients": h.coefficients, "rho": c.rho,
        "c_d": c.c_d, "c_l": c.c_l, "area": c.area, "r_c": c.r_c, "fin_length": c.fin_length,
        "c_d0": h.c_d0, "lift_ratio": h.lift_ratio, "added_mass": h.added_mass, "strips": h.strips,
    }
