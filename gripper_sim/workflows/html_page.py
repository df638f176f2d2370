"""Self-contained HTML pages of plotly figures: the settings every page of the project
uses, and the writing of a page (the grasp, window, study and calibration reports)."""
from __future__ import annotations

import html
from pathlib import Path

import plotly.graph_objects as go

from gripper_sim.errors import GripperSimError

#: plotly's settings of every page: no logo link to plotly.com
PLOTLY_CONFIG = {'displaylogo': False}


class PageWriteError(GripperSimError):
    """An HTML page cannot be written."""


def write_page(path: str | Path, page: str) -> Path:
    """Write the HTML ``page`` to ``path``; PageWriteError if it cannot be written."""
    target = Path(path)
    try:
        target.write_text(page, encoding='utf-8')
    except OSError as err:
        raise PageWriteError(f'cannot write {target}: {err.strerror}') from err
    return target


def write_figure_page(path: str | Path, title: str, figure: go.Figure) -> Path:
    """Write one figure as a self-contained page (plotly's JavaScript embedded) named
    ``title`` in the browser tab, with ``PLOTLY_CONFIG``.

    Raises:
        PageWriteError: the file cannot be written.
    """
    page = figure.to_html(include_plotlyjs=True, full_html=True, config=PLOTLY_CONFIG)
    page = page.replace('<head>', f'<head><meta charset="utf-8">'
                                  f'<title>{html.escape(title)}</title>', 1)
    return write_page(path, page)
