"""ROS 2 conventions shared by every inflarm node (imports rclpy; the message core does not).

- :mod:`.qos`: QoS profiles named by meaning, and QoS event callbacks that log mismatches.
- :mod:`.parameters`: parameters declared from one table, with descriptors and ranges.
- :mod:`.spin`: the Jazzy ``main()``.
- :mod:`.conversions`: JSON messages to and from ``std_msgs/String``.
"""
