"""The PNG figures of one recorded run (matplotlib, no pyplot state: each function builds a
``Figure`` and returns it; ``save`` writes it).

Every title and colour bar names the quantity it shows (``pressure_name``); the phases
(``events.Events``) are marked on the time plots; the fruit pictures draw the jaw plates
(as the ``jaws`` markers place them: a Fin Ray's on its base), the deformable fingers
and the table, with a colour scale from 0 to the largest pressure shown and the bruise
threshold marked on the colour bar.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.cm import ScalarMappable
from matplotlib.collections import LineCollection
from matplotlib.colors import Normalize
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle
from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection

from gripper_sim.recording.analysis.events import Events
from gripper_sim.recording.analysis.frames import Frame, jaw_contact_nodes, patch_outline
from gripper_sim.recording.analysis.series import TimeSeries
from gripper_sim.recording.analysis.summary import StiffnessFit, grasp_outcome
from gripper_sim.recording.errors import RecordingError

#: the colour map of contact pressure in every figure and in the HTML report
PRESSURE_COLOURS = 'YlOrRd'
PHASE_COLOUR = '0.35'


def pressure_name(dimension: int) -> str:
    """What the fruit's colours show: the damage estimate's contact pressure."""
    if dimension == 3:
        return 'contact pressure (normal force / vertex area)'
    return 'contact pressure (Hertz estimate)'


def pressure_scale(frames: list[Frame], bruise_pressure: float) -> float:
    """Pa, the top of the colour scale: the largest pressure shown (the bruise pressure
    when nothing presses)."""
    values = [float(np.nanmax(f.pressure)) for f in frames
              if f.pressure.size and np.any(np.isfinite(f.pressure))]
    top = max(values, default=0.0)
    return top if top > 0 else bruise_pressure


def contact_state(series: TimeSeries, row: int) -> str:
    """Which jaws touch the fruit at ``row``, in words."""
    left = series['left_jaw_contact'][row] > 0
    right = series['right_jaw_contact'][row] > 0
    if left and right:
        return 'in both jaws'
    if left or right:
        return 'one jaw touching'
    return 'no jaw contact'


def save(fig: Figure, path: Path) -> Path:
    """Write ``fig`` as a PNG to ``path``.

    Raises:
        RecordingError: the file cannot be written.
    """
    try:
        fig.savefig(path)
    except OSError as err:
        raise RecordingError(f'cannot write {path}: {err.strerror}') from err
    return path


def _mark_phases(axes: list, series: TimeSeries, events: Events) -> None:
    t = series['time_s']
    for label, row in events.marked():
        for k, ax in enumerate(axes):
            ax.axvline(t[row], color=PHASE_COLOUR, lw=0.8, ls='--', gid=f'phase:{label}')
            if k == 0:
                ax.annotate(label, (t[row], 0.5), xycoords=('data', 'axes fraction'),
                            xytext=(2, 0), textcoords='offset points', rotation=90,
                            va='center', ha='left', fontsize=7, color=PHASE_COLOUR,
                            bbox={'facecolor': 'white', 'edgecolor': 'none', 'pad': 1})


def force_vs_time(series: TimeSeries, summary: dict, events: Events) -> Figure:
    """Grip force, gap, compression and slip over time, each on its own axis, with the
    phases marked and the slip tolerance drawn."""
    t = series['time_s']
    fig = Figure(figsize=(8.5, 9), dpi=110, layout='constrained')
    axes = fig.subplots(4, 1, sharex=True, height_ratios=(1.4, 1, 1, 1))
    ax_force, ax_gap, ax_comp, ax_slip = axes
    ax_force.plot(t, series['grip_force_n'], color='k', lw=1.6, label='grip force (mean)')
    if np.any(np.isfinite(series['left_force_n'])):
        ax_force.plot(t, series['left_force_n'], lw=1, ls='--', label='left jaw')
    if np.any(np.isfinite(series['right_force_n'])):
        ax_force.plot(t, series['right_force_n'], lw=1, ls=':', label='right jaw')
    ax_force.plot([summary['time_of_peak_force_s']], [summary['peak_grip_force_n']], 'o',
                  color='tab:red', label=f"peak {summary['peak_grip_force_n']:.2f} N")
    ax_force.set_ylabel('normal force (N)')
    ax_force.legend(loc='lower right', fontsize=8)
    ax_gap.plot(t, 1e3 * series['gap_m'], color='tab:blue', gid='gap')
    ax_gap.set_ylabel('jaw gap (mm)')
    ax_comp.plot(t, 1e3 * series['compression_m'], color='tab:orange', gid='compression')
    ax_comp.set_ylabel('compression (mm)')
    ax_slip.plot(t, 1e3 * series['slip_distance_m'], color='tab:green', gid='slip')
    tolerance = summary['slip_threshold_m'] * 1e3
    ax_slip.axhline(tolerance, color='tab:red', lw=0.8, ls=':', gid='slip tolerance',
                    label=f'slip tolerance {tolerance:g} mm')
    slip_top = float(np.nanmax(np.abs(series['slip_distance_m']))) * 1e3
    ax_slip.set_ylim(-0.05 * max(slip_top, 1e-3), 1.15 * max(slip_top, tolerance))
    ax_slip.set_ylabel('centroid drop (mm)')
    ax_slip.legend(loc='upper left', fontsize=8)
    ax_slip.set_xlabel('sim time (s)')
    for ax in axes:
        ax.grid(alpha=0.3)
    _mark_phases(list(axes), series, events)
    fig.suptitle(f'Grip force, jaw gap, compression and slip ({grasp_outcome(summary)})',
                 fontsize=11)
    return fig


def force_vs_compression(series: TimeSeries, summary: dict, fit: StiffnessFit) -> Figure:
    """Force over compression coloured by time; the loading rows the stiffness was
    fitted on, the fitted line over their range and the secant chord."""
    fig = Figure(figsize=(7, 5.2), dpi=110, layout='constrained')
    ax = fig.subplots()
    c_mm = 1e3 * series['compression_m']
    force = series['grip_force_n']
    sc = ax.scatter(c_mm, force, c=series['time_s'], s=6, cmap='viridis')
    fig.colorbar(sc, ax=ax, label='sim time (s)')
    if fit.rows.size:
        ax.scatter(c_mm[fit.rows], force[fit.rows], s=16, facecolors='none',
                   edgecolors='tab:red', lw=0.6, label='loading rows fitted', gid='fit rows')
    if fit.tangent is not None:
        c = series['compression_m'][fit.rows]
        xs = np.linspace(c.min(), c.max(), 20)
        lo, hi = summary['stiffness_fit_force_range_n']
        t_lo, t_hi = summary['stiffness_fit_time_range_s']
        ax.plot(1e3 * xs, fit.tangent * xs + fit.intercept, 'r-', lw=1.5, gid='fit line',
                label=f'tangent {fit.tangent / 1e3:.2f} N/mm, fitted on {lo:.2f}-{hi:.2f} N'
                      f' (t = {t_lo:.3f}-{t_hi:.3f} s)')
    if fit.secant is not None and fit.start is not None and fit.end is not None:
        ends = [fit.start, fit.end]
        ax.plot(c_mm[ends], force[ends], 'D:', color='tab:purple', gid='secant',
                label=f'grip to end of loading: secant {fit.secant / 1e3:.2f} N/mm')
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc='upper left', fontsize=8)
    ax.set_xlabel('compression (mm)')
    ax.set_ylabel('grip force (N)')
    ax.set_title('Force vs compression (stiffness from the loading part only)')
    ax.grid(alpha=0.3)
    return fig


def _pressure_bar(fig: Figure, axes: Any, dimension: int, top: float,
                  bruise_pressure: float) -> Any:
    """The pressure colour bar (kPa), 0..``top``, with the bruise threshold marked."""
    name = pressure_name(dimension)
    mappable = ScalarMappable(Normalize(0.0, top / 1e3), PRESSURE_COLOURS)
    bruise_kpa = bruise_pressure / 1e3
    if bruise_pressure <= top * (1 + 1e-6):
        label = f'{name} (kPa)\nbruise threshold {bruise_kpa:.0f} kPa: black line'
    else:
        label = f'{name} (kPa)\nbruise threshold {bruise_kpa:.0f} kPa: above this scale'
    bar = fig.colorbar(mappable, ax=axes, label=label, shrink=0.85)
    if bruise_pressure <= top * (1 + 1e-6):
        bar.ax.axhline(bruise_kpa, color='k', lw=2, gid='bruise threshold')
        bar.ax.text(1.6, bruise_kpa, 'bruise', transform=bar.ax.get_yaxis_transform(),
                    va='center', fontsize=7)
    return bar


def _draw_boxes_2d(ax, frame: Frame) -> None:
    for box in frame.jaws:
        low, _ = box.bounds()
        ax.add_patch(Rectangle((1e3 * low[0], 1e3 * low[2]), 1e3 * box.size[0],
                               1e3 * box.size[2], facecolor='0.6', edgecolor='0.3',
                               alpha=0.8, gid='jaw'))
    if frame.table is not None:
        low, high = frame.table.bounds()
        ax.add_patch(Rectangle((1e3 * low[0], 1e3 * low[2]), 1e3 * frame.table.size[0],
                               1e3 * frame.table.size[2], facecolor=(0.55, 0.4, 0.25),
                               edgecolor='none', gid='table'))
    for segment in frame.finger_lines:
        ax.plot(1e3 * segment[:, 0], 1e3 * segment[:, 2], color=(0.15, 0.35, 0.75), lw=1.5,
                gid='finger')


def _view_box(frames: list[Frame]) -> tuple[np.ndarray, np.ndarray]:
    """(low, high) (3,) mm around every fruit and jaw of ``frames``."""
    pts = [f.points for f in frames] + [np.vstack(b.bounds()) for f in frames for b in f.jaws]
    every = 1e3 * np.vstack(pts)
    pad = 0.08 * float(np.ptp(every, axis=0).max() or 10.0)
    return every.min(axis=0) - pad, every.max(axis=0) + pad


def outline_snapshots(series: TimeSeries, frames: list[Frame], summary: dict) -> Figure:
    """2D: the outline at the key moments coloured by skin strain (top row, relative to
    the first frame) and by contact pressure (bottom row), with jaws and table."""
    bruise = summary['bruise_threshold_pa']
    top = pressure_scale(frames, bruise)
    name = pressure_name(2)
    first = frames[0].points[:, [0, 2]]
    rest = np.linalg.norm(np.diff(first, axis=0), axis=1)
    strains = []
    for frame in frames:
        seg = np.linalg.norm(np.diff(frame.points[:, [0, 2]], axis=0), axis=1)
        strains.append(seg / rest - 1.0 if seg.shape == rest.shape else np.zeros_like(seg))
    limit = max(1e-6, max(float(np.max(np.abs(s))) for s in strains))
    n = len(frames)
    fig = Figure(figsize=(3.4 * n + 1.6, 7.4), dpi=110, layout='constrained')
    axes = fig.subplots(2, n, squeeze=False)
    low, high = _view_box(frames)
    low[2] = min(low[2], -3.0)   # the table top (z = 0) in view
    strain_lines = None
    norm = Normalize(0.0, top / 1e3)
    for col, (frame, strain) in enumerate(zip(frames, strains)):
        pts = 1e3 * frame.points[:, [0, 2]]
        segments = list(np.stack([pts[:-1], pts[1:]], axis=1))
        ax_strain, ax_p = axes[0][col], axes[1][col]
        strain_lines = LineCollection(segments, cmap='coolwarm', linewidths=3)
        strain_lines.set_array(strain)
        strain_lines.set_clim(-limit, limit)
        ax_strain.add_collection(strain_lines)
        ax_p.plot(pts[:, 0], pts[:, 1], color='0.5', lw=1.2, zorder=2)
        ax_p.scatter(pts[:-1, 0], pts[:-1, 1], c=np.nan_to_num(frame.pressure[:-1]) / 1e3,
                     cmap=PRESSURE_COLOURS, norm=norm, s=14, zorder=3, gid='fruit pressure')
        ax_strain.set_title(f'{frame.label}, t = {frame.time:.3f} s\n'
                            f'{contact_state(series, frame.row)}', fontsize=9)
        peak = float(np.nanmax(frame.pressure)) if np.any(np.isfinite(frame.pressure)) \
            else 0.0
        ax_p.set_title(f'peak {name}\n{peak / 1e3:.1f} kPa', fontsize=8)
        for ax in (ax_strain, ax_p):
            _draw_boxes_2d(ax, frame)
            ax.set_xlim(low[0], high[0])
            ax.set_ylim(low[2], high[2])
            ax.set_aspect('equal')
            ax.tick_params(labelsize=7)
        ax_p.set_xlabel('x (mm)', fontsize=8)
        if col == 0:
            ax_strain.set_ylabel('z (mm)', fontsize=9)
            ax_p.set_ylabel('z (mm)', fontsize=9)
    if strain_lines is not None:
        fig.colorbar(strain_lines, ax=list(axes[0]),
                     label='skin strain (vs the first snapshot)', shrink=0.85)
    _pressure_bar(fig, list(axes[1]), 2, top, bruise)
    fig.suptitle('Fruit outline at key moments, with the jaws and the table', fontsize=11)
    return fig


def _box_faces(box) -> list[np.ndarray]:
    """The six (4, 3) faces of a box, mm."""
    low, high = (1e3 * v for v in box.bounds())
    x0, y0, z0 = low
    x1, y1, z1 = high
    c = np.array([[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0],
                  [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]])
    quads = ((0, 1, 2, 3), (4, 5, 6, 7), (0, 1, 5, 4), (2, 3, 7, 6), (1, 2, 6, 5),
             (0, 3, 7, 4))
    return [c[list(q)] for q in quads]


def mesh_snapshots(series: TimeSeries, frames: list[Frame], summary: dict) -> Figure:
    """3D: the skin at the key moments, each triangle coloured by the largest contact
    pressure of its corners on a scale up to the largest pressure shown; the jaw plates
    (see-through), the deformable fingers' edges and the table top."""
    bruise = summary['bruise_threshold_pa']
    top = pressure_scale(frames, bruise)
    name = pressure_name(3)
    n = len(frames)
    cols = 2 if n <= 4 else 3
    rows = int(np.ceil(n / cols))
    fig = Figure(figsize=(5.6 * cols + 1.4, 5.2 * rows), dpi=100, layout='constrained')
    low, high = _view_box(frames)
    centre = 0.5 * (low + high)
    half = 0.5 * float(np.max(high - low))
    norm = Normalize(0.0, top / 1e3)
    cmap = ScalarMappable(norm, PRESSURE_COLOURS)
    axes = []
    for k, frame in enumerate(frames):
        ax = fig.add_subplot(rows, cols, k + 1, projection='3d')
        axes.append(ax)
        pts = 1e3 * frame.points
        triangles = pts[frame.triangles]
        face_p = np.nanmax(frame.pressure[frame.triangles], axis=1) / 1e3
        ax.add_collection3d(Poly3DCollection(
            list(triangles), facecolors=cmap.to_rgba(np.nan_to_num(face_p)),
            edgecolors=(0, 0, 0, 0.12), linewidths=0.2, gid='fruit pressure'))
        for box in frame.jaws:
            ax.add_collection3d(Poly3DCollection(_box_faces(box), facecolors=(0.4, 0.4, 0.5,
                                                                              0.18),
                                                 edgecolors=(0.2, 0.2, 0.3, 0.7),
                                                 linewidths=0.6, gid='jaw'))
        if len(frame.finger_lines):
            ax.add_collection3d(Line3DCollection(list(1e3 * frame.finger_lines),
                                                 colors=[(0.15, 0.35, 0.75, 0.5)],
                                                 linewidths=0.4, gid='finger'))
        if frame.table is not None:
            z = 1e3 * frame.table.bounds()[1][2]
            x0, x1, y0, y1 = centre[0] - half, centre[0] + half, centre[1] - half, \
                centre[1] + half
            ax.add_collection3d(Poly3DCollection(
                [np.array([[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]])],
                facecolors=(0.55, 0.4, 0.25, 0.35), edgecolors='none', gid='table'))
        ax.set_xlim(centre[0] - half, centre[0] + half)
        ax.set_ylim(centre[1] - half, centre[1] + half)
        ax.set_zlim(min(centre[2] - half, -2.0), centre[2] + half)
        ax.set_box_aspect((1, 1, 1))
        ax.view_init(elev=18, azim=-60)
        for set_label, axis in ((ax.set_xlabel, 'x'), (ax.set_ylabel, 'y'),
                                (ax.set_zlabel, 'z')):
            set_label(f'{axis} (mm)', fontsize=8)
        ax.tick_params(labelsize=7)
        peak = float(np.nanmax(frame.pressure)) if np.any(np.isfinite(frame.pressure)) \
            else 0.0
        ax.set_title(f'{frame.label}, t = {frame.time:.3f} s, '
                     f'{contact_state(series, frame.row)}\n'
                     f'F = {series["grip_force_n"][frame.row]:.2f} N, peak {name} '
                     f'{peak / 1e3:.1f} kPa', fontsize=9)
    _pressure_bar(fig, axes, 3, top, bruise)
    fig.suptitle('Deformed fruit skin, jaw plates and table at key moments', fontsize=11)
    return fig


