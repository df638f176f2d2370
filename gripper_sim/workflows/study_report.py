"""A study's report: ``report.html`` (plotly, self-contained, works offline) and
``report.png`` (matplotlib), the same three views:

- window maps: every evaluation's grip force against each axis, coloured by outcome;
- success probability against grip force, per design point, with its interval;
- the population window per design point, with the intervals of its ends.
"""
from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Sequence

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402
import matplotlib.ticker as ticker  # noqa: E402
import plotly.graph_objects as go  # noqa: E402
from plotly.subplots import make_subplots  # noqa: E402

from gripper_sim.workflows.html_page import write_figure_page  # noqa: E402

OUTCOME_COLOURS = {'held': '#2ca02c', 'placed': '#2ca02c', 'slipped': '#bcbd22',
                   'dropped': '#1f77b4', 'bruised': '#ff7f0e', 'crushed': '#d62728',
                   'pinched': '#9467bd',
                   'failed': '#7f7f7f', 'solver failed': '#000000', 'error': '#000000'}
#: a design point's colour cycle
PALETTE = ('#1f77b4', '#ff7f0e', '#2ca02c', '#d62728', '#9467bd', '#8c564b', '#e377c2',
           '#7f7f7f', '#bcbd22', '#17becf')


def write_report(summary: dict, rows: Sequence[dict], out: str | os.PathLike) -> None:
    """Write ``out/report.html`` and ``out/report.png``."""
    out = Path(out)
    axes = [key for key in summary['axes'] if key != 'force'] or ['sample']
    _html(summary, rows, axes, out / 'report.html')
    _png(summary, rows, axes, out / 'report.png')


def _axis_value(row: dict, axis: str) -> str:
    return str(row.get(axis))


def _categories(rows: Sequence[dict], axis: str) -> list[str]:
    """The axis values in order: numbers by value, text alphabetically."""
    values = {row.get(axis) for row in rows}
    numeric = all(isinstance(v, (int, float)) for v in values)
    return [str(v) for v in sorted(values, key=(float if numeric else str))]


def _force_axis(ax) -> None:
    """Log force axis with plain numbers (2, 5, 10 N, not 2 x 10^0)."""
    ax.set_xscale('log')
    ax.xaxis.set_major_formatter(ticker.FuncFormatter(lambda v, _: f'{v:g}'))
    ax.xaxis.set_minor_formatter(ticker.FuncFormatter(
        lambda v, _: f'{v:g}' if str(f'{v:g}')[0] in '235' else ''))


#: px of the HTML report's panels: a window map, the success curves, and the population
#: window (its base, and per design point)
MAP_HEIGHT, CURVE_HEIGHT = 380, 420
WINDOW_BASE_HEIGHT, WINDOW_ROW_HEIGHT = 160, 70
#: how far (a factor) the population window's force axis reaches past its outermost ends
WINDOW_MARGIN = 1.3


def log_ticks(low: float, high: float) -> tuple[list[float], list[str]]:
    """Tick values (N) 1, 2, 5 per decade from ``low`` to ``high`` (N, > 0) and their
    labels as plain numbers ('0.5', '1', '20'), for a plotly log axis."""
    first, last = math.floor(math.log10(low)), math.ceil(math.log10(high))
    values = [m * 10.0 ** e for e in range(first, last + 1) for m in (1, 2, 5)]
    values = [v for v in values if low <= v * (1 + 1e-9) and v <= high * (1 + 1e-9)]
    return values, [f'{v:g}' for v in values]


def _log_axis(values: Sequence[float], margin: float = 1.0) -> dict:
    """A plotly log axis over the positive ``values`` (N), ``margin`` (a factor) past
    either end, ticked 1, 2, 5 per decade with plain numbers; {} without values."""
    positive = [float(v) for v in values if v is not None and math.isfinite(v) and v > 0]
    if not positive:
        return {}
    low, high = min(positive) / margin, max(positive) * margin
    if high <= low * 1.5:
        low, high = low / 1.5, high * 1.5
    ticks, labels = log_ticks(low, high)
    return dict(type='log', range=[math.log10(low), math.log10(high)], tickmode='array',
                tickvals=ticks, ticktext=labels)


def _window_ends(point: dict) -> tuple[float, float] | None:
    population = point.get('population') or {}
    window = population.get('window')
    return (window['low'], window['high']) if window else None


def _title(summary: dict) -> str:
    pop = summary['population']
    return (f"study {summary['study']}: {len(summary['points'])} design points x "
            f"{pop['samples']} fruits ({summary['method']}), {summary['rows']} evaluations; "
            f"window for {summary['fraction'] * 100:g} % of the fruits")


