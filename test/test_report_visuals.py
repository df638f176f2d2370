"""What the figures and HTML reports show: titles, panels, lines, labels, page settings.

Asserts on the figures' data (plotly JSON, page text), not on pixels. The runs are made
up (a ramped grip, then a lift or none), so no simulation is needed.
"""
from __future__ import annotations

import json
import re

import numpy as np
import pytest

from gripper_sim.recording.analysis.events import find_events
from gripper_sim.recording.analysis.report_html import (compression_figure,
                                                        write_window_report,
                                                        summary_rows, time_figure,
                                                        write_grasp_report)
from gripper_sim.recording.analysis.series import COLUMNS, TimeSeries
from gripper_sim.recording.analysis.summary import summarize

BRUISE = 260e3


def made_run(lifted: bool, n: int = 300) -> TimeSeries:
    """A 2D run: the jaws close, touch at row 60, squeeze to 10 N by row 150, then (when
    ``lifted``) the gripper rises 20 mm over rows 180-240 and holds."""
    rows = np.arange(n)
    columns = {name: np.zeros(n) for name in COLUMNS}
    columns['time_s'] = 0.01 * rows
    columns['dimension'][:] = 2
    touching = rows >= 60
    loading = np.clip((rows - 60) / 90.0, 0.0, 1.0)
    force = 10.0 * loading ** 1.3
    columns['grip_force_n'] = force
    columns['left_force_n'] = force
    columns['right_force_n'] = force
    columns['compression_m'] = 4e-3 * loading
    columns['gap_m'] = 0.08 - 0.02 * np.clip(rows / 60.0, 0, 1) - 4e-3 * loading
    columns['left_jaw_contact'] = touching.astype(float)
    columns['right_jaw_contact'] = touching.astype(float)
    columns['slip_distance_m'] = 1e-5 * loading
    columns['lift_m'] = (0.02 * np.clip((rows - 180) / 60.0, 0, 1) if lifted
                         else np.zeros(n)) + 0.03
    return TimeSeries(columns=columns, log_times=rows * 10_000_000,
                      stamps=rows * 10_000_000)


def report_summary(series: TimeSeries, finger: str | None = 'fin_ray') -> dict:
    """The summary ``analyze`` gives the report: the file's header and the numbers."""
    return {'file': 'run.mcap', 'fruit': 'apple', 'finger': finger,
            **summarize(series, bruise_pressure=BRUISE)}


def page_title(path) -> str:
    return re.search(r'<title>([^<]*)</title>', path.read_text()).group(1)


def page_figures(path) -> list[dict]:
    """The plotly figures of a page (the JSON of each ``Plotly.newPlot`` call)."""
    text = path.read_text()
    figures = []
    for match in re.finditer(r'Plotly\.newPlot\(\s*"[^"]+",\s*', text):
        data, end = json.JSONDecoder().raw_decode(text, match.end())
        layout, _ = json.JSONDecoder().raw_decode(text, end + text[end:].index('{'))
        figures.append({'data': data, 'layout': layout})
    return figures


# ---------------------------------------------------------------- grasp report
@pytest.mark.parametrize('finger', ['fin_ray', 'solid_pad'])
def test_the_grasp_report_names_the_finger(tmp_path, finger):
    series = made_run(lifted=True)
    path = write_grasp_report(series, report_summary(series, finger), [],
                              tmp_path / 'r.html')
    assert page_title(path) == f'Grasp of apple (2D) with the {finger} finger: held'
    assert ('finger', finger) in summary_rows(report_summary(series, finger))


def test_a_squeeze_report_is_titled_a_squeeze_and_has_no_slip_panel(tmp_path):
    series = made_run(lifted=False)
    summary = report_summary(series, 'flat')
    path = write_grasp_report(series, summary, [], tmp_path / 'r.html')
    assert page_title(path) == 'Squeeze of apple (2D) with the flat finger to 10 N'
    assert dict(summary_rows(summary))['held / slipped / dropped'].startswith(
        'n/a / n/a / n/a')
    fig = time_figure(series, summary, find_events(series))
    axis_titles = [fig.layout[name].title.text for name in fig.layout
                   if name.startswith('yaxis')]
    assert 'centroid drop (mm)' not in axis_titles
    assert not any('drop' in (trace.name or '') for trace in fig.data)
    assert not any('slip tolerance' in (a.text or '') for a in fig.layout.annotations)
    assert 'No slip panel' in path.read_text()


def test_a_lifted_run_keeps_its_slip_panel_and_its_dropped_flag():
    series = made_run(lifted=True)
    summary = report_summary(series)
    fig = time_figure(series, summary, find_events(series))
    assert any(fig.layout[name].title.text == 'centroid drop (mm)' for name in fig.layout
               if name.startswith('yaxis'))
    assert dict(summary_rows(summary))['held / slipped / dropped'] == \
        'True / False / False'


def test_phase_labels_sit_above_the_plot_area():
    series = made_run(lifted=True)
    summary = report_summary(series)
    fig = time_figure(series, summary, find_events(series))
    labels = [a for a in fig.layout.annotations if a.name == 'phase']
    assert [a.text for a in labels] == ['grip', 'lift-off', 'hold']
    for label in labels:
        # anchored by its bottom at the top of the plot area: it rises into the margin
        assert (label.yref, label.y, label.yanchor) == ('paper', 1.0, 'bottom')
    assert fig.layout.margin.t >= 60


