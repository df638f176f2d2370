"""``analyze``: every output of the analysis of one recording, run by run.

For a recording of one run the files go into the output directory; for a recording
with resets (several runs) each run gets ``run_1/``, ``run_2/``, ... with the same
files, and ``summary.json`` at the top lists the runs' summaries.
"""
from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from gripper_sim.recording.analysis import figures, report_html
from gripper_sim.recording.analysis.events import find_events, key_moments
from gripper_sim.recording.analysis.frames import Frame, cloud_at, read_frames
from gripper_sim.recording.analysis.series import (DEFAULT_BRUISE_PRESSURE, TimeSeries,
                                                   find_topics, read_config,
                                                   read_time_series, split_runs)
from gripper_sim.recording.analysis.summary import (describe, fit_stiffness, summarize,
                                                    write_csv)
from gripper_sim.recording.errors import RecordingError
from gripper_sim.recording.reader import BagReader

#: called as ``progress(stage, done, total)``: stage in words, counts of that stage
Progress = Callable[[str, int, int], None]
#: the steps of one run's outputs: CSV, time figures, snapshots, HTML report
OUTPUTS = 4


@dataclass
class AnalysisResult:
    """What ``analyze`` wrote.

    Attributes:
        summary: the run's summary; for several runs ``{'runs': [...], ...}``.
        runs: one summary per run (a list of one for a single run).
        output_dir: where the files are; files: every file written.
    """

    summary: dict
    output_dir: Path
    runs: list[dict] = field(default_factory=list)
    files: list[Path] = field(default_factory=list)

    def describe(self) -> list[str]:
        """Text lines: each run's summary, then the files written."""
        lines: list[str] = []
        if len(self.runs) > 1:
            lines.append(f'{len(self.runs)} runs in this recording (the sim time went back '
                         'to 0 at a reset): each is analysed on its own')
        for k, run in enumerate(self.runs):
            if len(self.runs) > 1:
                lines.append(f'--- run {k + 1} of {len(self.runs)} ---')
            lines += describe(run)
        return lines + [f'wrote {p}' for p in self.files]


def _mkdir(path: Path) -> None:
    try:
        path.mkdir(exist_ok=True)
    except OSError as err:
        raise RecordingError(f'cannot create {path}: {err.strerror}') from err


def check_output_dir(path: Path, *, overwrite: bool = False) -> None:
    """Raise RecordingError unless ``path`` can be the analysis' output folder: a new
    folder in an existing one (as every output of the CLI), or, with ``overwrite``, an
    existing folder to write into (its files of the same names are replaced)."""
    if path.exists() and not overwrite:
        raise RecordingError(f'{path} already exists; choose another output folder or '
                             'remove it (--force writes into it)')
    parent = path.absolute().parent
    if not parent.is_dir():
        raise RecordingError(f'{path}: directory {parent} does not exist')


def run_frames(bag: BagReader, topic: str | None, series: TimeSeries,
               rows: list[tuple[str, int]], bruise: float) -> list[Frame]:
    """The labelled frames of ``rows`` ((label, row) pairs) of one run ([] without
    markers)."""
    if topic is None or not rows:
        return []
    labels = dict((row, label) for label, row in rows)
    frames = read_frames(bag, topic, series, [row for _, row in rows], bruise)
    for frame in frames:
        frame.label = labels.get(frame.row, '')
    return frames


def animation_rows(series: TimeSeries, count: int) -> list[tuple[str, int]]:
    """About ``count`` rows evenly spread in time over the run, plus its key moments."""
    events = find_events(series)
    moments = key_moments(series, events)
    t = series['time_s']
    times = [t[0] + (t[-1] - t[0]) * k / max(count - 1, 1) for k in range(count)]
    rows = {int(min(len(t) - 1, max(0, (abs(t - x)).argmin()))) for x in times}
    named = dict((row, label) for label, row in moments)
    rows |= set(named)
    return [(named.get(row, ''), row) for row in sorted(rows)]


def _analyze_run(bag: BagReader, topics: dict, series: TimeSeries, header: dict[str, Any],
                 out: Path, *, figures_on: bool, html: bool, bruise: float,
                 frames_in_html: int, done: Callable[[int], None]) -> tuple[dict, list[Path]]:
    """Write one run's outputs into ``out``; ``done(k)`` after each of ``OUTPUTS``."""
    summary = {**header, **summarize(series, bruise_pressure=bruise)}
    _mkdir(out)
    files = [out / 'timeseries.csv', out / 'summary.json']
    write_csv(series, files[0])
    done(1)
    if figures_on:
        events = find_events(series)
        fit = fit_stiffness(series, events)
        files.append(figures.save(figures.force_vs_time(series, summary, events),
                                  out / 'force_vs_time.png'))
        files.append(figures.save(figures.force_vs_compression(series, summary, fit),
                                  out / 'force_vs_compression.png'))
        done(2)
        snapshots = run_frames(bag, topics['markers'], series,
                               key_moments(series, events), bruise)
        if snapshots and series.dimension == 3:
            files.append(figures.save(figures.mesh_snapshots(series, snapshots, summary),
                                      out / 'mesh_snapshots.png'))
        elif snapshots:
            files.append(figures.save(figures.outline_snapshots(series, snapshots, summary),
                                      out / 'outline_snapshots.png'))
        if series.dimension == 3 and topics['nodes'] is not None:
            row = int(series['grip_force_n'].argmax())
            cloud = cloud_at(bag, topics['nodes'], int(series.log_times[row]),
                             int(series.stamps[row]))
            if cloud is not None:
                fig, patches = figures.contact_patch(series, cloud)
                files.append(figures.save(fig, out / 'contact_patch.png'))
                summary['contact_patches_at_peak_force'] = patches
        done(3)
        if html:
            frames = run_frames(bag, topics['markers'], series,
                                animation_rows(series, frames_in_html), bruise)
            files.append(report_html.write_grasp_report(series, summary, frames,
                                                        out / 'report.html'))
    done(OUTPUTS)
    # last: the 3D contact patch figure adds its measured patches to the summary
    _write_json(files[1], summary)
    return summary, files