def _html(summary: dict, rows: Sequence[dict], axes: list[str], path: Path) -> None:
    titles = [f'window map: grip force vs {axis}' for axis in axes] + [
        'success probability vs grip force', 'population window per design point']
    heights = ([MAP_HEIGHT] * len(axes) + [CURVE_HEIGHT, WINDOW_BASE_HEIGHT
                                           + WINDOW_ROW_HEIGHT * len(summary['points'])])
    gap = 110   # px between panels: the axis title and the next panel's title
    fig = make_subplots(rows=len(titles), cols=1, subplot_titles=titles,
                        row_heights=heights, vertical_spacing=gap / (sum(heights)
                                                                     + gap * len(titles)))
    for i, axis in enumerate(axes, start=1):
        for outcome, colour in OUTCOME_COLOURS.items():
            picked = [r for r in rows if r['outcome'] == outcome]
            if not picked:
                continue
            fig.add_trace(go.Scatter(
                x=[_axis_value(r, axis) for r in picked], y=[r['force'] for r in picked],
                mode='markers', name=outcome, legendgroup=outcome, showlegend=(i == 1),
                marker=dict(color=colour, size=6, opacity=0.6),
                text=[f"point {r['point']}, sample {r['sample']}, {r['kind']}"
                      for r in picked]), row=i, col=1)
        fig.update_yaxes(title_text='grip force (N)', row=i, col=1,
                         **_log_axis([r['force'] for r in rows], margin=1.2))
        fig.update_xaxes(type='category', title_text=axis, row=i, col=1,
                         categoryorder='array', categoryarray=_categories(rows, axis))
    curve_row, window_row = len(axes) + 1, len(axes) + 2
    for k, point in enumerate(summary['points']):
        curve = (point.get('population') or {}).get('curve')
        if not curve:
            continue
        colour = PALETTE[k % len(PALETTE)]
        for trace in band_traces(curve, colour):
            fig.add_trace(trace, row=curve_row, col=1)
        fig.add_trace(go.Scatter(x=curve['force'], y=curve['p'], mode='lines',
                                 name=point['label'], line=dict(color=colour, shape='hv')),
                      row=curve_row, col=1)
    fig.add_hline(y=summary['fraction'], line_dash='dot', row=curve_row, col=1)
    curve_forces = [f for point in summary['points']
                    for f in ((point.get('population') or {}).get('curve') or {}).get(
                        'force', [])]
    fig.update_xaxes(title_text='grip force (N)', row=curve_row, col=1,
                     **_log_axis(curve_forces))
    fig.update_yaxes(title_text='fruits succeeding', range=[0, 1.02], row=curve_row, col=1)
    labels = [p['label'] for p in summary['points']]
    window_forces: list[float] = []
    for point in summary['points']:
        ends = _window_ends(point)
        if ends is None:
            fig.add_annotation(x=0.5, xref='x domain', y=point['label'],
                               yref=f'y{window_row}', text='no safe force',
                               showarrow=False)
            continue
        ci = point['population']['ci']
        window_forces += list(ends) + ([f for pair in (ci['low'], ci['high']) for f in pair]
                                       if ci else [])
        fig.add_trace(go.Scatter(x=list(ends), y=[point['label']] * 2, mode='lines+markers',
                                 line=dict(width=8, color='#2ca02c'), showlegend=False,
                                 name=point['label']), row=window_row, col=1)
        if ci:
            for lo, hi in (ci['low'], ci['high']):
                fig.add_trace(go.Scatter(x=[lo, hi], y=[point['label']] * 2, mode='lines',
                                         line=dict(width=2, color='#333333'),
                                         showlegend=False, hoverinfo='x'),
                              row=window_row, col=1)
    fig.update_xaxes(title_text='grip force (N)', row=window_row, col=1,
                     **(_log_axis(window_forces, WINDOW_MARGIN) or {'type': 'log'}))
    fig.update_yaxes(type='category', categoryarray=labels, row=window_row, col=1)
    fig.update_layout(title=_title(summary), height=sum(heights) + gap * len(titles) + 60,
                      template='plotly_white')
    write_figure_page(path, f"Study {summary['study']}", fig)


