"""The Foxglove layout of the live view, built with ``foxglove.layouts``.

``config/foxglove/gripper_sim_layout.json`` is this layout for the node named
``gripper_sim`` in the root namespace; write it again with::

    python -m gripper_sim.view.layout config/foxglove/gripper_sim_layout.json

Panels: the 3D scene (``/gripper_sim/scene``; the ROS markers, which draw the same,
hidden), plots of grip force (N), compression (m) and slip distance (m) on their own
axes, and the fruit state message.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import foxglove.layouts as fl

from gripper_sim.view.foxglove import node_topics, scene_topic


def _plot(title: str, path: str, label: str) -> fl.SplitItem:
    return fl.SplitItem(content=fl.PlotPanel(
        title=title,
        config=fl.PlotConfig(paths=[fl.PlotSeries(value=path, label=label)],
                             show_legend=True, y_axis_label=label)))


def build_layout(node_name: str = 'gripper_sim', namespace: str = '/') -> fl.Layout:
    """The layout for the node ``node_name`` in ``namespace``."""
    topics = {suffix: name for suffix, (name, _) in node_topics(node_name, namespace).items()}
    state = topics['fruit/state']
    scene = fl.ThreeDeePanel(title='grasp (contact pressure colour scale beside the fruit)',
                             config=fl.ThreeDeeConfig(
        follow_tf='world',
        camera_state=fl.ThreeDeeCameraState(distance=0.35, phi=70.0, theta_offset=0.0,
                                            target=(0.0, 0.0, 0.05), perspective=True),
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
