"""The stiffness of a recording made at the node's default publish_rate (100 Hz).

A Grasp goal closes in force mode and loads the apple within a few milliseconds: at
100 Hz the loading falls in one or two samples, whatever the sampling phase, and no
stiffness can be estimated from it. ``analyze`` then says why in words (the loading's
samples and the recording's interval) instead of a bare n/a, and gives no secant that
would depend on where the samples fell. A loading that 100 Hz resolves (a squeeze in
position mode) gives the stiffness it gives at 1 kHz. The recordings are the node's
messages (``SimRecorder``), every step and every tenth step of one simulated run.
"""
from __future__ import annotations

from contextlib import ExitStack

import pytest

import rclpy  # noqa: F401
import gripper_sim_interfaces.msg  # noqa: F401

from gripper_sim.configuration import load_config  # noqa: E402
from gripper_sim.recording.analysis import analyze  # noqa: E402
from gripper_sim.recording.analysis.summary import describe  # noqa: E402
from gripper_sim.recording.offline import SimRecorder  # noqa: E402
from gripper_sim.workflows.factory import make_simulation  # noqa: E402
from gripper_sim.workflows.grasp import GraspSequence, run_grasp  # noqa: E402
from gripper_sim.workflows.scenario import grasp_height  # noqa: E402
from gripper_sim.workflows.squeeze import SQUEEZE_DEFAULTS, squeeze  # noqa: E402

pytestmark = pytest.mark.ros

#: record every STRIDE-th step: 100 Hz at the default 1 ms step
STRIDE = 10


def record_rates(folder, sim, run) -> tuple:
    """Record ``run(sim)`` at every step and at every ``STRIDE``-th step in each of the
    ``STRIDE`` phases; (the full-rate file, [the subsampled files])."""
    assert sim.dt == pytest.approx(1e-3)
    with ExitStack() as stack:
        full = folder / 'full.mcap'
        sim.add_observer(stack.enter_context(SimRecorder(full, sim.config,
                                                         initial=sim.last)).on_step)
        slow = [folder / f'phase{phase}.mcap' for phase in range(STRIDE)]
        for phase, path in enumerate(slow):
            rec = stack.enter_context(SimRecorder(path, sim.config, initial=sim.last))
            sim.add_observer(lambda r, rec=rec, phase=phase:
                             r.step % STRIDE == phase and rec.on_step(r))
        run(sim)
    return full, slow


def summary_of(path, tmp_path):
    return analyze(path, tmp_path / f'{path.stem}_analysis', figures=False,
                   html=False).summary


def test_a_grasp_at_100_hz_says_why_it_has_no_stiffness(tmp_path):
    base = load_config()
    sim = make_simulation(load_config(overrides={'gripper.initial_lift':
                                                 grasp_height(base)}))
    full, slow = record_rates(tmp_path, sim, lambda sim: run_grasp(
        sim, GraspSequence(sim, 3.0, None, 0.01, 0.05)))
    fast = summary_of(full, tmp_path)
    assert fast['stiffness_n_per_m'] > 0 and fast['secant_stiffness_n_per_m'] > 0
    assert fast['stiffness_note'] is None
    for path in slow:
        s = summary_of(path, tmp_path)
        assert s['samples'] < 0.15 * fast['samples']
        assert s['stiffness_n_per_m'] is None and s['secant_stiffness_n_per_m'] is None
        assert s['stiffness_fit_force_range_n'] is None
        note = s['stiffness_note']
        assert note.startswith('no stiffness: the loading') and 'one every 10 ms' in note
        assert '3 needed' in note and 'publish_rate' in note
        text = '\n'.join(describe({**s, 'fruit_state_topic': 'fs'}))
        line = text.index('n/a (tangent), n/a (secant)')
        assert text.index('no stiffness: the loading') > line, text


def test_a_squeeze_at_100_hz_has_the_stiffness_it_has_at_1_khz(tmp_path):
    sim = make_simulation(load_config(overrides=SQUEEZE_DEFAULTS))
    full, slow = record_rates(tmp_path, sim, lambda sim: squeeze(sim, 0.02, to_force=3.0))
    fast = summary_of(full, tmp_path)
    for path in slow:
        s = summary_of(path, tmp_path)
        assert s['stiffness_note'] is None
        assert s['stiffness_n_per_m'] == pytest.approx(fast['stiffness_n_per_m'], rel=0.02)
        # the chord starts at the first sample with both jaws on the fruit: up to a
        # sample interval (0.2 mm at this speed) into the loading
        assert s['secant_stiffness_n_per_m'] == pytest.approx(
            fast['secant_stiffness_n_per_m'], rel=0.06)
