"""The 2D solid pad's grid (``gripper.finger.type: solid_pad``, ``core.solid_pad``): its
cells along the jaw height, and the check of a pad that would be meshed too finely."""
from __future__ import annotations

import math

from gripper_sim.errors import ConfigError

PREFIX = 'gripper.finger.solid_pad.'
#: cells a 2D pad may have along the jaw height at most (its cells are about square,
#: ``thickness / layers`` wide; the default pad has 27 rows): finer, and its mesh and
#: the matrices of its contact pairs outgrow any memory
MAX_ROWS = 400


def row_count(thickness: float, height: float, layers: int) -> int:
    """Cells along the height ``height`` (m) of a pad ``thickness`` (m) thick with
    ``layers`` cells across it: about square, at least 2."""
    return max(2, int(round(height / (thickness / layers))))


def check_solid_pad(config) -> None:
    """ConfigError naming the key if the 2D solid pad of ``config`` would have more than
    ``MAX_ROWS`` rows of cells (only when ``gripper.finger.type`` is solid_pad; the 3D
    pad's cells along the height are capped, ``core3d.soft_fingers3d``)."""
    if config.get('gripper.finger.type') != 'solid_pad' or config.get('dimension', 2) == 3:
        return
    thickness = float(config[PREFIX + 'thickness'])
    layers = int(config[PREFIX + 'layers'])
    height = float(config['gripper.jaw_height'])
    rows = height * layers / thickness
    if rows > MAX_ROWS:
        thinnest = math.ceil(1e6 * height * layers / MAX_ROWS) / 1e6
        raise ConfigError(
            f"config key '{PREFIX}thickness' = {thickness:g} m: too thin for its {layers} "
            f'layers: its square cells ({thickness / layers:.3g} m) would take {rows:.3g} '
            f'rows along the jaw height ({height:g} m), at most {MAX_ROWS}: use a thickness '
            f'of {thinnest:g} m or more, or fewer layers ({PREFIX}layers)')
