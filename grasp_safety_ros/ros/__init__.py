"""ROS 2 adapter of the core: message conversions, node parameters and the node."""
