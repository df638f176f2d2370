"""A linear plane frame by the direct stiffness method: the reference the Fin Ray's rod
model is checked against.

Each rod edge is an Euler-Bernoulli frame element (axial EA / L, bending 12 EI / L^3 ...;
Przemieniecki, "Theory of Matrix Structural Analysis", ch. 5), exact for loads at nodes.
Three dofs per node (u_x, u_z, rotation); members that meet at a node share its rotation
(rigid joints); the base nodes are clamped. Independent of the rod model's joints and
its discrete curvature: only the layout (nodes, members) and the section properties are
shared.
"""
import numpy as np


def frame_displacements(positions, members, axial, bending, base_nodes, forces):
    """(n, 2) m, the linear displacements of the frame's nodes.

    Args:
        positions: (n, 2) m.  members: node chains (arrays), each a straight member.
        axial, bending: EA (N) and EI (N m^2), one per member.
        base_nodes: clamped nodes.  forces: (n, 2) N at the nodes.
    """
    n = len(positions)
    k = np.zeros((3 * n, 3 * n))
    for nodes, ea, ei in zip(members, axial, bending):
        for a, b in zip(nodes[:-1], nodes[1:]):
            d = positions[b] - positions[a]
            length = float(np.hypot(*d))
            c, s = d / length
            local = np.zeros((6, 6))
            local[np.ix_([0, 3], [0, 3])] = ea / length * np.array([[1, -1], [-1, 1]])
            beam = ei / length ** 3 * np.array([
                [12, 6 * length, -12, 6 * length],
                [6 * length, 4 * length ** 2, -6 * length, 2 * length ** 2],
                [-12, -6 * length, 12, -6 * length],
                [6 * length, 2 * length ** 2, -6 * length, 4 * length ** 2]])
            local[np.ix_([1, 2, 4, 5], [1, 2, 4, 5])] = beam
            rotation = np.zeros((6, 6))
            for block in (0, 3):
                rotation[block:block + 3, block:block + 3] = [[c, s, 0], [-s, c, 0],
                                                               [0, 0, 1]]
            dofs = np.r_[3 * a:3 * a + 3, 3 * b:3 * b + 3]
            k[np.ix_(dofs, dofs)] += rotation.T @ local @ rotation
    load = np.zeros(3 * n)
    load[0::3] = forces[:, 0]
    load[1::3] = forces[:, 1]
    fixed = np.zeros(3 * n, bool)
    for node in base_nodes:
        fixed[3 * node:3 * node + 3] = True
    free = ~fixed & (np.abs(k).sum(axis=1) > 0)
    u = np.zeros(3 * n)
    u[free] = np.linalg.solve(k[np.ix_(free, free)], load[free])
    return np.stack([u[0::3], u[1::3]], axis=1)
