"""ROS 2 managed (lifecycle) node ``compensator_lifecycle``, for lifecycle managers.

The same glue as :class:`fog_temp_comp.ros.node.CompensatorNode` (:class:`CompensatorShell`:
parameters, topics, diagnostics), driven by the lifecycle transitions instead of the constructor:

- **configure** loads and validates the coefficients and builds the compensator, subscriptions
  and publishers; a bad coefficients file (or filter parameter) fails the transition, the node
  stays *unconfigured* and the reason is logged;
- **activate** enables the corrected output (a lifecycle publisher on ``imu/data``);
- **deactivate** stops the output; the compensator is kept, and temperature keeps feeding the
  Tdot filter, so re-activation resumes warm (no new warm-up) with the bias learned at rest;
- **cleanup** releases the compensator, subscriptions and publishers (back to unconfigured);
- **shutdown** releases them too.

With ``rest_learning`` and ``rest_bias_file``, the learned bias is read at configure and written
at deactivate, cleanup and shutdown (and after a ``~/learn_bias_now`` window).

``/diagnostics`` is a plain publisher, published while configured (active or not).
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from typing import Any

from rclpy.lifecycle import LifecycleNode, LifecyclePublisher, State, TransitionCallbackReturn
from rclpy.lifecycle.node import LifecycleNodeMixin
from rclpy.publisher import Publisher

from fog_temp_comp.core.coefficients import CoefficientsError
from fog_temp_comp.ros.compensator_shell import CompensatorShell
from fog_temp_comp.ros.rclpy_compat import RCLError
from fog_temp_comp.ros.spin import run

#: rclpy's own transition step (a private method, present in Humble and Jazzy)
_RCLPY_CHANGE_STATE = LifecycleNodeMixin._LifecycleNodeMixin__change_state  # type: ignore[attr-defined]


class CompensatorLifecycleNode(CompensatorShell, LifecycleNode):
    """Managed compensator: unconfigured at construction, publishing only while active."""

    def __init__(
        self,
        node_name: str = 'fog_temp_compensator',
        *,
        params_file_paths: Sequence[str] = (),
        **kwargs: Any,
    ) -> None:
        super().__init__(node_name, **kwargs)
        self._setup_parameters(params_file_paths, kwargs.get('cli_args'))
        self.output_enabled = False

    def on_configure(self, state: State) -> TransitionCallbackReturn:
        """Load and validate the coefficients; create the topics (output still disabled)."""
        try:
            self._configure()
        except (CoefficientsError, ValueError, TypeError) as err:
            self._forget_compensator()
            self.get_logger().error(f'configure failed, staying unconfigured: {err}')
            return TransitionCallbackReturn.FAILURE
        self._create_io()
        self._log_config('configured')
        return TransitionCallbackReturn.SUCCESS

    def _create_output(self, *args: Any, **kwargs: Any) -> Publisher:
        """``imu/data`` as a lifecycle publisher: silent unless active."""
        return self.create_lifecycle_publisher(*args, **kwargs)

    def _destroy_output(self, publisher: Publisher) -> None:
        assert isinstance(publisher, LifecyclePublisher)
        self.destroy_lifecycle_publisher(publisher)

    def on_activate(self, state: State) -> TransitionCallbackReturn:
        """Start publishing corrected gyro rates."""
        self.output_enabled = True
        return super().on_activate(state)

    def on_deactivate(self, state: State) -> TransitionCallbackReturn:
        """Stop the output; keep the compensator (Tdot filter state) and temperature input."""
        self.output_enabled = False
        self.save_learned_bias('deactivate')
        return super().on_deactivate(state)

    def on_cleanup(self, state: State) -> TransitionCallbackReturn:
        """Write the learned bias; release the compensator, subscriptions and publishers."""
        self.save_learned_bias('cleanup')
        self._release()
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: State) -> TransitionCallbackReturn:
        """Write the learned bias; release everything from any primary state."""
        self.save_learned_bias('shutdown')
        self._release()
        return TransitionCallbackReturn.SUCCESS

    def _LifecycleNodeMixin__change_state(self, transition_id: int) -> TransitionCallbackReturn:
        """A transition the current state has not (ACTIVATE while unconfigured) fails, logged.

        rclpy before ros2/rclpy#1319 (Humble, the Jazzy wheels) lets rcl's "Transition is not
        registered" escape the change_state service callback and stop the node; rclcpp and
        newer rclpy answer ``success: False`` and stay in the current state, as this does.
        """
        try:
            return _RCLPY_CHANGE_STATE(self, transition_id)
        except RCLError as err:
            label = self._state_machine.current_state[1]
            self.get_logger().error(
                f'transition {transition_id} is not available from state {label!r}: '
                f'{str(err).splitlines()[0]}'
            )
            return TransitionCallbackReturn.FAILURE

    def _release(self) -> None:
        self.output_enabled = False
        if self.configured:
            self._destroy_io()
        self._forget_compensator()


def main(args: Sequence[str] | None = None) -> int:
    """Entry point of ``ros2 run fog_temp_comp compensator_lifecycle``."""
    return run(CompensatorLifecycleNode, args, about=__doc__ or '')


if __name__ == '__main__':
    sys.exit(main())
