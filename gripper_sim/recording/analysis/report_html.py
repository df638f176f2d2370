"""Self-contained HTML reports (plotly, its JavaScript embedded: they open offline).

``write_html_report(path, title, blocks)`` is the one page writer: a list of blocks,
each a heading with either a plotly figure or a small table of (name, value) rows.
The analysis of a recording (``write_grasp_report``), the grasp window
(``write_window_report``) and a study can each build their blocks and call it.

The grasp report: the key numbers; force, gap, compression and slip over time with the
phases marked; force over compression with the stiffness fit; and an animation of the
fruit (2D outline, 3D skin) with a time slider, coloured by the contact pressure on a
stated scale, with the jaw plates and the table drawn and the phase named in each frame.
"""
from __future__ import annotations

import html
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import plotly.graph_objects as go
import plotly.io as pio
from plotly.subplots import make_subplots

from gripper_sim.recording.analysis.events import (Events, find_events, lift_never_moved,
                                                   phase_at)
from gripper_sim.recording.analysis.figures import (PRESSURE_COLOURS, contact_state,
                                                    pressure_name, pressure_scale)
from gripper_sim.recording.analysis.frames import Box, Frame
from gripper_sim.recording.analysis.series import TimeSeries
from gripper_sim.recording.analysis.summary import fit_stiffness, grasp_outcome
from gripper_sim.recording.errors import RecordingError
from gripper_sim.workflows.html_page import PLOTLY_CONFIG, PageWriteError, write_page

#: the element id of the fruit animation's plot, for scripts and tests
ANIMATION_ID = 'fruit-animation'


@dataclass(frozen=True)
class Block:
    """One part of a report page.

    Attributes:
        heading: the section title.
        figure: a plotly figure, or None.
        rows: (name, value) pairs shown as a table (after the figure, if both).
        text: a paragraph under the heading.
        div_id: the figure's element id (default: made up by plotly).
        links: (label, relative address) pairs shown as a list of links.
    """

    heading: str
    figure: go.Figure | None = None
    rows: Sequence[tuple[str, str]] = ()
    text: str = ''
    div_id: str | None = None
    links: Sequence[tuple[str, str]] = ()


_PAGE = """<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{title}</title>
<style>
body {{ font-family: sans-serif; margin: 1.5em auto; max-width: 1200px; color: #222; }}
h1 {{ font-size: 1.4em; }} h2 {{ font-size: 1.15em; margin-top: 1.6em; }}
table {{ border-collapse: collapse; margin: 0.5em 0; }}
td {{ border-bottom: 1px solid #ddd; padding: 0.2em 1em 0.2em 0; }}
p.note {{ color: #555; font-size: 0.9em; }}
</style></head><body>
<h1>{title}</h1>
{body}
</body></html>
"""


def write_html_report(path: str | Path, title: str, blocks: Sequence[Block]) -> Path:
    """Write one self-contained HTML page of ``blocks``: plotly's JavaScript is embedded
    once (no network needed to open it), each figure interactive.

    Raises:
        RecordingError: the file cannot be written.
    """
    parts: list[str] = []
    script_done = False
    for block in blocks:
        parts.append(f'<h2>{html.escape(block.heading)}</h2>')
        if block.text:
            parts.append(f'<p class="note">{html.escape(block.text)}</p>')
        if block.figure is not None:
            parts.append(pio.to_html(block.figure, full_html=False, auto_play=False,
                                     include_plotlyjs=not script_done, div_id=block.div_id,
                                     config=PLOTLY_CONFIG))
            script_done = True
        if block.rows:
            cells = ''.join(f'<tr><td>{html.escape(name)}</td><td>{html.escape(value)}'
                            '</td></tr>' for name, value in block.rows)
            parts.append(f'<table>{cells}</table>')
        if block.links:
            items = ''.join(f'<li><a href="{html.escape(href)}">{html.escape(label)}</a></li>'
                            for label, href in block.links)
            parts.append(f'<ul>{items}</ul>')
    return _write_page(path, _PAGE.format(title=html.escape(title), body='\n'.join(parts)))


def _write_page(path: str | Path, page: str) -> Path:
    """Write the HTML ``page`` to ``path``; RecordingError if it cannot be written."""
    try:
        return write_page(path, page)
    except PageWriteError as err:
        raise RecordingError(str(err)) from err


