"""The robot the node serves: built from its parameters or /robot_description (bundle), and
the parameter group that rebuilds it (group)."""
