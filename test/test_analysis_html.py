"""The HTML reports in a real browser (headless Debian Chromium, offline) and the 3D mesh
figure; the ``--html`` and ``--quiet`` options and the progress bars of the CLI.

Each report is opened from disk with no network: the test takes a screenshot (not
blank), reads no JavaScript error and no request leaving the machine, and where there is
an animation clicks on its time slider and sees another frame drawn.
"""
from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import rclpy  # noqa: F401
import gripper_sim_interfaces.msg  # noqa: F401

from chromium import Browser  # noqa: E402
from gripper_sim.cli import progress  # noqa: E402
from gripper_sim.cli.main import main  # noqa: E402
from gripper_sim.configuration import load_config  # noqa: E402
from gripper_sim.recording.analysis import analyze, figures  # noqa: E402
from gripper_sim.recording.analysis.events import find_events, key_moments  # noqa: E402
from gripper_sim.recording.analysis.outputs import run_frames  # noqa: E402
from gripper_sim.recording.analysis.report_html import (ANIMATION_ID,  # noqa: E402
                                                        write_runs_index,
                                                        write_window_report)
from gripper_sim.recording.analysis.series import (find_topics, read_time_series,  # noqa: E402
                                                   split_runs)
from gripper_sim.recording.analysis.summary import summarize  # noqa: E402
from gripper_sim.recording.reader import BagReader  # noqa: E402
from gripper_sim.workflows.window import GraspWindow, Trial  # noqa: E402

pytestmark = pytest.mark.ros

COARSE_3D = ['--set', 'dimension=3', '--set', 'fruit.mesh.subdivisions=4',
             '--set', 'sim.dt=0.005']
PICK = ['pick', '--force', '2', '--lift', '0.01', '--hold', '0.05', '--quiet']


@pytest.fixture(scope='module')
def pick_3d(tmp_path_factory):
    """A coarse 3D pick recorded by the CLI, and its analysis directory."""
    folder = tmp_path_factory.mktemp('pick3d')
    path = folder / 'pick3d.mcap'
    assert main([*PICK, *COARSE_3D, '--out', str(path)]) == 0
    analyze(path, folder / 'analysis')
    return path, folder / 'analysis'


@pytest.fixture(scope='module')
def pick_2d_html(tmp_path_factory):
    """``pick --html`` of the 2D default fruit (recorded to a temporary file)."""
    folder = tmp_path_factory.mktemp('pick2d')
    assert main([*PICK, '--html', str(folder / 'pick.html')]) == 0
    return folder / 'pick.html'


def made_window() -> GraspWindow:
    """A window of trials with every kind of outcome (not simulated: the report's input)."""
    forces = [0.5, 1.0, 2.0, 4.0, 8.0]
    trials = [Trial(force=f, kind='bruise' if f >= 4.0 else 'hold', held=f >= 1.0,
                    slipped=f < 1.0, bruised=f >= 8.0,
                    outcome='dropped' if f < 1.0 else 'bruised' if f >= 8.0 else 'held',
                    slip_distance=0.01 / f, peak_grip_force=1.01 * f,
                    peak_jaw_pressure=1e4 * f, peak_table_pressure=2e3,
                    peak_damage_pressure=4e4 * f,
                    bruised_at='jaws' if f >= 8.0 else None, wall_time=1.0)
              for f in forces]
    return GraspWindow(fruit='apple', finger='flat', min_force=1.0, max_force=4.0,
                       min_estimate=0.9, max_estimate=5.0, mass=0.2, friction=0.5,
                       tolerance=0.03, trials=trials)


@pytest.fixture(scope='module')
def window_html(tmp_path_factory):
    """The window report of ``made_window``."""
    path = tmp_path_factory.mktemp('window') / 'window.html'
    write_window_report(made_window().as_dict(), path)
    return path


def not_blank(png: bytes) -> None:
    image = np.asarray(Image.open(io.BytesIO(png)).convert('L'), dtype=float)
    assert image.std() > 10.0, 'the screenshot is (nearly) one colour'
    assert len(np.unique(image)) > 50


def open_report(browser: Browser, path: Path, shot: Path) -> int:
    """Open ``path``, wait until every plot is drawn, check the page; the plot count."""
    browser.open(path)
    count = browser.wait_until(
        "(() => { const d = Array.from(document.querySelectorAll('.plotly-graph-div'));"
        " return d.length && d.every(g => g._fullLayout && g.querySelector('.main-svg'))"
        " ? d.length : 0; })()")
    not_blank(browser.screenshot(shot))
    assert browser.console_errors == []
    assert browser.remote_requests == []
    return count


def frame_state(browser: Browser) -> dict:
    gd = f"document.getElementById('{ANIMATION_ID}')"
    return json.loads(browser.evaluate(
        f"JSON.stringify({{active: {gd}._fullLayout.sliders[0].active,"
        f" title: {gd}._fullLayout.title.text,"
        f" fruit: Array.from({gd}._fullData[{gd}._fullData.length - 1].x).slice(0, 8)}})"))