# ---------------------------------------------------------------------- grasp report
def _number(value: Any, unit: str, scale: float = 1.0, digits: int = 3) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return 'n/a'
    return f'{value * scale:.{digits}g} {unit}'


def _yes_no(value: bool | None) -> str:
    """A flag of the summary: True, False, or n/a when it was not judged (None)."""
    return 'n/a' if value is None else str(value)


def summary_rows(summary: dict) -> list[tuple[str, str]]:
    """The key numbers of a run's summary as (name, value) rows."""
    three_d = summary.get('dimension') == 3
    fit = summary.get('stiffness_fit_force_range_n')
    lifted = summary['held'] is not None
    dropped = summary.get('dropped', False) if lifted else None   # judged over the lift
    rows = [
        ('fruit', str(summary.get('fruit'))),
        *([('finger', str(summary['finger']))] if summary.get('finger') else []),
        ('model', f"{summary.get('dimension', 2)}D"),
        ('sim time', f"{summary['start_time_s']:.3f} to "
                     f"{summary['start_time_s'] + summary['duration_s']:.3f} s"),
        ('held / slipped / dropped', f"{_yes_no(summary['held'])} / "
                                     f"{_yes_no(summary['slipped'])} / "
                                     f"{_yes_no(dropped)}"
                                     + ('' if lifted
                                        else f' ({grasp_outcome(summary)})')),
        ('centroid drop at the end of the hold (what held is judged on; no contact slide '
         'in a recording)', _number(summary['held_slip_distance_m'], 'mm', 1e3)),
        ('peak grip force', _number(summary['peak_grip_force_n'], 'N')),
        ('peak compression', _number(summary['peak_compression_m'], 'mm', 1e3)),
        ('stiffness (tangent, secant)',
         f"{_number(summary['stiffness_n_per_m'], 'N/mm', 1e-3)}, "
         f"{_number(summary['secant_stiffness_n_per_m'], 'N/mm', 1e-3)}"
         + (f' (fitted on the loading only, {fit[0]:.2f}-{fit[1]:.2f} N)' if fit else '')
         + (f" ({summary['stiffness_note']})" if summary.get('stiffness_note') else '')),
        ('peak damage pressure', _number(summary['peak_damage_pressure_pa'], 'kPa', 1e-3)),
        ('bruise threshold', _number(summary['bruise_threshold_pa'], 'kPa', 1e-3)),
        ('bruised / crushed', f"{summary['bruised']} / {summary['crushed']}"),
    ]
    if three_d:
        rows.append(('contact area at peak force',
                     _number(summary['contact_area_at_peak_force_m2'], 'mm^2', 1e6)))
    else:
        rows.append(('contact length at peak force',
                     _number(summary['contact_length_at_peak_force_m'], 'mm', 1e3)))
    rows += [(f'phase: {label}', f'{time:.3f} s')
             for label, time in summary.get('event_times_s', {}).items()]
    return rows


#: px above the plot area of the time figure, where the phases are named
PHASE_LABEL_MARGIN = 70


def _phase_lines(fig: go.Figure, series: TimeSeries, events: Events) -> None:
    """A dashed line at each phase, its name written upwards above the plot area (clear
    of the curves, which may reach the top of the axes)."""
    t = series['time_s']
    for label, row in events.marked():
        fig.add_vline(x=float(t[row]), line_dash='dash', line_color='grey', line_width=1)
        fig.add_annotation(x=float(t[row]), y=1.0, yref='paper', text=label,
                           showarrow=False, textangle=-90, xanchor='center',
                           yanchor='bottom', yshift=2, font={'size': 10, 'color': 'grey'},
                           name='phase')


