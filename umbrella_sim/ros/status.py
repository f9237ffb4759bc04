# Copyright 2026 umbrella_sim developers
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""
umbrella_node's status on /diagnostics: its level, its message and its values (node_status).

What msg_docs/topic_diagnostics.md documents, read off the node: a fault or a stopped
recording (ERROR), a second simulator in the namespace, a lag past max(50 ms, two
publication periods), the run outside the model's validity (WARN), else its phase (OK).
"""
from __future__ import annotations

from diagnostic_msgs.msg import DiagnosticStatus

from .pacing import behind_text
from .ribs_messages import ribs_diagnostics
from ..core.step_rule import step_taken_now


def node_status(node, sim_t: float, measured: float, lag: float) -> tuple[int, str, dict]:
    """Return (level, message, values) of node's status at sim time sim_t (lag, measured: s)."""
    rtf = node.node_cfg['real_time_factor']
    if node.fault:
        level, message = DiagnosticStatus.ERROR, f'fault: {node.fault}'
    elif node.recording_error:
        level = DiagnosticStatus.ERROR
        message = f'recording stopped: {node.recording_error}'
    elif node._peers_warned:
        level, message = DiagnosticStatus.WARN, node._peers_warned
    elif rtf > 0 and lag > max(0.05, 2.0 / node.driver_rate):
        level, message = DiagnosticStatus.WARN, behind_text(lag, measured, rtf)
    elif node.driver.summary.warnings():
        level, message = DiagnosticStatus.WARN, "outside the model's validity: " + '; '.join(
            w.split(':')[0] for w in node.driver.summary.warnings())
    else:
        level, message = DiagnosticStatus.OK, node._phase
    values = {'sim_time_s': f'{sim_t:.6f}', 'measured_real_time_factor': f'{measured:.4f}',
              'requested_real_time_factor': rtf, 'lag_s': f'{max(lag, 0.0):.6f}',
              'max_lag_s': f'{max(node.pacer.max_lag, 0.0):.6f}',
              'phase': node._phase, 'paused': node.paused,
              'accepted_commands': node.commands.accepted,
              'refused_commands': node.commands.refused, 'steps': node.sim.steps,
              'lockstep': node.node_cfg['lockstep'],
              'waiting_for_command': bool(node.lockstep.waiting_since),
              'lockstep_waits': node.lockstep.waits,
              'physics_step_s': step_taken_now(node.sim),
              'grid_step_s': node.sim.h, 'slip_s': f'{node.pacer.slip:.6f}',
              're_anchors': node.pacer.re_anchors,
              'refused_not_recorded': node.commands.refused_not_recorded,
              'clock_publishers': getattr(node, 'clock_publishers', 1),
              'recording': ('off' if node.recording is None else
                            f'stopped: {node.recording_error}' if node.recording_error
                            else 'ok')}
    for i, text in enumerate(node.driver.summary.warnings()):
        values[f'warning_{i}'] = text
    values.update(ribs_diagnostics(node.driver.summary.figures(stage2=False))
                  if node.ribs > 1 else {})
    return level, message, values
