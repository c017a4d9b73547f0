"""The paper's method (Mavrakis et al., IROS 2017): tip IK along the trajectory (``ik``), the
effective mass of robot + object (``effective_mass``) and the evaluation and ranking of grasps
(``ranking``); ``compiled`` bridges them to ``core.kernels``, ``pool`` shares large requests
out over workers and ``warm_up`` compiles the kernels ahead of the first request."""
