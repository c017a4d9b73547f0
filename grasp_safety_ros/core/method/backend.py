"""Where the per-sample work of the analyses runs, decided once: the compiled kernels or the
Pinocchio reference (upkie's ``Backend`` pattern: the analyses receive one and never test
for numba or the chain themselves).

``Backend.chain`` is the chain as the kernels take it (``compiled.chain_arrays``) when they
run, None when Pinocchio does (numba missing, a chain the kernels do not support, or the
``python`` backend asked for). The analysis functions take that chain (``chain=None``: their
Pinocchio reference path, which ``test_performance_paths`` holds equal to the compiled one).
"""

from __future__ import annotations

from collections.abc import Collection, Sequence
from concurrent.futures import Executor
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..model.inertia import ObjectInertia
from ..model.robot import RobotModel
from .compiled import chain_arrays
from .ik import IKSolver
from .ik_config import compiled_available
from .packed import ChainArrays
from .terms import OPTIONAL_TERMS, SampleTerms, grasps_terms


@dataclass(frozen=True)
class Backend:
    """The compiled kernels (``chain``: the chain's arrays) or the Pinocchio reference
    (``chain`` None)."""

    chain: ChainArrays | None = None

    @classmethod
    def of(cls, ik: IKSolver) -> Backend:
        """The backend of an evaluator's IK solver (``GraspSafetyEvaluator.ik``): compiled
        when its kernels run, so the analyses run where the ranking ran."""
        return cls(ik.chain if ik.compiled else None)

    @classmethod
    def for_robot(cls, robot: RobotModel) -> Backend:
        """Compiled when numba is installed and the kernels support ``robot``'s chain."""
        return cls(chain_arrays(robot) if compiled_available() else None)

    @property
    def compiled(self) -> bool:
        """Whether the compiled kernels run."""
        return self.chain is not None

    def grasps_terms(
        self,
        robot: RobotModel,
        object_inertia: ObjectInertia,
        transforms_tip_to_object: Sequence[pin.SE3],
        joint_positions: Sequence[np.ndarray],
        optional: Collection[str] = OPTIONAL_TERMS,
        executor: Executor | None = None,
    ) -> tuple[SampleTerms, np.ndarray]:
        """``terms.grasps_terms`` on this backend's chain (the per-sample terms of G grasps
        and their counts; ``executor``: the thread pool that shares the kernel call out); only
        the compiled backend has them (ValueError otherwise)."""
        if self.chain is None:
            raise ValueError("the Pinocchio backend has no shared terms")
        return grasps_terms(
            robot,
            self.chain,
            object_inertia,
            transforms_tip_to_object,
            joint_positions,
            optional,
            executor,
        )
