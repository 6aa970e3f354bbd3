"""The ROS 2 glue: the ``compensator`` node and its diagnostics.

Converts messages and parameters and calls :class:`~fog_temp_comp.core.compensator.Compensator`;
no signal processing of its own. ``node`` (the ``compensator`` executable) and
``lifecycle_node`` (``compensator_lifecycle``) run ``compensator_shell`` (topics, callbacks,
diagnostics) with its parts ``node_parameters`` (parameters and their checks),
``bias_learning`` (``rest_bias_file``, ``~/learn_bias_now``) and ``console_log``; ``params``,
``diagnostics`` and ``spin`` (executor, ``main``).

May import: ``fog_temp_comp.core`` and ``fog_temp_comp.ros`` (and rclpy and the ROS messages).
"""
