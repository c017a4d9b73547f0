"""The compiled path of the method: numba kernels on plain arrays, split by concern.

``kinematics`` (forward kinematics, tip Jacobian, integrate / difference of configurations),
``lie_group`` (Pinocchio's log3 / log6 / Jlog6 / exp3), ``linalg`` (LU solve, damped
least-squares step), ``ik`` (pose and trajectory IK), ``effective_mass`` (translational
mobility), ``grasp`` (the fused kernel: IK and effective mass of a batch of grasps along
the object's motion, sampled once by the caller, so every trajectory type runs compiled),
``terms`` (the per-(grasp, sample) terms the analyses share), ``effort`` (joint velocities,
accelerations and torques of a batch of grasps along their joint paths), ``points`` (the
analyses' effective masses at points fixed to the tip or to the links, over (grasp, sample,
point), and the joint velocities that make the tip follow its twist) and ``uncertainty``
(effective masses of a batch of grasps over a set of object inertias). They
mirror the Pinocchio-based Python loops of ``core.method`` operation for operation, so
per-sample results equal the Python path's to rounding, for serial chains of revolute,
continuous ((cos, sin) in q, as Pinocchio) and prismatic joints. Their inputs come packed,
one value each, as ``core.method`` builds them: the chain (``ChainArrays``), the IK settings
(``IKSettings``), the body inertias (``BodyInertias``), the object's motion
(``ObjectMotion``) and the buffers (``GraspBuffers``), with a workspace of scratch arrays
(``ik.workspace``): they allocate nothing, so they run without numba's reference counting
(``_jit``). They import nothing from the package but ``_jit``; only ``core.method`` imports
them. They release the GIL (``nogil=True``).

numba's disk cache holds one folder per digest of all kernel sources, shared by the checkouts
of a machine (``_jit``): an edit of any kernel file compiles afresh (numba itself watches only a
function's own file, yet the kernels call each other across files), and a second checkout of
the same sources loads the first one's compiled kernels. ``make setup`` runs the warm-up when a
kernel file changes, so compiling happens there, not at the first request.
"""
