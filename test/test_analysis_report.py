"""The analysis of real recorded runs: figures that say what they show, stiffness from the
loading part, the node's own held/slipped, one analysis per run across resets.

Each expectation comes from the simulation that made the recording (the grasp state
machine's phases and result, the step results), never from hard-coded outputs.
"""
from __future__ import annotations

import re

import numpy as np
import pytest

import rclpy  # noqa: F401
import gripper_sim_interfaces.msg  # noqa: F401

from gripper_sim.configuration import load_config  # noqa: E402
from gripper_sim.convert import messages  # noqa: E402
from gripper_sim.recording.analysis import analyze, read_time_series, split_runs  # noqa: E402
from gripper_sim.recording.analysis import figures  # noqa: E402
from gripper_sim.recording.analysis.events import find_events, key_moments  # noqa: E402
from gripper_sim.recording.analysis.frames import pressure_from_colours  # noqa: E402
from gripper_sim.recording.analysis.outputs import run_frames  # noqa: E402
from gripper_sim.recording.analysis.series import find_topics  # noqa: E402
from gripper_sim.recording.analysis.summary import summarize  # noqa: E402
from gripper_sim.recording.offline import SimRecorder  # noqa: E402
from gripper_sim.recording.reader import BagReader  # noqa: E402
from gripper_sim.workflows.factory import make_simulation  # noqa: E402
from gripper_sim.workflows.grasp import (CLOSING, HOLDING, LIFTING, GraspSequence,  # noqa: E402
                                         run_grasp)
from gripper_sim.workflows.scenario import grasp_height  # noqa: E402

pytestmark = pytest.mark.ros

LIFT = 0.03


def recorded_pick(path, force: float, hold: float = 0.3, overrides: dict | None = None,
                  release: bool = False):
    """A pick (close, settle, lift LIFT, hold, and with ``release`` lower and open) of
    the default fruit recorded at every step as the node would publish it; (grasp
    summary, [(step result, phase)])."""
    base = load_config(overrides=overrides or {})
    config = load_config(overrides={**(overrides or {}),
                                    'gripper.initial_lift': grasp_height(base)})
    sim = make_simulation(config)
    steps = []
    with SimRecorder(path, sim.config, initial=sim.last) as rec:
        sim.add_observer(rec.on_step)
        sequence = GraspSequence(sim, force, None, LIFT, hold, release=release)
        summary = run_grasp(sim, sequence, on_step=lambda r, phase: steps.append((r, phase)))
    return summary, steps


@pytest.fixture(scope='module')
def held_pick(tmp_path_factory):
    path = tmp_path_factory.mktemp('held') / 'held.mcap'
    summary, steps = recorded_pick(path, 3.0)
    assert summary['outcome'] == 'held'
    return path, summary, steps


@pytest.fixture(scope='module')
def released_pick(tmp_path_factory):
    """A held pick that lowers the fruit back and opens the jaws, as a Grasp goal with
    release does."""
    path = tmp_path_factory.mktemp('released') / 'released.mcap'
    summary, steps = recorded_pick(path, 3.0, hold=0.1, release=True)
    assert summary['outcome'] == 'held' and steps[-1][1] == 'done'
    return path, summary, steps


@pytest.fixture(scope='module')
def slipped_pick(tmp_path_factory):
    """A grip too weak to lift the fruit: it stays on the table as the jaws rise,
    'dropped' (as in ``run``), and slipped."""
    path = tmp_path_factory.mktemp('slipped') / 'slipped.mcap'
    summary, steps = recorded_pick(path, 0.5, hold=0.2)
    assert summary['outcome'] == 'dropped' and summary['slipped']
    return path, summary, steps


def load_run(path):
    """(series, summary, frames of the key moments) of the single run in ``path``."""
    with BagReader(path) as bag:
        topics = find_topics(bag)
        runs = split_runs(read_time_series(bag, topics))
        assert len(runs) == 1
        series = runs[0]
        bruise = float(load_config()['fruit.bruise_pressure'])
        summary = summarize(series, bruise_pressure=bruise)
        frames = run_frames(bag, topics['markers'], series,
                            key_moments(series, find_events(series)), bruise)
    return series, summary, frames


# ---------------------------------------------------------------------- held / slipped
def centroid_slip_held(steps) -> float:
    """m, the centroid's slip relative to the jaws (``StepResult.slip_distance``) at the
    step that ended the hold (or the drop): the first after the lift-off in no lifted
    phase."""
    lifted = (LIFTING, HOLDING)
    start = next(i for i, (_r, phase) in enumerate(steps) if phase == LIFTING)
    return next(r.slip_distance for r, phase in steps[start:] if phase not in lifted)


