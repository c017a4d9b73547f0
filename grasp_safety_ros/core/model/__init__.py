"""The inputs of the method: the robot chain (``robot``), the grasped object's inertia
(``inertia``) and the object's post-grasp trajectory (``trajectory``)."""
