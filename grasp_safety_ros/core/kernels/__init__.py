"""The compiled path of the method: numba kernels on plain arrays, split by concern.

``kinematics`` (forward kinematics, tip Jacobian), ``lie_group`` (Pinocchio's log3 / log6 /
Jlog6 / exp3), ``linalg`` (LU solve, damped least-squares step), ``ik`` (pose and trajectory
IK), ``effective_mass`` (translational mobility) and ``grasp`` (the fused per-grasp kernel).
They mirror the Pinocchio-based Python loops of ``core.method`` operation for operation, so
per-sample results equal the Python path's to rounding; they are compiled on first use and
cached on disk by numba (``cache=True``) and release the GIL (``nogil=True``). They import
nothing from the package but ``_jit``; only ``core.method`` imports them. numba's disk cache is
keyed by each kernel's own file: after editing a kernel that others call, clear
``__pycache__`` (or touch the callers) so that no stale compiled caller is loaded.
"""
