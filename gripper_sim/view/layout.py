"""The Foxglove layout of the live view, built with ``foxglove.layouts``.

``config/foxglove/gripper_sim_layout.json`` is this layout for the node named
``gripper_sim`` in the root namespace; write it again with::

    python -m gripper_sim.view.layout config/foxglove/gripper_sim_layout.json

Panels: the 3D scene (``/gripper_sim/scene``; the ROS markers, which draw the same,
hidden), plots of grip force (N), compression (m) and slip distance (m) on their own
axes, and the fruit state message.

The 3D panel's camera states every field Foxglove would otherwise fill from its own
defaults: those (a near plane 0.5 m from the camera, the orbit centred on the frame's
origin), made for scenes metres across, hid the whole gripper scene.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import foxglove.layouts as fl

from gripper_sim.view.foxglove import node_topics, scene_topic

#: m, the point of frame ``world`` the 3D panel's camera orbits and looks at: between
#: the pressure colour bar (about 0.17 m to the -x side of the fruit) and the jaws, a
#: little above the table
CAMERA_TARGET = (-0.06, 0.0, 0.05)
CAMERA_DISTANCE = 0.45   # m from the target: the bar, its labels and the jaws in view
CAMERA_PHI = 70.0        # degrees from the vertical: 20 degrees down onto the x-z plane
CAMERA_FOVY = 45.0       # degrees, vertical field of view
#: m, the near and far clipping planes: everything from 1 cm to 10 m of the camera
CAMERA_NEAR, CAMERA_FAR = 0.01, 10.0


def _plot(title: str, path: str, label: str) -> fl.SplitItem:
    return fl.SplitItem(content=fl.PlotPanel(
        title=title,
        config=fl.PlotConfig(paths=[fl.PlotSeries(value=path, label=label)],
                             show_legend=True, y_axis_label=label)))


def camera_state() -> fl.ThreeDeeCameraState:
    """The 3D panel's camera: looking at ``CAMERA_TARGET`` from the -y side (theta 0),
    every field given (Foxglove's own defaults clip a scene this small)."""
    return fl.ThreeDeeCameraState(
        distance=CAMERA_DISTANCE, phi=CAMERA_PHI, theta_offset=0.0,
        target=(0.0, 0.0, 0.0), target_offset=CAMERA_TARGET,
        target_orientation=(0.0, 0.0, 0.0, 1.0), perspective=True, fovy=CAMERA_FOVY,
        near=CAMERA_NEAR, far=CAMERA_FAR)


def build_layout(node_name: str = 'gripper_sim', namespace: str = '/') -> fl.Layout:
    """The layout for the node ``node_name`` in ``namespace``."""
    topics = {suffix: name for suffix, (name, _) in node_topics(node_name, namespace).items()}
    state = topics['fruit/state']
    scene = fl.ThreeDeePanel(title='grasp (contact pressure colour scale beside the fruit)',
                             config=fl.ThreeDeeConfig(
        follow_tf='world',
        camera_state=camera_state(),
        topics={scene_topic(topics['markers']): fl.BaseRendererSceneUpdateTopicSettings(
                    visible=True),
                topics['markers']: fl.BaseRendererRosMarkerTopicSettings(visible=False)}))
    plots = fl.SplitContainer(direction='column', items=[
        _plot('grip force', f'{state}.grip_force', 'grip force (N)'),
        _plot('compression', f'{state}.compression', 'compression (m)'),
        _plot('slip', f'{state}.slip_distance', 'slip distance (m)'),
        fl.SplitItem(content=fl.RawMessagesPanel(
            title='fruit state', config=fl.RawMessagesConfig(topic_path=state,
                                                             expansion='all')))])
    return fl.Layout(content=fl.SplitContainer(direction='row', items=[
        fl.SplitItem(proportion=3, content=scene), fl.SplitItem(proportion=2, content=plots)]))


def layout_json(node_name: str = 'gripper_sim', namespace: str = '/') -> str:
    """``build_layout`` as indented JSON text (ends with a newline)."""
    return json.dumps(json.loads(build_layout(node_name, namespace).to_json()), indent=2) + '\n'


def main(argv: list[str] | None = None) -> int:
    """Write the layout to the file given (or print it)."""
    args = sys.argv[1:] if argv is None else argv
    text = layout_json()
    if args:
        Path(args[0]).write_text(text, encoding='utf-8')
    else:
        sys.stdout.write(text)
    return 0


if __name__ == '__main__':
    sys.exit(main())
