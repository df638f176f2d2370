"""The live view: the node's topics and a 3D scene served to Foxglove over WebSocket.

``scene`` turns the node's markers into a Foxglove ``SceneUpdate`` (pure functions);
``foxglove`` runs the server (``foxglove-sdk``) for the node and for ``replay``;
``layout`` builds the Foxglove layout shipped in ``config/foxglove/``.
"""
from gripper_sim.view.errors import ViewError

__all__ = ['ViewError']