def test_held_and_slipped_are_the_grasp_results_own(held_pick, slipped_pick, released_pick,
                                                     tmp_path):
    """One definition (gripper_sim.core.slip): the analysis of the recording says what
    the grasp state machine (the node's Grasp result) said; the steps the simulation
    flags as sliding agree (the held fruit sags in the jaws without sliding). The slip
    it judges on is the one a recording carries, the centroid's at the end of the hold
    (``FruitState.slip_distance``); the grasp judges on its contacts' slide, which a
    recording does not carry."""
    for path, grasp, steps in (held_pick, slipped_pick, released_pick):
        s = analyze(path, tmp_path / path.stem, figures=False).summary
        assert s['slipped'] == grasp['slipped']
        assert s['dropped'] == grasp['dropped']
        assert s['held'] == (grasp['outcome'] == 'held')
        assert s['held_slip_distance_m'] == pytest.approx(centroid_slip_held(steps),
                                                          abs=1e-9)
    path, _grasp, steps = released_pick
    lowering = next(r.time for r, phase in steps if phase == 'releasing')
    release = analyze(path, tmp_path / 'events', figures=False).summary['event_times_s']
    assert lowering < release['release'] < release['let go']
    assert not any(r.slipping for r, _phase in held_pick[2])
    assert any(r.slipping for r, _phase in slipped_pick[2])


# ---------------------------------------------------------------------- stiffness
def test_stiffness_of_a_grasp_with_a_lift_is_fitted_on_the_loading_only(held_pick, tmp_path):
    path, _grasp, steps = held_pick
    # the loading part as the state machine saw it: closing, both jaws on the fruit
    loading = [r for r, phase in steps if phase == CLOSING and r.in_contact_with('left_jaw')
               and r.in_contact_with('right_jaw')]
    force = np.array([r.grip_force for r in loading])
    compression = np.array([r.deformation.compression for r in loading])
    upper = force >= 0.2 * force.max()
    loading_only = np.polyfit(compression[upper], force[upper], 1)[0]
    s = analyze(path, tmp_path / 'a', figures=False).summary
    assert s['stiffness_n_per_m'] == pytest.approx(loading_only, rel=0.05)
    lift_off = next(r.time for r, phase in steps if phase == LIFTING)
    t_lo, t_hi = s['stiffness_fit_time_range_s']
    assert loading[0].time <= t_lo < t_hi < lift_off
    f_lo, f_hi = s['stiffness_fit_force_range_n']
    plateau = max(r.grip_force for r, phase in steps if r.time < lift_off)
    assert 0 < f_lo < 0.9 * force.max() < f_hi < plateau


# ---------------------------------------------------------------------- figures
def _numbers(text: str) -> list[float]:
    return [float(v) for v in re.findall(r'-?\d+\.\d+', text)]


def test_outline_snapshots_title_and_colour_bar_name_one_quantity(held_pick):
    series, summary, frames = load_run(held_pick[0])
    fig = figures.outline_snapshots(series, frames, summary)
    name = figures.pressure_name(2)
    pressure_axes = [ax for ax in fig.axes if any(c.get_gid() == 'fruit pressure'
                                                  for c in ax.collections)]
    assert len(pressure_axes) == len(frames) >= 3
    bars = [ax for ax in fig.axes if name in ax.get_ylabel()]
    assert len(bars) == 1, 'one pressure colour bar, named as the titles'
    for ax, frame in zip(pressure_axes, frames):
        assert name in ax.get_title()
        drawn = next(c for c in ax.collections if c.get_gid() == 'fruit pressure')
        shown = float(np.max(drawn.get_array()))
        assert _numbers(ax.get_title())[-1] == pytest.approx(shown, abs=0.05)
        assert shown == pytest.approx(np.nanmax(frame.pressure) / 1e3, abs=1e-9)


