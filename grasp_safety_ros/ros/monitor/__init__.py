"""The live speed-scaling monitor: node (wiring, main), governor (decisions), joint_states,
parameters, messages."""
