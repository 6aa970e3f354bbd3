"""The ROS 2 glue: the ``compensator`` node and its diagnostics.

Converts messages and parameters and calls :class:`~fog_temp_comp.core.compensator.Compensator`;
no signal processing of its own.

May import: ``fog_temp_comp.core`` and ``fog_temp_comp.ros`` (and rclpy and the ROS messages).
"""
