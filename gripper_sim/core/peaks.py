"""The peaks of a run, measured the same way by every verb: grip force, compression and
contact pressure, the jaws' pressure apart from the table's.

An observer: call it with every ``StepResult`` (2D or 3D). ``pick``, ``squeeze``, ``run``,
``window``, studies and the node's Grasp action all read their peaks from it.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np
from numba import njit

from gripper_sim.core.results import StepResult

#: obstacle names (before any '.part') whose contact pressure is the jaws'
JAWS = ('left_jaw', 'right_jaw')
#: obstacle name of the table
TABLE = 'table'


@lru_cache(maxsize=64)
def _site_tables(names: tuple) -> tuple[np.ndarray, np.ndarray]:
    """(n_obstacles + 1,) bool each, indexed by obstacle + 1 (-1: free): the obstacle is a
    face of a jaw, the table. Kept per obstacle-name tuple (one per face set)."""
    base = [name.split('.')[0] for name in names]
    jaw = np.array([False] + [name in JAWS for name in base])
    table = np.array([False] + [name == TABLE for name in base])
    return jaw, table


def site_codes(names: tuple) -> np.ndarray:
    """(n_obstacles + 1,) int64, indexed by obstacle + 1 (0: free): 1 a face of a jaw, 2 the
    table, else 0 (the tables of ``contact_pressures``, for the compiled advance)."""
    jaw, table = _site_tables(tuple(names))
    return np.where(jaw, 1, np.where(table, 2, 0)).astype(np.int64)


@lru_cache(maxsize=64)
def _kept_site_codes(names: tuple) -> np.ndarray:
    """``site_codes`` kept per obstacle-name tuple (read only)."""
    codes = site_codes(names)
    codes.flags.writeable = False
    return codes


@njit(cache=True)
def _site_maxima(pressure, obstacle, surface, site):
    """(jaw, table) Pa: the largest of 0 and ``pressure`` (n_s,) Pa at the surface nodes
    ``surface`` (n_s,) whose obstacle (``obstacle`` (n,), -1 none) is a jaw's face
    (``site``, indexed by obstacle + 1: 1) or the table (2); as ``np.maximum`` takes
    them (a NaN wins, ties keep the first)."""
    jaw = table = 0.0
    for s in range(surface.shape[0]):
        where = site[obstacle[surface[s]] + 1]
        p = pressure[s]
        if where == 1 and not (jaw >= p or jaw != jaw):
            jaw = p
        elif where == 2 and not (table >= p or table != table):
            table = p
    return jaw, table


def _sites(result: StepResult) -> tuple[np.ndarray, np.ndarray]:
    """(n_surface,) bool each: the surface node touches a jaw (any face of it), the table."""
    owner = np.asarray(result.contact_obstacle)[result.surface] + 1
    jaw, table = _site_tables(tuple(result.obstacle_names))
    return jaw[owner], table[owner]


def damage_site(result: StepResult) -> str | None:
    """Where the damage pressure (``Damage.node_pressure``) of this step is largest:
    'jaws', 'table', or None (no damage model, no pressure, or elsewhere)."""
    damage = result.damage
    if damage is None or not np.size(damage.node_pressure):
        return None
    pressure = np.asarray(damage.node_pressure)
    node = int(np.argmax(pressure))
    if pressure[node] <= 0:
        return None
    on_jaw, on_table = _sites(result)
    return 'jaws' if on_jaw[node] else 'table' if on_table[node] else None


#: (result, its contact_pressures): the last one computed (a run's observers all ask)
_last_pressures: tuple = (None, (0.0, 0.0))


def contact_pressures(result: StepResult) -> tuple[float, float]:
    """(jaw pressure, table pressure) in Pa: the largest contact pressure at a surface
    node held by a jaw (by any face of it), and at one resting on the table.

    The pressure of a node is ``Deformation.node_pressure`` (2D: normal force over the
    tributary length times the depth, a planar line contact; 3D: over the vertex area,
    resolved over the patch).
    """
    global _last_pressures
    last = _last_pressures
    if last[0] is result:
        return last[1]
    pressure = np.asarray(result.deformation.node_pressure)
    if not pressure.size:
        pressures = 0.0, 0.0
    else:  # pressure[mask].max(initial=0.0) of each site's mask, in one compiled pass
        pressures = _site_maxima(pressure, np.asarray(result.contact_obstacle),
                                 np.asarray(result.surface),
                                 _kept_site_codes(tuple(result.obstacle_names)))
    _last_pressures = (result, pressures)
    return pressures


class RunPeaks:
    """Largest values over the steps seen.

    Attributes:
        grip_force: N, largest measured grip force (mean jaw normal force).
        compression: m, largest loss of width along the closing axis.
        jaw_pressure: Pa, largest contact pressure at the jaws (``contact_pressures``).
        table_pressure: Pa, largest contact pressure on the table.
        bruised_at: where the fruit first bruised ('jaws', 'table'; ``damage_site`` of
            the first bruised step), or None.
    """

    def __init__(self):
        self.grip_force = self.compression = 0.0
        self.jaw_pressure = self.table_pressure = 0.0
        self.bruised_at: str | None = None

    def __call__(self, result: StepResult) -> None:
        self.grip_force = max(self.grip_force, float(result.grip_force))
        self.compression = max(self.compression, float(result.deformation.compression))
        jaw, table = contact_pressures(result)
        self.jaw_pressure = max(self.jaw_pressure, jaw)
        self.table_pressure = max(self.table_pressure, table)
        if self.bruised_at is None and result.damage is not None and result.damage.bruised:
            self.bruised_at = damage_site(result)

    def include(self, peaks: tuple) -> None:
        """Raise the peaks to those of steps this object did not see: (grip force N,
        compression m, jaw pressure Pa, table pressure Pa), as
        ``Simulation.advance`` gives them."""
        grip_force, compression, jaw, table = peaks
        self.grip_force = max(self.grip_force, grip_force)
        self.compression = max(self.compression, compression)
        self.jaw_pressure = max(self.jaw_pressure, jaw)
        self.table_pressure = max(self.table_pressure, table)

    def as_dict(self) -> dict[str, float]:
        """The peaks under their vocabulary keys (``gripper_sim.core.vocabulary``)."""
        return dict(peak_grip_force=self.grip_force, peak_compression=self.compression,
                    peak_jaw_pressure=self.jaw_pressure,
                    peak_table_pressure=self.table_pressure, bruised_at=self.bruised_at)
