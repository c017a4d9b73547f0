"""The IK solver's settings, its per-trajectory result and the backend choice (``ik`` re-exports
them; ``IKSolver`` is in ``ik``)."""

from __future__ import annotations

import importlib.util
from dataclasses import dataclass

import numpy as np

from ..exceptions import InvalidInputError
from .packed import IKSettings


def _numba_installed() -> bool:
    try:
        return importlib.util.find_spec("numba") is not None
    except (ImportError, ValueError):
        return False


NUMBA_AVAILABLE = _numba_installed()
"""Whether the optional accelerator numba is installed (imported only when first used)."""

BACKENDS = ("auto", "compiled", "python")
"""IK / effective-mass implementations: see the module docstring."""


@dataclass(frozen=True)
class IKConfig:
    """Settings of the IK solver.

    Attributes:
        position_tolerance_m: Converged when the tip position error is at most this [m].
        orientation_tolerance_rad: ... and the tip orientation error at most this [rad].
        max_iterations: Gauss-Newton iterations per sample.
        max_iteration_step: Largest joint change of one iteration (inf-norm) [rad or m].
        random_restarts: Random seeds tried for the first sample when the given seed fails.
        random_seed: Seed of those restarts (results are deterministic).
        max_joint_step: Largest joint change between consecutive samples before the
            trajectory counts as a jump (IK branch switch) [rad or m].
        check_velocity_limits: Refuse trajectories whose joint speeds exceed the URDF limits.
    """

    position_tolerance_m: float = 1e-6
    orientation_tolerance_rad: float = 1e-6
    max_iterations: int = 100
    max_iteration_step: float = 0.5
    random_restarts: int = 30
    random_seed: int = 0
    max_joint_step: float = 0.5
    check_velocity_limits: bool = True

    def __post_init__(self) -> None:
        positive = {
            "ik.position_tolerance_m": self.position_tolerance_m,
            "ik.orientation_tolerance_rad": self.orientation_tolerance_rad,
            "ik.max_iteration_step": self.max_iteration_step,
            "ik.max_joint_step": self.max_joint_step,
        }
        for name, value in positive.items():
            if not (isinstance(value, (int, float)) and np.isfinite(value) and value > 0):
                raise InvalidInputError(name, f"must be a finite number > 0, got {value!r}")
        for name, value in {
            "ik.max_iterations": self.max_iterations,
            "ik.random_restarts": self.random_restarts,
        }.items():
            if not isinstance(value, int) or isinstance(value, bool) or value < 0:
                raise InvalidInputError(name, f"must be an integer >= 0, got {value!r}")


def ik_settings(
    config: IKConfig, velocity_limits: np.ndarray, predictor_max_ratio: float
) -> IKSettings:
    """IKSettings of an IKConfig, the chain's velocity limits (per joint) and the predictor's
    largest defect growth (``ik.PREDICTOR_MAX_RATIO``)."""
    velocity_limits = np.array(velocity_limits, dtype=float)
    check_velocity = np.array(
        config.check_velocity_limits & np.isfinite(velocity_limits) & (velocity_limits > 0),
        dtype=np.bool_,
    )
    return IKSettings(
        float(config.position_tolerance_m),
        float(config.orientation_tolerance_rad),
        int(config.max_iterations),
        float(config.max_iteration_step),
        float(config.max_joint_step),
        float(predictor_max_ratio),
        bool(check_velocity.any()),
        check_velocity,
        velocity_limits,
    )


@dataclass(frozen=True)
class IKTrajectoryResult:
    """Joint positions along a trajectory, or the reason it cannot be followed.

    Attributes:
        q: Pinocchio configurations, one row per solved sample.
        iterations: Gauss-Newton iterations per solved sample.
        reason: Empty when every sample was solved; otherwise why the trajectory fails.
    """

    q: np.ndarray
    iterations: np.ndarray
    reason: str

    @property
    def feasible(self) -> bool:
        """True when every sample was solved within tolerance and limits."""
        return not self.reason


def compiled_available() -> bool:
    """True when numba is importable (the compiled backend can be used)."""
    return NUMBA_AVAILABLE


def check_backend(backend: str, field_name: str = "backend") -> str:
    """Return ``backend`` if it is one of BACKENDS, else raise InvalidInputError."""
    if backend not in BACKENDS:
        raise InvalidInputError(
            field_name, f"must be one of {', '.join(BACKENDS)}, got {backend!r}"
        )
    if backend == "compiled" and not NUMBA_AVAILABLE:
        raise InvalidInputError(
            field_name, "'compiled' needs numba (pip install numba); use 'auto' or 'python'"
        )
    return backend