def time_figure(series: TimeSeries, summary: dict, events: Events) -> go.Figure:
    """Grip force (and per jaw), gap, compression and (for a lifted run) slip, each on its
    own axis; a run that never lifted has no slip panel (slip is judged over the lift)."""
    t = series['time_s']
    lifted = summary['held'] is not None
    rows = 4 if lifted else 3
    fig = make_subplots(rows=rows, cols=1, shared_xaxes=True, vertical_spacing=0.03,
                        row_heights=(0.34, 0.22, 0.22, 0.22)[:rows])
    fig.add_trace(go.Scatter(x=t, y=series['grip_force_n'], name='grip force (mean)',
                             line={'color': 'black'}), row=1, col=1)
    for side in ('left', 'right'):
        values = series[f'{side}_force_n']
        if np.any(np.isfinite(values)):
            fig.add_trace(go.Scatter(x=t, y=values, name=f'{side} jaw',
                                     line={'dash': 'dot', 'width': 1}), row=1, col=1)
    fig.add_trace(go.Scatter(x=t, y=1e3 * series['gap_m'], name='jaw gap (mm)'), row=2, col=1)
    fig.add_trace(go.Scatter(x=t, y=1e3 * series['compression_m'], name='compression (mm)'),
                  row=3, col=1)
    if lifted:
        fig.add_trace(go.Scatter(x=t, y=1e3 * series['slip_distance_m'],
                                 name='centroid drop in the jaws (mm)'), row=4, col=1)
        tolerance = 1e3 * summary['slip_threshold_m']
        fig.add_hline(y=tolerance, line_dash='dot', line_color='red', row=4, col=1,
                      annotation_text=f'slip tolerance {tolerance:g} mm')
    for row, label in enumerate(('normal force (N)', 'jaw gap (mm)', 'compression (mm)',
                                 'centroid drop (mm)')[:rows], start=1):
        fig.update_yaxes(title_text=label, row=row, col=1)
    fig.update_xaxes(title_text='sim time (s)', row=rows, col=1)
    _phase_lines(fig, series, events)
    fig.update_layout(height=820 if lifted else 640, margin={'t': PHASE_LABEL_MARGIN})
    return fig


def compression_figure(series: TimeSeries, summary: dict, events: Events) -> go.Figure:
    """Force over compression coloured by time, with the loading fit over its range."""
    fit = fit_stiffness(series, events)
    c_mm = 1e3 * series['compression_m']
    fig = go.Figure(go.Scatter(
        x=c_mm, y=series['grip_force_n'], mode='markers', name='samples',
        marker={'size': 4, 'color': series['time_s'], 'colorscale': 'Viridis',
                'colorbar': {'title': {'text': 'sim time (s)'}}}))
    if fit.tangent is not None:
        c = series['compression_m'][fit.rows]
        xs = np.linspace(c.min(), c.max(), 20)
        lo, hi = summary['stiffness_fit_force_range_n']
        fig.add_trace(go.Scatter(x=1e3 * xs, y=fit.tangent * xs + fit.intercept,
                                 mode='lines', line={'color': 'red'},
                                 name=f'tangent {fit.tangent / 1e3:.2f} N/mm '
                                      f'(loading, {lo:.2f}-{hi:.2f} N)'))
    if fit.secant is not None and fit.start is not None and fit.end is not None:
        ends = [fit.start, fit.end]
        fig.add_trace(go.Scatter(x=c_mm[ends], y=series['grip_force_n'][ends],
                                 mode='lines+markers', uid='secant',
                                 line={'color': 'purple', 'dash': 'dot'},
                                 marker={'symbol': 'diamond', 'size': 8},
                                 name=f'grip to end of loading: secant '
                                      f'{fit.secant / 1e3:.2f} N/mm'))
    fig.update_layout(xaxis_title='compression (mm)', yaxis_title='grip force (N)',
                      height=480, legend={'x': 0.01, 'y': 0.99})
    return fig


def _box_mesh(box: Box, name: str, colour: str, opacity: float) -> go.Mesh3d:
    low, high = (1e3 * v for v in box.bounds())
    x = [low[0], high[0], high[0], low[0], low[0], high[0], high[0], low[0]]
    y = [low[1], low[1], high[1], high[1], low[1], low[1], high[1], high[1]]
    z = [low[2], low[2], low[2], low[2], high[2], high[2], high[2], high[2]]
    i = [0, 0, 4, 4, 0, 0, 1, 1, 2, 2, 3, 3]
    j = [1, 2, 5, 6, 1, 5, 2, 6, 3, 7, 0, 4]
    k = [2, 3, 6, 7, 5, 4, 6, 5, 7, 6, 4, 7]
    return go.Mesh3d(x=x, y=y, z=z, i=i, j=j, k=k, color=colour, opacity=opacity, name=name,
                     hoverinfo='name', showscale=False)