def move_slider(browser: Browser, shots: Path) -> tuple[dict, dict]:
    """Click at 3/4 of the animation's slider; the frame state before and after, and
    the animation's screenshots before and after."""
    gd = f"document.getElementById('{ANIMATION_ID}')"
    browser.evaluate(f'{gd}.scrollIntoView()')
    box = json.loads(browser.evaluate(f'JSON.stringify({gd}.getBoundingClientRect())'))
    rail = json.loads(browser.evaluate(
        f"JSON.stringify({gd}.querySelector('.slider-rail-rect').getBoundingClientRect())"))
    clip = {'x': box['x'], 'y': box['y'] + browser.evaluate('window.scrollY'),
            'width': box['width'], 'height': box['height']}
    before = frame_state(browser)
    png_before = browser.screenshot(shots / 'animation_before.png', clip)
    browser.click(rail['x'] + 0.75 * rail['width'], rail['y'] + 0.5 * rail['height'])
    browser.wait_until(f'{gd}._fullLayout.sliders[0].active > 0')
    browser.wait_until(f"{gd}._fullLayout.title.text !== {json.dumps(before['title'])}")
    after = frame_state(browser)
    png_after = browser.screenshot(shots / 'animation_after.png', clip)
    not_blank(png_after)
    assert png_after != png_before
    assert browser.console_errors == []
    return before, after


def test_grasp_reports_open_offline_and_the_slider_changes_the_frame(pick_2d_html, pick_3d,
                                                                     tmp_path):
    reports = {'2d': pick_2d_html, '3d': pick_3d[1] / 'report.html'}
    with Browser() as browser:
        for name, path in reports.items():
            shots = tmp_path / name
            shots.mkdir()
            assert open_report(browser, path, shots / 'page.png') == 3
            before, after = move_slider(browser, shots)
            assert before['active'] == 0 < after['active']
            assert after['fruit'] != before['fruit'], 'the fruit did not move'
            assert before['title'].startswith('t = 0.000 s')


def test_window_report_opens_offline(window_html, tmp_path):
    with Browser() as browser:
        assert open_report(browser, window_html, tmp_path / 'window.png') == 1
        text = browser.evaluate('document.body.innerText')
    assert '1 N .. 4 N' in text and 'hold: dropped' in text and 'bruise: bruised' in text


def test_window_report_says_when_the_fingers_did_not_reach_a_grip(tmp_path):
    """A window whose bounds end at grips the fingers did not reach (the silicone Fin
    Ray's): its rows say so for each bound, and the trials read 'not reached'."""
    window = made_window()
    window.min_force = None  # 1 N slid, 2 N not reached; 4 N safe, 8 N not reached
    hold_2, bruise_8 = window.trials[2], window.trials[4]
    for trial in window.trials[:3]:
        trial.held = False
    hold_2.outcome, hold_2.peak_grip_force = 'failed', 1.5
    bruise_8.outcome, bruise_8.bruised, bruise_8.peak_grip_force = 'failed', False, 5.0
    page = write_window_report(window.as_dict(), tmp_path / 'window.html').read_text()
    assert window.min_force_limited_by == window.max_force_limited_by == 'grip not reached'
    assert 'lower bound' in page and 'so no force holds' in page
    assert 'upper bound' in page and 'the fingers deliver no more' in page
    assert 'hold: not reached' in page and 'bruise: not reached' in page
    # a hold search whose last trial did not converge says that instead
    hold_2.outcome, hold_2.peak_grip_force = 'solver failed', 2.0
    page = write_window_report(window.as_dict(), tmp_path / 'failed.html').read_text()
    assert window.min_force_limited_by == 'solver failure'
    assert 'whether it holds is not known' in page


def test_the_index_of_several_runs_links_to_their_reports(pick_3d, tmp_path):
    _path, analysis = pick_3d
    summary = json.loads((analysis / 'summary.json').read_text())
    (tmp_path / 'run_1').symlink_to(analysis, target_is_directory=True)
    index = write_runs_index([summary], ['run_1'], tmp_path / 'report.html')
    with Browser() as browser:
        browser.open(index)
        not_blank(browser.screenshot(tmp_path / 'index.png'))
        link = json.loads(browser.evaluate(
            "JSON.stringify(document.querySelector('a').getBoundingClientRect())"))
        browser.click(link['x'] + 5, link['y'] + 0.5 * link['height'])
        browser.wait_until("location.href.endsWith('run_1/report.html')")
        browser.wait_until(f"!!(document.getElementById('{ANIMATION_ID}') &&"
                           f" document.getElementById('{ANIMATION_ID}')._fullLayout)")
        assert browser.console_errors == [] and browser.remote_requests == []


