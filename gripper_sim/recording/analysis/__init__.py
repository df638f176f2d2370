"""Offline analysis of a recorded grasp, from the MCAP file alone (no ROS graph).

Reads the sim node's ``FruitState`` topic (and, when recorded, the two jaw wrenches,
``/joint_states``, the markers and the node point cloud), cuts it into runs at resets,
and writes per run:

- ``timeseries.csv``: one row per FruitState message (``series.COLUMNS``);
- ``summary.json``: peaks, the stiffness of the loading part and the range it was
  fitted on, held/slipped (the node's rule, ``gripper_sim.core.slip.grasp_slipped``,
  on the centroid's drop: a recording has no contact slide), the phases found, contact
  size, damage;
- ``force_vs_time.png``, ``force_vs_compression.png``; ``outline_snapshots.png`` (2D)
  or ``mesh_snapshots.png`` and ``contact_patch.png`` (3D);
- ``report.html``: the same as an interactive page with an animation of the fruit.

Modules: ``series`` (reading, runs), ``events`` (phases), ``frames`` (the geometry of
chosen moments), ``summary`` (numbers, CSV), ``figures`` (PNGs), ``report_html`` (HTML
pages), ``outputs`` (``analyze``). Messages are decoded with ``mcap-ros2-support`` from
the schemas stored in the file, so the analysis runs without ROS installed.
"""
from gripper_sim.recording.analysis.frames import (cloud_array, jaw_contact_nodes,
                                                   patch_outline)
from gripper_sim.recording.analysis.outputs import (AnalysisResult, analyze, load_summary,
                                                    write_recording_report)
from gripper_sim.recording.analysis.series import (COLUMNS, TimeSeries, find_topics,
                                                   read_config, read_time_series,
                                                   split_runs)
from gripper_sim.recording.analysis.summary import fit_stiffness, summarize, write_csv

__all__ = ['COLUMNS', 'AnalysisResult', 'TimeSeries', 'analyze', 'cloud_array',
           'find_topics', 'fit_stiffness', 'jaw_contact_nodes', 'load_summary',
           'patch_outline', 'read_config', 'read_time_series', 'split_runs', 'summarize',
           'write_csv', 'write_recording_report']