def _rectangle(box: Box | None, name: str, colour: str) -> go.Scatter:
    if box is None:
        return go.Scatter(x=[], y=[], name=name, showlegend=False)
    low, high = (1e3 * v for v in box.bounds())
    return go.Scatter(x=[low[0], high[0], high[0], low[0], low[0]],
                      y=[low[2], low[2], high[2], high[2], low[2]], fill='toself',
                      mode='lines', line={'color': colour, 'width': 1}, fillcolor=colour,
                      opacity=0.7, name=name, hoverinfo='name', showlegend=False)


def _colour_bar(dimension: int, top: float, bruise: float) -> dict:
    name = pressure_name(dimension)
    ticks = list(np.linspace(0.0, top / 1e3, 5))
    labels = [f'{v:.0f}' for v in ticks]
    if bruise <= top * (1 + 1e-6):
        ticks.append(bruise / 1e3)
        labels.append(f'bruise {bruise / 1e3:.0f}')
        note = ''
    else:
        note = f'<br>bruise threshold {bruise / 1e3:.0f} kPa<br>is above this scale'
    return {'title': {'text': f'{name}<br>(kPa){note}', 'side': 'right'},
            'tickvals': ticks, 'ticktext': labels}


def _frame_traces(frame: Frame, dimension: int, top: float, bruise: float) -> list:
    """The traces of one frame: table, left and right jaw, (2D) the deformable fingers,
    fruit (in that order)."""
    pressure_kpa = np.nan_to_num(frame.pressure) / 1e3
    jaws = list(frame.jaws) + [None] * (2 - len(frame.jaws))
    if dimension == 3:
        scene: list = []
        if frame.table is not None:
            scene.append(_box_mesh(frame.table, 'table', 'sienna', 0.35))
        else:
            scene.append(go.Mesh3d(x=[], y=[], z=[], name='table'))
        for k, jaw in enumerate(jaws[:2]):
            scene.append(_box_mesh(jaw, ('left', 'right')[k] + ' jaw', 'slategrey', 0.3)
                         if jaw is not None else go.Mesh3d(x=[], y=[], z=[]))
        pts = 1e3 * frame.points
        tri = frame.triangles
        scene.append(go.Mesh3d(
            x=pts[:, 0], y=pts[:, 1], z=pts[:, 2], i=tri[:, 0], j=tri[:, 1], k=tri[:, 2],
            intensity=pressure_kpa, colorscale=PRESSURE_COLOURS, cmin=0.0, cmax=top / 1e3,
            colorbar=_colour_bar(3, top, bruise), name='fruit', flatshading=False,
            hovertemplate='p = %{intensity:.1f} kPa<extra>fruit</extra>'))
        return scene
    pts = 1e3 * frame.points
    return [
        _rectangle(frame.table, 'table', 'sienna'),
        _rectangle(jaws[0], 'left jaw', 'slategrey'),
        _rectangle(jaws[1], 'right jaw', 'slategrey'),
        _segments(frame.finger_lines, 'fingers', 'rgb(38,89,191)'),
        go.Scatter(x=pts[:, 0], y=pts[:, 2], mode='lines+markers', name='fruit',
                   line={'color': 'rgb(90,90,90)', 'width': 1.5},
                   marker={'size': 7, 'color': pressure_kpa, 'colorscale': PRESSURE_COLOURS,
                           'cmin': 0.0, 'cmax': top / 1e3,
                           'colorbar': _colour_bar(2, top, bruise)},
                   hovertemplate='p = %{marker.color:.1f} kPa<extra>fruit</extra>',
                   showlegend=False),
    ]


def _segments(lines: np.ndarray, name: str, colour: str) -> go.Scatter:
    """Line segments (s, 2, 3) m drawn in the x-z plane (mm), one trace (may be empty)."""
    xz = np.full((len(lines), 3, 2), np.nan)
    xz[:, :2] = 1e3 * lines[:, :, [0, 2]]
    return go.Scatter(x=xz[:, :, 0].ravel(), y=xz[:, :, 1].ravel(), mode='lines', name=name,
                      line={'color': colour, 'width': 2}, hoverinfo='skip', showlegend=False)


def _frame_title(series: TimeSeries, events: Events, frame: Frame, dimension: int) -> str:
    peak = float(np.nanmax(frame.pressure)) if np.any(np.isfinite(frame.pressure)) else 0.0
    moment = f' ({frame.label})' if frame.label else ''
    return (f't = {frame.time:.3f} s{moment}: {phase_at(events, frame.row)}, '
            f'{contact_state(series, frame.row)}, F = {series["grip_force_n"][frame.row]:.2f}'
            f' N, peak {pressure_name(dimension)} {peak / 1e3:.1f} kPa')


