"""The node's process: start-up, spin thread and shut-down (process), memory figures and
trimming (memory), the long-lived heap frozen for the garbage collector (collector), read-only
parameters in ``ros2 param load`` (read_only), and the only uses of private rclpy API
(rclpy_private)."""
