"""The rclpy halves of inflarm_bringup's tools (imported only when they run)."""