def animation_figure(series: TimeSeries, frames: list[Frame], summary: dict) -> go.Figure:
    """The fruit over time with a time slider and play/pause buttons (module docstring)."""
    dimension = series.dimension
    bruise = summary['bruise_threshold_pa']
    top = pressure_scale(frames, bruise)
    events = find_events(series)
    every = 1e3 * np.vstack([f.points for f in frames] +
                            [np.vstack(b.bounds()) for f in frames for b in f.jaws])
    low, high = every.min(axis=0), every.max(axis=0)
    pad = 0.08 * float(np.max(high - low) or 10.0)
    low, high = low - pad, high + pad
    low[2] = min(low[2], -3.0)
    plotly_frames = [go.Frame(data=_frame_traces(f, dimension, top, bruise), name=str(k),
                              layout={'title': {'text': _frame_title(series, events, f,
                                                                      dimension)}})
                     for k, f in enumerate(frames)]
    fig = go.Figure(data=plotly_frames[0].data, frames=plotly_frames)
    steps = [{'method': 'animate', 'label': f'{f.time:.2f}' + (f' {f.label}' if f.label
                                                                else ''),
              'args': [[str(k)], {'mode': 'immediate', 'frame': {'duration': 0,
                                                                  'redraw': True},
                                  'transition': {'duration': 0}}]}
             for k, f in enumerate(frames)]
    fig.update_layout(
        title={'text': _frame_title(series, events, frames[0], dimension)},
        height=720 if dimension == 3 else 640, showlegend=False,
        sliders=[{'active': 0, 'steps': steps, 'currentvalue': {'prefix': 'sim time (s): '},
                  'pad': {'t': 40}}],
        updatemenus=[{'type': 'buttons', 'showactive': False, 'x': 1.0, 'y': 1.02,
                      'xanchor': 'right', 'yanchor': 'bottom', 'direction': 'left',
                      'buttons': [
                          {'label': 'play', 'method': 'animate',
                           'args': [None, {'frame': {'duration': 120, 'redraw': True},
                                           'fromcurrent': True,
                                           'transition': {'duration': 0}}]},
                          {'label': 'pause', 'method': 'animate',
                           'args': [[None], {'mode': 'immediate',
                                             'frame': {'duration': 0, 'redraw': False}}]}]}])
    if dimension == 3:
        fig.update_layout(scene={
            'xaxis': {'title': {'text': 'x (mm)'}, 'range': [low[0], high[0]]},
            'yaxis': {'title': {'text': 'y (mm)'}, 'range': [low[1], high[1]]},
            'zaxis': {'title': {'text': 'z (mm)'}, 'range': [low[2], high[2]]},
            'aspectmode': 'cube', 'camera': {'eye': {'x': 1.2, 'y': -1.6, 'z': 0.6}}})
    else:
        fig.update_layout(plot_bgcolor='white')
        fig.update_xaxes(title_text='x (mm)', range=[low[0], high[0]], gridcolor='#eee')
        fig.update_yaxes(title_text='z (mm)', range=[low[2], high[2]], scaleanchor='x',
                         gridcolor='#eee')
    return fig


def write_grasp_report(series: TimeSeries, summary: dict, frames: list[Frame],
                       path: str | Path) -> Path:
    """``report.html`` of one recorded run: numbers, time plots, force-compression and
    (when the recording has markers) the fruit animation."""
    events = find_events(series)
    dimension = series.dimension
    lifted = summary['held'] is not None
    blocks = [Block('Summary', rows=summary_rows(summary)),
              Block('Force, gap, compression and slip over time' if lifted else
                    'Force, gap and compression over time', time_figure(
                  series, summary, events), text='Dashed lines: the phases found in the '
                  'recording (grip, lift-off, hold, release, let go).' + (
                      '' if lifted else ' No slip panel: the fruit was not lifted, and '
                      'slip is judged over the lift and hold.')),
              Block('Force vs compression', compression_figure(series, summary, events),
                    text='The stiffness is fitted on the loading part only, from the grip '
                         'to the force reached before the lift.')]
    if frames:
        blocks.append(Block(
            'The fruit over time', animation_figure(series, frames, summary),
            div_id=ANIMATION_ID,
            text=f'Colour: {pressure_name(dimension)} in kPa, from 0 to the largest value '
                 f'shown; the bruise threshold is '
                 f"{summary['bruise_threshold_pa'] / 1e3:.0f} kPa. Grey: the jaw plates; "
                 'brown: the table; blue: deformable fingers. Move the slider or press play.'))
    return write_html_report(path, grasp_report_title(series, summary), blocks)