def test_outline_snapshots_draw_jaws_and_table_where_they_were(held_pick, slipped_pick):
    """The held fruit is up in the jaws at the end; the one that stayed on the table is
    drawn on the table with the jaws above it."""
    ends = {}
    for name, (path, _grasp, steps) in (('held', held_pick), ('slipped', slipped_pick)):
        series, summary, frames = load_run(path)
        fig = figures.outline_snapshots(series, frames, summary)
        end_ax = [ax for ax in fig.axes if any(c.get_gid() == 'fruit pressure'
                                               for c in ax.collections)][-1]
        jaws = [p for p in end_ax.patches if p.get_gid() == 'jaw']
        table = [p for p in end_ax.patches if p.get_gid() == 'table']
        assert len(jaws) == 2 and len(table) == 1
        last = steps[-1][0]
        for jaw in jaws:   # drawn at the gripper's height (mm)
            centre = jaw.get_y() + 0.5 * jaw.get_height()
            assert centre == pytest.approx(1e3 * last.lift, abs=1e-3)
        table_top = table[0].get_y() + table[0].get_height()
        fruit_bottom = 1e3 * float(np.min(last.positions[:, 1]))
        assert fruit_bottom == pytest.approx(1e3 * frames[-1].points[:, 2].min(), abs=1e-3)
        ends[name] = fruit_bottom - table_top
    assert ends['slipped'] < 2.0            # left on the table
    assert ends['held'] > 0.8 * 1e3 * LIFT  # carried up


def test_force_vs_time_gap_on_its_own_axis_slip_visible_phases_marked(held_pick):
    path, _grasp, steps = held_pick
    series, summary, _frames = load_run(path)
    fig = figures.force_vs_time(series, summary, find_events(series))
    by_gid = {}
    for ax in fig.axes:
        for line in ax.lines:
            by_gid.setdefault(line.get_gid(), []).append(ax)
    gap_ax, slip_ax = by_gid['gap'][0], by_gid['slip'][0]
    assert gap_ax is not slip_ax and gap_ax is not by_gid['compression'][0]
    slip_mm = 1e3 * np.abs(series['slip_distance_m'])
    assert slip_ax.get_ylim()[1] <= 1.2 * max(slip_mm.max(), 1e3 * summary['slip_threshold_m'])
    lift_off = next(r.time for r, phase in steps if phase == LIFTING)
    marks = [line for line in slip_ax.lines if line.get_gid() == 'phase:lift-off']
    assert len(marks) == 1
    dt = steps[1][0].time - steps[0][0].time
    # the state machine commands the lift after a step; the lift rises in the next ones
    assert lift_off < marks[0].get_xdata()[0] <= lift_off + 3.5 * dt
    grip = next(line for line in slip_ax.lines if line.get_gid() == 'phase:grip')
    first_both = next(r.time for r, _ in steps if r.in_contact_with('left_jaw')
                      and r.in_contact_with('right_jaw'))
    assert grip.get_xdata()[0] == pytest.approx(first_both, abs=1e-9)


def test_marker_colours_give_back_the_pressure():
    bruise = 2.6e5
    pressure = np.linspace(0.0, bruise, 27)
    colours = [messages.pressure_colour(p, bruise) for p in pressure]
    rgb = np.array([[np.float32(c.r), np.float32(c.g), np.float32(c.b)] for c in colours])
    assert pressure_from_colours(rgb, bruise) == pytest.approx(pressure, abs=0.1)


# ---------------------------------------------------------------------- runs
def test_a_recording_with_a_reset_is_analysed_run_by_run(tmp_path):
    config = load_config(overrides={'world.gravity': 0.0, 'world.table': False})
    sim = make_simulation(config)
    path = tmp_path / 'reset.mcap'
    lengths = []
    with SimRecorder(path, sim.config, initial=sim.last) as rec:
        sim.add_observer(rec.on_step)
        for target in (2.0, 3.0):
            sim.command_force(target)
            while sim.last.grip_force < 0.9 * target:
                sim.step()
            lengths.append(sim.time)
            if target == 2.0:
                sim.reset()
                rec.reset()
                rec.write_result(sim.last)
    result = analyze(path, tmp_path / 'out')
    assert len(result.runs) == 2
    for run, length in zip(result.runs, lengths):
        assert run['start_time_s'] == 0.0
        assert run['duration_s'] == pytest.approx(length, abs=1e-9)
    assert result.runs[1]['peak_grip_force_n'] >= 0.9 * 3.0 > result.runs[0]['peak_grip_force_n']
    for k in (1, 2):
        run_dir = tmp_path / 'out' / f'run_{k}'
        times = np.loadtxt(run_dir / 'timeseries.csv', delimiter=',', skiprows=1,
                           usecols=0)
        assert times[0] == 0.0 and np.all(np.diff(times) > 0)
        assert (run_dir / 'force_vs_time.png').is_file()
        assert (run_dir / 'report.html').is_file()
    assert [r['run'] for r in result.summary['runs']] == [1, 2]
    index = (tmp_path / 'out' / 'report.html').read_text()
    assert 'href="run_1/report.html"' in index and 'href="run_2/report.html"' in index