def test_mesh_snapshots_show_the_patch_and_mark_the_bruise_threshold(pick_3d):
    path, _out = pick_3d
    with BagReader(path) as bag:
        topics = find_topics(bag)
        series = split_runs(read_time_series(bag, topics))[0]
        config = load_config(overrides={'dimension': 3})
        bruise = float(config['fruit.bruise_pressure'])
        summary = summarize(series, bruise_pressure=bruise)
        frames = run_frames(bag, topics['markers'], series,
                            key_moments(series, find_events(series)), bruise)
    fig = figures.mesh_snapshots(series, frames, summary)
    fig.canvas.draw()
    bar = next(ax for ax in fig.axes if figures.pressure_name(3) in ax.get_ylabel())
    shown = max(float(np.nanmax(f.pressure)) for f in frames)
    assert 0 < shown < 0.5 * bruise          # a gentle grasp: far below the threshold
    assert bar.get_ylim()[1] == pytest.approx(shown / 1e3)   # the scale ends at the peak
    assert f'bruise threshold {bruise / 1e3:.0f} kPa' in bar.get_ylabel()
    peak_ax = next(ax for ax in fig.axes if ax.get_title().startswith('peak force'))
    assert figures.pressure_name(3) in peak_ax.get_title()
    skin = next(c for c in peak_ax.collections if c.get_gid() == 'fruit pressure')
    colours = np.unique(np.round(skin.get_facecolors(), 3), axis=0)
    assert len(colours) >= 5, 'the contact patch is not told apart from the rest'
    box = peak_ax.get_position()
    size = (box.width * fig.get_figwidth(), box.height * fig.get_figheight())
    assert min(size) >= 3.0, f'3D panels of {size} in'   # were 2.1 in square


def test_html_and_quiet_options(tmp_path, capsys):
    out = tmp_path / 'a'
    path = tmp_path / 'squeeze.mcap'
    assert main(['squeeze', '--to-force', '1', '--quiet', '--out', str(path),
                 '--html', str(tmp_path / 'squeeze.html')]) == 0
    captured = capsys.readouterr()
    assert 'wrote' in captured.err and 'squeeze.html' in captured.err
    assert (tmp_path / 'squeeze.html').read_text().count('<script') >= 2
    assert main(['analyze', str(path), '-o', str(out), '--no-html', '--quiet']) == 0
    assert not (out / 'report.html').exists() and (out / 'summary.json').is_file()
    assert capsys.readouterr().err == ''     # not a terminal: no bar
    assert main(['pick', '--force', '2', '--html', str(tmp_path / 'no' / 'x.html'),
                 '--quiet', '--hold', '0']) == 2
    err = capsys.readouterr().err
    assert err.startswith('error: cannot write') and 'Traceback' not in err


def test_window_verb_writes_its_report(monkeypatch, tmp_path, capsys):
    """The verb hands its window to the report (the search itself is stubbed: it is
    tested with the window verb)."""
    monkeypatch.setattr('gripper_sim.workflows.window.grasp_window',
                        lambda config, scenario, tolerance, progress, workers=1: made_window())
    path = tmp_path / 'window.html'
    assert main(['window', '--html', str(path), '--quiet']) == 0
    out = capsys.readouterr().out
    assert 'trial' not in out and 'safe window     1 N .. 4 N' in out
    page = path.read_text()
    assert 'Grasp window of apple with the flat finger (pick_and_place)' in page
    assert '1 N .. 4 N' in page
    # the fruit's bruise pressure is drawn on the damage panel (kPa)
    from test_report_visuals import page_figures
    bruise = load_config()['fruit.bruise_pressure'] * 1e-3
    shapes = page_figures(path)[0]['layout']['shapes']
    assert any(shape['yref'] == 'y2' and shape['y0'] == shape['y1'] == pytest.approx(bruise)
               for shape in shapes), shapes


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_shows_on_a_terminal_only(monkeypatch, tmp_path):
    monkeypatch.setattr(progress, 'DELAY', 0.0)
    terminal = Terminal()
    monkeypatch.setattr('sys.stderr', terminal)
    path = tmp_path / 'squeeze.mcap'
    assert main(['squeeze', '--to-force', '0.5', '--out', str(path)]) == 0
    assert 'squeeze' in terminal.getvalue() and 'steps' in terminal.getvalue()
    assert main(['analyze', str(path), '-o', str(tmp_path / 'a'), '--no-html']) == 0
    assert 'analyze: reading' in terminal.getvalue()
    assert 'analyze: run 1 of 1' in terminal.getvalue()
    quiet = Terminal()
    monkeypatch.setattr('sys.stderr', quiet)
    assert main(['squeeze', '--to-force', '0.5', '--quiet']) == 0
    assert quiet.getvalue() == ''
    piped = io.StringIO()
    monkeypatch.setattr('sys.stderr', piped)
    assert main(['squeeze', '--to-force', '0.5']) == 0
    assert piped.getvalue() == ''