def grasp_report_title(series: TimeSeries, summary: dict) -> str:
    """'Grasp of apple (2D) with the fin_ray finger: held', or for a run whose gripper
    never rose (a squeeze) 'Squeeze of apple (2D) with the flat finger to 10 N'; the
    finger is named when the recording stored its configuration (``summary['finger']``)."""
    finger = summary.get('finger')
    scene = (f"{summary.get('fruit') or 'a fruit'} ({series.dimension}D)"
             + (f' with the {finger} finger' if finger else ''))
    if lift_never_moved(series):
        return f"Squeeze of {scene} to {_number(summary['peak_grip_force_n'], 'N')}"
    return f'Grasp of {scene}: {grasp_outcome(summary)}'



def write_runs_index(summaries: Sequence[dict], run_dirs: Sequence[str],
                     path: str | Path) -> Path:
    """The page of a recording with several runs: each run's numbers and a link to its
    own report (``run_dirs``: the runs' folders relative to ``path``)."""
    blocks = [Block(f'Run {k + 1}', rows=summary_rows(summary),
                    links=[('its report: plots and the fruit over time',
                            f'{folder}/report.html')])
              for k, (summary, folder) in enumerate(zip(summaries, run_dirs))]
    title = (f"{len(summaries)} runs of {summaries[0].get('fruit') or 'a fruit'} "
             '(the sim time went back to 0 at a reset between them)')
    return write_html_report(path, title, blocks)


# ---------------------------------------------------------------------- window report
def _force_value(value: Any) -> float | None:
    """A window bound as a float (``as_dict`` writes infinity as 'inf'), or None."""
    return None if value is None else float(value)


def _trial_pressure(trial: dict) -> float:
    """Pa, the trial's peak damage pressure."""
    return float(trial.get('peak_pressure', trial.get('peak_damage_pressure', math.nan)))


def _trial_colour(trial: dict, good: bool) -> str:
    """A window trial's marker colour: grey where its solver failed, orange where its
    grip did not reach its command (verdict 'not reached'), else green if ``good``, red
    if not."""
    if trial['outcome'] == 'solver failed':
        return 'grey'
    if trial.get('verdict') == 'not reached':
        return 'darkorange'
    return 'seagreen' if good else 'crimson'


#: the window page's row on a bound that a solver failure or the fingers' reach limited:
#: (bound, its ``*_limited_by``) -> the row's text
_BOUND_ROWS = {
    ('lower bound', 'grip not reached'): 'none: the fingers did not reach the grip of the '
                                         'forces above the largest that slid, so no force '
                                         'holds',
    ('lower bound', 'solver failure'): 'not found: the trial at gripper.max_force did not '
                                       'converge, so whether it holds is not known',
    ('upper bound', 'solver failure'): 'the nearest trial above it did not converge: the '
                                       'fruit bruises somewhere above it, not at it',
    ('upper bound', 'grip not reached'): 'the nearest trial above it did not reach its grip, '
                                         'the fruit undamaged: the fingers deliver no more',
}


def _damage_word(trial: dict) -> str:
    """A trial's word in the damage panel: a 'bruise' trial's verdict (bruised, safe,
    pinched, solver failed, not reached); a 'hold' trial's damage (bruised or not)."""
    if trial['kind'] == 'bruise' and 'verdict' in trial:
        return trial['verdict']
    if trial['outcome'] == 'solver failed':
        return trial['outcome']
    return 'bruised' if trial['bruised'] else 'not bruised'