def contact_patch(series: TimeSeries, cloud: np.ndarray) -> tuple[Figure, dict]:
    """The jaw contact patches at peak force: the nodes with a jaw contact force
    (``jaw_contact_nodes``) projected onto the jaw plane y-z, coloured by their normal
    force, with their convex outline and its area. Also returns the patch areas (m^2)
    and node counts per jaw."""
    row = int(np.argmax(series['grip_force_n']))
    sides = jaw_contact_nodes(cloud)
    fig = Figure(figsize=(9, 4.4), dpi=110, layout='constrained')
    axes = fig.subplots(1, 2)
    patches: dict[str, Any] = {}
    picked = np.concatenate([sides['left'], sides['right']])
    f_max = float(np.abs(cloud[picked, 3]).max()) if picked.size else 1.0
    scatter = None
    for ax, side in zip(axes, ('left', 'right')):
        nodes = sides[side]
        yz = cloud[nodes][:, [1, 2]]
        outline, area = patch_outline(yz)
        patches[side] = {'nodes': int(nodes.size), 'hull_area_m2': area}
        if nodes.size:
            scatter = ax.scatter(1e3 * yz[:, 0], 1e3 * yz[:, 1], c=np.abs(cloud[nodes, 3]),
                                 cmap='viridis', vmin=0.0, vmax=f_max, s=28)
            if len(outline) > 3:
                ax.plot(1e3 * outline[:, 0], 1e3 * outline[:, 1], 'k-', lw=1)
            centre = yz.mean(axis=0)
            span = max(float(np.ptp(yz, axis=0).max()), 1e-3)
            ax.set_xlim(1e3 * (centre[0] - span), 1e3 * (centre[0] + span))
            ax.set_ylim(1e3 * (centre[1] - span), 1e3 * (centre[1] + span))
        else:
            ax.text(0.5, 0.5, 'no contact', ha='center', va='center',
                    transform=ax.transAxes)
        ax.set_aspect('equal')
        ax.set_xlabel('y (mm)')
        ax.set_ylabel('z (mm)')
        ax.grid(alpha=0.3)
        ax.set_title(f'{side} jaw: {nodes.size} nodes, outline area {area * 1e6:.1f} mm^2',
                     fontsize=9)
    if scatter is not None:
        fig.colorbar(scatter, ax=list(axes), label='node normal force |f_x| (N)', shrink=0.8)
    fig.suptitle(f'Contact patches at peak force ({series["grip_force_n"][row]:.2f} N, '
                 f't = {series["time_s"][row]:.3f} s); contact area (vertex areas, both '
                 f'jaws) {series["contact_area_m2"][row] * 1e6:.1f} mm^2', fontsize=9)
    return fig, patches