def _write_json(path: Path, data: dict) -> None:
    try:
        path.write_text(json.dumps(data, indent=2) + '\n', encoding='utf-8')
    except OSError as err:
        raise RecordingError(f'cannot write {path}: {err.strerror}') from err


def analyze(path: str | os.PathLike, output_dir: str | os.PathLike, *,
            namespace: str | None = None, figures: bool = True, html: bool = True,
            frames_in_html: int = 60, progress: Progress | None = None,
            overwrite: bool = False) -> AnalysisResult:
    """Analyse the grasp(s) recorded in ``path``; write CSV, JSON, PNGs and the HTML
    report (``report.html``) to ``output_dir``, one set per run.

    Args:
        figures: write the PNG figures (and the HTML report when ``html``).
        html: write ``report.html`` (needs ``figures``).
        frames_in_html: about how many moments the report's animation shows per run.
        progress: told how far the reading and the runs are.
        overwrite: write into ``output_dir`` if it exists (else refused).

    Raises:
        RecordingError: bad file, no FruitState topic, ``output_dir`` exists (without
            ``overwrite``) or its parent does not, or the output cannot be written.
    """
    out = Path(output_dir)
    with BagReader(path) as bag:
        topics = find_topics(bag, namespace)
        check_output_dir(out, overwrite=overwrite)   # after the input's own errors
        config = read_config(bag)
        bruise = float(config.get('fruit.bruise_pressure', DEFAULT_BRUISE_PRESSURE))
        reading = None if progress is None else \
            (lambda done, total: progress('reading', done, total))
        runs = split_runs(read_time_series(bag, topics, reading))
        header = {'file': str(Path(path)), 'fruit_state_topic': topics['state'],
                  'left_wrench_topic': topics['left'], 'right_wrench_topic': topics['right'],
                  'fruit': config.get('fruit.name'),
                  'finger': config.get('gripper.finger.name')}
        summaries: list[dict] = []
        files: list[Path] = []
        _mkdir(out)
        for k, series in enumerate(runs):
            stage = f'run {k + 1} of {len(runs)}'

            def done(count: int, stage: str = stage) -> None:
                if progress is not None:
                    progress(stage, count, OUTPUTS)
            done(0)
            run_dir = out if len(runs) == 1 else out / f'run_{k + 1}'
            run_header = header if len(runs) == 1 else \
                {**header, 'run': k + 1, 'runs': len(runs)}
            summary, written = _analyze_run(bag, topics, series, run_header, run_dir,
                                            figures_on=figures, html=html and figures,
                                            bruise=bruise, frames_in_html=frames_in_html,
                                            done=done)
            summaries.append(summary)
            files += written
    if len(runs) == 1:
        return AnalysisResult(summary=summaries[0], output_dir=out, runs=summaries,
                              files=files)
    top = {**header, 'runs': summaries}
    top_files = [out / 'summary.json']
    _write_json(top_files[0], top)
    if figures and html:
        top_files.append(report_html.write_runs_index(
            summaries, [f'run_{k + 1}' for k in range(len(runs))], out / 'report.html'))
    return AnalysisResult(summary=top, output_dir=out, runs=summaries,
                          files=top_files + files)


def load_summary(output_dir: str | os.PathLike) -> dict:
    """Read back a ``summary.json``."""
    return json.loads((Path(output_dir) / 'summary.json').read_text(encoding='utf-8'))


def write_recording_report(path: str | os.PathLike, html_path: str | os.PathLike, *,
                           namespace: str | None = None,
                           frames_in_html: int = 60) -> Path:
    """Only the HTML report of the last run recorded in ``path`` (e.g. the run an
    offline verb just recorded), written to ``html_path``.

    Raises:
        RecordingError: bad file, no FruitState topic, or the report cannot be written.
    """
    with BagReader(path) as bag:
        topics = find_topics(bag, namespace)
        config = read_config(bag)
        bruise = float(config.get('fruit.bruise_pressure', DEFAULT_BRUISE_PRESSURE))
        series = split_runs(read_time_series(bag, topics))[-1]
        summary = {'file': str(Path(path)), 'fruit_state_topic': topics['state'],
                   'fruit': config.get('fruit.name'),
                   'finger': config.get('gripper.finger.name'),
                   **summarize(series, bruise_pressure=bruise)}
        frames = run_frames(bag, topics['markers'], series,
                            animation_rows(series, frames_in_html), bruise)
    return report_html.write_grasp_report(series, summary, frames, html_path)