def test_the_force_compression_plot_draws_the_secant():
    series = made_run(lifted=True)
    summary = report_summary(series)
    fig = compression_figure(series, summary, find_events(series))
    secant = [trace for trace in fig.data if trace.uid == 'secant']
    assert len(secant) == 1
    f_start, f_end = secant[0].y
    c_start, c_end = secant[0].x
    assert (f_end - f_start) / (c_end - c_start) * 1e3 == pytest.approx(
        summary['secant_stiffness_n_per_m'])
    assert f"{summary['secant_stiffness_n_per_m'] / 1e3:.2f} N/mm" in secant[0].name


# ---------------------------------------------------------------- window report
def made_window_dict() -> dict:
    """A window's ``as_dict`` with hold trials (dropped, held) and bruise trials (safe,
    bruised), not simulated: the report's input."""
    from dataclasses import replace

    from test_analysis_html import made_window
    return replace(made_window(), max_slip=1e-3).as_dict()


def test_the_window_report_says_safe_draws_its_limits_and_names_the_commanded_force(
        tmp_path):
    path = write_window_report(made_window_dict(), tmp_path / 'w.html',
                               bruise_pressure=260e3)
    fig = page_figures(path)[0]
    slip, damage = fig['data']
    words = dict(zip(damage['x'], damage['text']))
    assert words[4.0] == 'safe' and words[8.0] == 'bruised'
    assert words[1.0] == 'not bruised'             # a hold trial: its damage, not 'held'
    assert dict(zip(slip['x'], slip['text']))[1.0] == 'held'
    lines = {(shape['yref'], shape['y0']) for shape in fig['layout']['shapes']
             if shape['y0'] == shape['y1']}
    assert ('y', 1.0) in lines and ('y2', 260.0) in lines
    assert fig['layout']['xaxis2']['title']['text'] == 'commanded grip force (N)'
    assert slip['customdata'] == pytest.approx([1.01 * f for f in slip['x']])


# ---------------------------------------------------------------- study report
def made_study() -> tuple[dict, list[dict]]:
    """A study's summary and rows (two design points of four fruits), not computed."""
    axis = 'contact.jaw.static_friction'
    forces = [0.6, 1.0, 1.6, 2.2, 12.0, 18.0, 30.0]
    points = []
    for k, friction in enumerate((0.5, 0.8)):
        curve = dict(force=forces, p=[0, .25, .75, 1, 1, .5, 0],
                     lower=[0, 0, .2, .4, .4, 0, 0], upper=[.6, .8, 1, 1, 1, .9, .6])
        points.append(dict(index=k, label=f'{axis}={friction}', values={axis: friction},
                           population=dict(window=dict(low=2.1, high=13.0),
                                           ci=dict(low=[1.6, 2.5], high=[11.0, 18.0]),
                                           curve=curve)))
    rows = [dict(point=k, sample=s, kind='hold', outcome='held' if f > 1 else 'dropped',
                 force=f, **{axis: friction})
            for k, friction in enumerate((0.5, 0.8)) for s in range(4) for f in forces]
    summary = dict(study='small', axes=[axis, 'force'], population=dict(samples=4),
                   points=points, method='bisection', rows=len(rows), fraction=0.99,
                   confidence=0.9)
    return summary, rows


def test_the_study_report_reads_in_newtons_and_gives_each_panel_room(tmp_path):
    from gripper_sim.workflows.study_report import write_report
    summary, rows = made_study()
    write_report(summary, rows, tmp_path)
    path = tmp_path / 'report.html'
    assert page_title(path) == 'Study small'
    assert '"displaylogo": false' in path.read_text()
    layout = page_figures(path)[0]['layout']
    force_axes = [layout['yaxis'], layout['xaxis2'], layout['xaxis3']]
    for axis in force_axes:
        assert axis['type'] == 'log'
        assert set(axis['ticktext']) <= {'0.2', '0.5', '1', '2', '5', '10', '20', '50',
                                         '100'}
        assert len(axis['ticktext']) >= 3 and '10' in axis['ticktext']
    low, high = (10 ** v for v in layout['xaxis3']['range'])
    assert low < 0.9 * 1.6 and high > 1.1 * 18.0        # past the whiskers
    plot_height = layout['height'] - 160                  # less the margins, roughly
    for axis in ('yaxis', 'yaxis2', 'yaxis3'):
        span = layout[axis]['domain'][1] - layout[axis]['domain'][0]
        assert span * plot_height >= 250, axis


# ---------------------------------------------------------------- calibration
def made_fit():
    from gripper_sim.workflows.calibrate_data import CompressionCurve
    from gripper_sim.workflows.calibrate_fit import FitResult, FittedKey
    from gripper_sim.workflows.calibrate_model import SimulatedCurve
    d = np.linspace(0.0, 6e-3, 13)
    measured = CompressionCurve(d, 1.5e6 * d ** 1.5, 5e-3, None, '')
    simulated = SimulatedCurve(d, 1.45e6 * d ** 1.5, np.zeros(13), np.zeros(13, bool))
    key = FittedKey('fruit.flesh.youngs_modulus', 9.971e5, 0.015 * 9.971e5, 8.9e5, False)
    return FitResult((key,), {}, simulated, simulated, measured, 1.7, 3.4, np.eye(1), (),
                     9)


def test_the_calibration_figures_give_the_unit_and_the_standard_error(tmp_path):
    from gripper_sim.workflows.calibrate_plots import _title, plot_html
    result = made_fit()
    assert 'flesh.youngs_modulus = 9.971e+05 Pa +/- 1.5%' in _title(result, 'my_peach')
    plot_html(result, tmp_path / 'my_peach.html', 'my_peach')
    path = tmp_path / 'my_peach.html'
    assert page_title(path) == 'Calibration of my_peach'
    assert '"displaylogo": false' in path.read_text()
    assert 'Pa +/- 1.5%' in page_figures(path)[0]['layout']['title']['text']