def write_window_report(window: dict, path: str | Path, title: str = 'Grasp window',
                        bruise_pressure: float | None = None) -> Path:
    """``window``'s report: every trial's outcome, slip and peak damage pressure over its
    commanded grip force, with the bounds found and the two limits (``window.max_slip``,
    the bruise pressure). ``window``: ``GraspWindow.as_dict()``; ``bruise_pressure``: Pa,
    the fruit's (``fruit.bruise_pressure``; None: that line is not drawn)."""
    trials = sorted(window.get('trials', []), key=lambda t: t['force'])
    force = [t['force'] for t in trials]
    measured = [t.get('peak_grip_force', math.nan) for t in trials]
    fig = make_subplots(rows=2, cols=1, shared_xaxes=True, vertical_spacing=0.06)
    fig.add_trace(go.Scatter(
        x=force, y=[1e3 * t['slip_distance'] for t in trials], mode='markers',
        text=[t.get('verdict', t['outcome']) for t in trials], customdata=measured,
        name='slip (mm)',
        marker={'size': 10, 'color': [_trial_colour(t, t['held']) for t in trials]},
        hovertemplate='%{x:.3g} N commanded (%{customdata:.3g} N measured): %{text}, '
                      'slip %{y:.3f} mm<extra></extra>'), row=1, col=1)
    fig.add_trace(go.Scatter(
        x=force, y=[_trial_pressure(t) / 1e3 for t in trials], mode='markers',
        text=[_damage_word(t) for t in trials], customdata=measured,
        name='peak damage pressure (kPa)',
        marker={'size': 10, 'symbol': 'diamond',
                'color': [_trial_colour(t, not t['bruised']) for t in trials]},
        hovertemplate='%{x:.3g} N commanded (%{customdata:.3g} N measured): %{text}, '
                      '%{y:.1f} kPa<extra></extra>'), row=2, col=1)
    if window.get('max_slip'):
        limit = 1e3 * float(window['max_slip'])
        fig.add_hline(y=limit, line_dash='dot', line_color='red', row=1, col=1,
                      annotation_text=f'slip limit (window.max_slip) {limit:g} mm',
                      annotation_position='top right')
    if bruise_pressure is not None:
        fig.add_hline(y=bruise_pressure / 1e3, line_dash='dot', line_color='red', row=2,
                      col=1, annotation_text=f'bruise pressure {bruise_pressure / 1e3:.0f}'
                                             ' kPa', annotation_position='bottom left')
    low, high = _force_value(window.get('min_force')), _force_value(window.get('max_force'))
    limited_by = window.get('max_force_limited_by')
    high_label = {'solver failure': 'safe up to (solver failure above)',
                  'grip not reached': 'safe up to (grip not reached above)'}
    for value, label in ((low, 'holds from'),
                         (high, high_label.get(limited_by, 'bruises above'))):
        if value is not None and math.isfinite(value):
            fig.add_vline(x=value, line_dash='dash', line_color='grey')
            fig.add_annotation(x=value, y=1.0, yref='paper', text=f'{label} {value:.3g} N',
                               showarrow=False, xanchor='left')
    fig.update_yaxes(title_text='slip (mm)', row=1, col=1)
    fig.update_yaxes(title_text='peak damage pressure (kPa)', row=2, col=1)
    fig.update_xaxes(title_text='commanded grip force (N)', row=2, col=1)
    fig.update_layout(height=640, showlegend=False)
    rows = [(f"{t['force']:.4g} N", f"{t['kind']}: {t.get('verdict', t['outcome'])}, slip "
             f"{1e3 * t['slip_distance']:.3f} "
             f'mm, peak damage pressure {_trial_pressure(t) / 1e3:.1f} kPa') for t in trials]
    if not window.get('window') or low is None or high is None:
        found = 'none'
    else:
        found = f'{low:.3g} N .. ' + (f'{high:.3g} N' if math.isfinite(high)
                                      else 'gripper.max_force (nothing bruised)')
    window_rows = [('safe window', found)]
    for bound, key in (('lower bound', 'min_force_limited_by'),
                       ('upper bound', 'max_force_limited_by')):
        why = _BOUND_ROWS.get((bound, window.get(key)))
        if why is not None:
            window_rows.append((bound, why))
    return write_html_report(path, title, [
        Block('Window', rows=window_rows),
        Block('Trials', fig, rows=rows,
              text='Green: held (top) or not bruised (bottom); red: not held, or bruised '
                   '(pinched: the fingers closed on each other over the fruit, crushing it '
                   'between them); grey: the solver failed (neither); orange: the grip '
                   'did not reach its command (not bruised, but not in the window). '
                   'Dotted red: the slip limit (top) and the bruise pressure (bottom). '
                   'Hover: the commanded and the measured grip force.')])
