"""Bias learning at rest in the node: the ``rest_bias_file`` and the ``~/learn_bias_now`` service.

The learned constant bias (deg/h per axis) is read from the file at start / configure, if it was
learned with the same coefficients and Earth rate, and written on shutdown, deactivate, cleanup
and after a "learn now" window; the service arms one window learned without the rest checks.
"""

from __future__ import annotations

import os
import sys
from typing import Any

from std_srvs.srv import Trigger

from fog_temp_comp.core.restfile import (
    LearnedBiasError,
    check_learned_bias,
    file_sha256,
    learned_bias_from_status,
    read_learned_bias,
    write_learned_bias,
)
from fog_temp_comp.ros.node_parameters import ParametersMixin, resolve_path


class BiasLearningMixin(ParametersMixin):
    """The learned-bias file and "learn now" of :class:`CompensatorShell` (a Node mixin)."""

    #: gyro messages are corrected and published only while this is set (lifecycle: active)
    output_enabled: bool
    #: what happened to ``rest_bias_file`` (loaded, refused and why, written, ...)
    _rest_bias_state: str
    _forced_seen: int
    _forced_outcome_seen: str

    # ------------------------------------------------------------------ learned bias file
    def _load_learned_bias(self) -> None:
        """Start the bias learner from ``rest_bias_file`` if it holds a value for this model."""
        path = self.config.rest_bias_file
        self._rest_bias_state = ''
        self._forced_seen = 0
        self._forced_outcome_seen = ''
        rest = self.compensator.rest
        if rest is None or not path:
            return
        log = self.get_logger()
        if not os.path.exists(path):
            self._rest_bias_state = 'absent: starting from zero'
            log.info(f'rest_bias_file {path} does not exist yet: starting from zero')
            return
        try:
            bias = read_learned_bias(path)
            check_learned_bias(
                bias,
                coefficients_sha256=self._coefficients_sha256(),
                earth_rate_body_deg_h=self.config.rest.earth_rate_body_deg_h,
                path=path,
            )
        except (LearnedBiasError, OSError) as err:
            self._rest_bias_state = f'refused: {err}'
            log.warning(f'rest_bias_file not used, starting from zero: {err}')
            return
        reason = rest.start_from(bias.bias_deg_h)
        if reason is not None:
            self._rest_bias_state = f'refused: {reason}'
            log.warning(f'rest_bias_file {path}: {reason}; starting from zero')
            return
        text = ', '.join(f'{v:.3f}' for v in bias.bias_deg_h)
        self._rest_bias_state = f'loaded: {text} deg/h (x, y, z)'
        log.info(
            f'rest_bias_file {path}: starting from the learned bias {text} deg/h (x, y, z), '
            f'{bias.windows} windows at {bias.temperature_degC:.2f} degC'
        )

    def _coefficients_sha256(self) -> str:
        return file_sha256(resolve_path(self.config.coefficients_file))

    def save_learned_bias(self, why: str) -> bool:
        """Write what was learned in this run to ``rest_bias_file``; whether a file was written.

        Nothing is written without a file, without learning, or before a window was learned
        in this run (the file keeps the last turn-on's value). An error is logged, not raised.
        """
        rest = self.compensator.rest if self.configured else None
        path = self.config.rest_bias_file if self.configured else ''
        if rest is None or not path:
            return False
        try:
            bias = learned_bias_from_status(
                rest.finish(),
                self.config.rest,
                coefficients_file=self.config.coefficients_file,
                coefficients_sha256=self._coefficients_sha256(),
            )
            if bias is None:
                return False
            write_learned_bias(path, bias)
        except OSError as err:
            self._rest_bias_state = f'write failed ({why}): {err}'
            self._say('error', f'rest_bias_file {path}: cannot write it ({why}): {err}')
            return False
        text = ', '.join(f'{v:.3f}' for v in bias.bias_deg_h)
        self._rest_bias_state = f'written ({why}): {text} deg/h (x, y, z)'
        self._say('info', f'rest_bias_file {path} written ({why}): {text} deg/h (x, y, z)')
        return True

    def _say(self, level: str, text: str) -> None:
        """Log ``text``; after Ctrl-C (rclpy shut down: no /rosout to log to) on stderr."""
        if self.context.ok():  # a call site per severity: rclpy refuses two at one
            if level == 'error':
                self.get_logger().error(text)
            else:
                self.get_logger().info(text)
        else:
            print(f'[{level.upper()}] [{self.get_name()}]: {text}', file=sys.stderr)

    def destroy_node(self) -> None:
        """Write the learned bias (shutdown), then destroy the node."""
        self.save_learned_bias('shutdown')
        super().destroy_node()

    # ------------------------------------------------------------------ learn now
    def _on_learn_now(self, request: Trigger.Request, response: Trigger.Response) -> Any:
        """``~/learn_bias_now``: accept the next rest window without the rest checks."""
        reason = self._learn_now_refusal()
        if reason:
            response.success = False
            response.message = reason
            return response
        rest = self.compensator.rest
        assert rest is not None
        rest.force_next_window()
        st = rest.finish()
        settings = self.config.rest
        so_far = ', '.join(f'{v:.3f}' for v in st.learned_deg_h)
        response.success = True
        response.message = (
            f'armed: the next {settings.window_s:g} s window is learned without the rest '
            f'checks, if its residual is within {settings.residual_limit_deg_h:g} deg/h '
            f'(rest_residual_limit_deg_h); learned so far {so_far} deg/h (x, y, z) from '
            f'{st.windows_rest} windows; the outcome is logged and in /diagnostics '
            '(rest_forced_outcome)'
        )
        self.get_logger().info(f'learn_bias_now: {response.message}')
        return response

    def _learn_now_refusal(self) -> str:
        """Why "learn now" cannot be armed ('' if it can)."""
        if not self.configured or self.compensator.rest is None:
            return 'not configured'
        if not self.output_enabled:
            return 'inactive: no gyro is processed; activate the node first'
        status = self.compensator.status
        if not status.has_temperature or not status.estimator_ready:
            return (
                'the Tdot filter is not warmed up yet: the drift-corrected rate the bias is '
                'learned from is not available; call again once diagnostics say filter_ready'
            )
        if status.temperature_stale:
            return 'temperature stale: the drift-corrected rate is not available'
        return ''

    def _check_forced_window(self) -> None:
        """Log and save once a "learn now" window has been judged (diagnostics timer)."""
        rest = self.compensator.rest
        if rest is None:
            return
        st = rest.status
        if st.forced_outcome and st.forced_outcome != self._forced_outcome_seen:
            self._forced_outcome_seen = st.forced_outcome
            log = self.get_logger()
            if st.windows_forced > self._forced_seen:
                log.info(f'learn_bias_now: {st.forced_outcome}')
                self.save_learned_bias('learn_bias_now')
            else:
                log.warning(f'learn_bias_now: {st.forced_outcome}')
        self._forced_seen = st.windows_forced
