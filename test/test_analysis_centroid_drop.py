"""analyze judges held/slipped on the recorded centroid drop (a recording has no contact
slide, which pick and run judge on) and names the figure so in its text and report."""
from __future__ import annotations

from gripper_sim.recording.analysis.summary import held_line


def fmt(value, unit, scale=1.0, digits=3):
    return 'n/a' if value is None else f'{value * scale:.{digits}f} {unit}'


def lifted_summary(**changes) -> dict:
    summary = {'gripped': True, 'held': True, 'slipped': False, 'dropped': False,
               'held_slip_distance_m': 1.33e-4, 'max_slip_distance_m': 2e-4}
    summary.update(changes)
    return summary


def test_the_held_line_names_the_centroid_drop_and_what_pick_judges_on():
    line = held_line(lifted_summary(), fmt)
    assert line.startswith('held: True   slipped: False (centroid drop at the end of the '
                           'hold 0.133 mm, largest 0.200 mm)'), line
    assert 'contact slide' in line and 'pick and run' in line
    assert 'slip at the end' not in line


def test_a_run_not_lifted_names_its_largest_centroid_drop():
    line = held_line(lifted_summary(held=None, slipped=None), fmt)
    assert 'largest centroid drop 0.200 mm' in line, line
