"""The solid pad's grid (``gripper.finger.type: solid_pad``, ``core.solid_pad``): its
cells along the jaw height, and the check of a pad too thin for its layers."""
from __future__ import annotations

import math

from gripper_sim.errors import ConfigError

PREFIX = 'gripper.finger.solid_pad.'
#: how many times smaller than the jaw height a pad's cells across its thickness
#: (``thickness / layers``) may be at most: the 2D pad's cells are about square, so as
#: many rows of them along the height (the default pad: 27); finer, and its mesh and the
#: matrices of its contact pairs outgrow any memory (the 3D pad caps its rows, but its
#: cells then grow as flat)
MAX_ROWS = 400


def row_count(thickness: float, height: float, layers: int) -> int:
    """Cells along the height ``height`` (m) of a 2D pad ``thickness`` (m) thick with
    ``layers`` cells across it: about square, at least 2."""
    return max(2, int(round(height / (thickness / layers))))


def check_solid_pad(config) -> None:
    """ConfigError naming the key if the solid pad of ``config`` has cells across its
    thickness more than ``MAX_ROWS`` times smaller than the jaw height (only when
    ``gripper.finger.type`` is solid_pad)."""
    if config.get('gripper.finger.type') != 'solid_pad':
        return
    thickness = float(config[PREFIX + 'thickness'])
    layers = int(config[PREFIX + 'layers'])
    height = float(config['gripper.jaw_height'])
    ratio = row_count(thickness, height, layers)
    if ratio > MAX_ROWS:
        thinnest = math.ceil(1e6 * height * layers / MAX_ROWS) / 1e6
        raise ConfigError(
            f"config key '{PREFIX}thickness' = {thickness:g} m: too thin for its {layers} "
            f'layers: its cells across it ({thickness / layers:.3g} m) are {ratio:.3g} '
            f'times smaller than the jaw height ({height:g} m), at most {MAX_ROWS} (the 2D '
            f'pad meshes that many rows of square cells): use a thickness of {thinnest:g} '
            f'm or more, or fewer layers ({PREFIX}layers)')
