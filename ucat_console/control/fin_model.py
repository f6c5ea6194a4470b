"""Per-fin quasi-steady model (control.md section 1, paper eqs 1-8) and its force table.

A stroke k starts at angle ``theta_k``, moves by ``d_k`` at mean rate ``w_k > 0``.
Its fin-frame force (eq 5) depends on (d, w) only::

    fxl = -L cos(d/2) - D sin(d/2),   fyl = -L sin(d/2) - D cos(d/2),
    L = 0.5 rho C_L A_f (r_c w)^2,     D = 0.5 rho C_D A_f (r_c w)^2,

and reaches the body frame through the mid-stroke angle, f = R(theta + d/2) f^l (eqs 6-8).

The solver works with the *stroke-frame* force g(d, w) = R(d/2) f^l(d, w), so that
f_k = R(theta_k) g(d_k, w_k). For the analytic model this simplifies exactly to::

    g = -q w^2 (C_L cos d, C_L sin d + C_D),   q = 0.5 rho A_f r_c^2,

which costs one sine/cosine pair per stroke. A :class:`ForceTable` holds the fin-frame
force on a uniform (d, w) grid (the seam for measured data) and derives the stroke-frame
table from it at the grid nodes; both are read by bilinear interpolation.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ucat_console.control.params import MpcConfig


def dynamic_pressure_gain(cfg: MpcConfig) -> float:
    """q = 0.5 rho A_f r_c^2, so that L = q C_L w^2 and D = q C_D w^2 (eqs 2-3)."""
    return 0.5 * cfg.rho * cfg.fin_area * cfg.r_c**2


def fin_frame_force(d: ArrayLike, w: ArrayLike, cfg: MpcConfig) -> tuple[NDArray, NDArray]:
    """Fin-frame mean force (fxl, fyl) of a stroke d at mean rate w (eqs 2-5)."""
    d = np.asarray(d, dtype=float)
    w = np.asarray(w, dtype=float)
    v = cfg.r_c * np.abs(w)  # eq 2
    drag = 0.5 * cfg.rho * cfg.c_d * cfg.fin_area * v**2  # eq 3
    lift = 0.5 * cfg.rho * cfg.c_l * cfg.fin_area * v**2
    thr = d / 2.0  # eq 4
    fxl = -lift * np.cos(thr) - drag * np.sin(thr)  # eq 5
    fyl = -lift * np.sin(thr) - drag * np.cos(thr)
    return fxl, fyl


def rotate(angle: ArrayLike, x: ArrayLike, y: ArrayLike) -> tuple[NDArray, NDArray]:
    """R(angle) @ (x, y), the 2-D rotation of eq 7."""
    c, s = np.cos(angle), np.sin(angle)
    return c * x - s * y, s * x + c * y


def stroke_force_body(
    theta: ArrayLike, d: ArrayLike, w: ArrayLike, cfg: MpcConfig
) -> tuple[NDArray, NDArray]:
    """Body-frame mean force of a stroke starting at theta (eqs 6-8)."""
    fxl, fyl = fin_frame_force(d, w, cfg)
    return rotate(np.asarray(theta) + np.asarray(d) / 2.0, fxl, fyl)


@dataclass(frozen=True, eq=False)
class ForceTable:
    """Fin-frame force on a uniform (d, w) grid, read by bilinear interpolation.

    ``fx[i, j]``, ``fy[i, j]`` are the force at ``d = d_lo + i * step_d`` and
    ``w = w_lo + j * step_w``. Files are ``.npz`` with arrays ``d``, ``w``, ``fx``, ``fy``
    (fin frame, newtons), so a table identified from tank tests loads the same way.
    """

    d: NDArray[np.float64]
    w: NDArray[np.float64]
    fx: NDArray[np.float64]
    fy: NDArray[np.float64]

    def __post_init__(self) -> None:
        for name in ("d", "w"):
            axis = getattr(self, name)
            if axis.ndim != 1 or axis.size < 2:
                raise ValueError(f"force table {name}: need a 1-D axis of >= 2 nodes")
            if not np.all(np.isfinite(axis)):
                raise ValueError(f"force table {name}: axis has non-finite values")
            steps = np.diff(axis)
            if np.any(steps <= 0) or not np.allclose(steps, steps[0], rtol=1e-9, atol=1e-12):
                raise ValueError(f"force table {name}: axis must be uniform and increasing")
        shape = (self.d.size, self.w.size)
        for name in ("fx", "fy"):
            arr = getattr(self, name)
            if arr.shape != shape:
                raise ValueError(f"force table {name}: shape {arr.shape}, expected {shape}")
            if not np.all(np.isfinite(arr)):
                raise ValueError(f"force table {name}: non-finite entries")

    @classmethod
    def from_model(cls, cfg: MpcConfig) -> ForceTable:
        """Tabulate the analytic model over [-d_max, d_max] x [w_min, w_max]."""
        d = np.linspace(-cfg.d_max, cfg.d_max, cfg.table_n_d)
        w = np.linspace(cfg.w_min, cfg.w_max, cfg.table_n_w)
        fx, fy = fin_frame_force(d[:, None], w[None, :], cfg)
        return cls(d, w, np.ascontiguousarray(fx), np.ascontiguousarray(fy))

    @classmethod
    def load(cls, path: str | Path) -> ForceTable:
        p = Path(path)
        try:
            with np.load(p, allow_pickle=False) as z:
                files = z.files
                arrays = {k: np.asarray(z[k], dtype=np.float64) for k in ("d", "w", "fx", "fy") if k in files}
        except FileNotFoundError:
            raise ValueError(f"{p}: force table file not found") from None
        except (OSError, EOFError, ValueError) as e:
            raise ValueError(f"{p}: not a readable .npz force table: {e}") from None
        missing = [k for k in ("d", "w", "fx", "fy") if k not in arrays]
        if missing:
            raise ValueError(f"{p}: force table lacks array(s) {', '.join(missing)}")
        try:
            return cls(**arrays)
        except ValueError as e:
            raise ValueError(f"{p}: {e}") from None

    def save(self, path: str | Path) -> None:
        np.savez(Path(path), d=self.d, w=self.w, fx=self.fx, fy=self.fy)

    def covers(self, cfg: MpcConfig) -> bool:
        """Whether the grid spans the MPC's decision box."""
        tol = 1e-9
        return bool(
            self.d[0] <= -cfg.d_max + tol
            and self.d[-1] >= cfg.d_max - tol
            and self.w[0] <= cfg.w_min + tol
            and self.w[-1] >= cfg.w_max - tol
        )

    def stroke_frame(self) -> tuple[NDArray, NDArray]:
        """g = R(d/2) f^l at the nodes: the stroke-frame table the solver interpolates."""
        gx, gy = rotate(self.d[:, None] / 2.0, self.fx, self.fy)
        return np.ascontiguousarray(gx), np.ascontiguousarray(gy)

    def interpolate(self, d: ArrayLike, w: ArrayLike) -> tuple[NDArray, NDArray]:
        """Bilinear interpolation of the fin-frame force (clamped to the grid)."""
        return bilinear(self.d, self.w, self.fx, self.fy, d, w)


def bilinear(
    d_axis: NDArray, w_axis: NDArray, ax: NDArray, ay: NDArray, d: ArrayLike, w: ArrayLike
) -> tuple[NDArray, NDArray]:
    """Bilinear read of two tables on one uniform grid; points are clamped to the grid."""
    d = np.clip(np.asarray(d, dtype=float), d_axis[0], d_axis[-1])
    w = np.clip(np.asarray(w, dtype=float), w_axis[0], w_axis[-1])
    hd = d_axis[1] - d_axis[0]
    hw = w_axis[1] - w_axis[0]
    fi = np.minimum((d - d_axis[0]) / hd, d_axis.size - 1 - 1e-12)
    fj = np.minimum((w - w_axis[0]) / hw, w_axis.size - 1 - 1e-12)
    i = np.floor(fi).astype(int)
    j = np.floor(fj).astype(int)
    td = fi - i
    tw = fj - j

    def read(a: NDArray) -> NDArray:
        return (
            (1 - td) * (1 - tw) * a[i, j]
            + td * (1 - tw) * a[i + 1, j]
            + (1 - td) * tw * a[i, j + 1]
            + td * tw * a[i + 1, j + 1]
        )

    return read(ax), read(ay)