def band_traces(curve: dict, colour: str) -> list:
    """The interval band of a success curve ({force, p, lower, upper}) as plotly traces:
    its lower and upper bounds as steps (``hv``, as the curve and the PNG draw them), the
    space between filled. A polygon through the bounds drew straight slopes between the
    forces, a band that was not the interval between them."""
    edge = dict(x=curve['force'], mode='lines', line=dict(width=0, shape='hv'),
                hoverinfo='skip', showlegend=False)
    red, green, blue = (int(colour[i:i + 2], 16) for i in (1, 3, 5))
    return [go.Scatter(y=curve['lower'], **edge),
            go.Scatter(y=curve['upper'], fill='tonexty',
                       fillcolor=f'rgba({red}, {green}, {blue}, 0.15)', **edge)]


def _png(summary: dict, rows: Sequence[dict], axes: list[str], path: Path) -> None:
    panels = len(axes) + 2
    window_height = 0.6 + 0.25 * len(summary['points'])
    fig, ax = plt.subplots(panels, 1, squeeze=False,
                           figsize=(9, 3.2 * (panels - 1) + 1.2 + window_height),
                           height_ratios=[3.2] * (panels - 1) + [0.6 + window_height])
    ax = ax[:, 0]
    for i, axis in enumerate(axes):
        categories = _categories(rows, axis)
        spread = 0.0 if axis == 'sample' else 0.3
        for outcome, colour in OUTCOME_COLOURS.items():
            picked = [r for r in rows if r['outcome'] == outcome]
            if not picked:
                continue
            x = [categories.index(_axis_value(r, axis))
                 + spread * ((r['sample'] * 0.618) % 1 - 0.5) for r in picked]
            ax[i].scatter(x, [r['force'] for r in picked], s=10, color=colour, alpha=0.6,
                          label=outcome if i == 0 else None)
        step = max(1, len(categories) // 20)
        ax[i].set_xticks(range(0, len(categories), step), categories[::step],
                         fontsize=7 if len(categories) > 8 else None)
        ax[i].set_xlim(-0.5, len(categories) - 0.5)  # one category: not the spread's width
        ax[i].set_yscale('log')
        ax[i].yaxis.set_major_formatter(ticker.FuncFormatter(lambda v, _: f'{v:g}'))
        ax[i].set_xlabel(axis)
        ax[i].set_ylabel('grip force (N)')
        ax[i].set_title(f'window map: grip force vs {axis}', fontsize=10)
        if i == 0:
            ax[i].legend(fontsize=7, ncol=4, loc='best')
    curve_ax, window_ax = ax[len(axes)], ax[len(axes) + 1]
    for k, point in enumerate(summary['points']):
        curve = (point.get('population') or {}).get('curve')
        if not curve:
            continue
        colour = PALETTE[k % len(PALETTE)]
        curve_ax.fill_between(curve['force'], curve['lower'], curve['upper'], step='post',
                              color=colour, alpha=0.15)
        curve_ax.step(curve['force'], curve['p'], where='post', color=colour,
                      label=point['label'])
    curve_ax.axhline(summary['fraction'], color='k', linestyle=':', linewidth=1)
    _force_axis(curve_ax)
    curve_ax.set_ylim(0, 1.02)
    curve_ax.set_xlabel('grip force (N)')
    curve_ax.set_ylabel('fruits succeeding')
    curve_ax.set_title('success probability vs grip force (band: Clopper-Pearson interval)',
                       fontsize=10)
    if len(summary['points']) <= 12:
        curve_ax.legend(fontsize=7)
    for y, point in enumerate(summary['points']):
        ends = _window_ends(point)
        if ends is None:
            window_ax.text(0.5, y, 'no safe force', transform=window_ax.get_yaxis_transform(),
                           ha='center', va='center', fontsize=8)
            continue
        window_ax.plot(ends, [y, y], color='#2ca02c', linewidth=6, solid_capstyle='butt')
        ci = point['population']['ci']
        if ci:
            for lo, hi in (ci['low'], ci['high']):
                window_ax.plot([lo, hi], [y, y], color='#333333', linewidth=1.5,
                               marker='|', markersize=10)
    window_ax.set_yticks(range(len(summary['points'])),
                         [p['label'] for p in summary['points']], fontsize=7)
    window_ax.set_ylim(-0.7, len(summary['points']) - 0.3)
    _force_axis(window_ax)
    window_ax.set_xlabel('grip force (N)')
    window_ax.set_title(f"population window ({summary['fraction'] * 100:g} % of the fruits; "
                        f"whiskers: {summary['confidence'] * 100:g} % bootstrap interval of "
                        'each end)', fontsize=10)
    fig.suptitle(_title(summary), fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
