"""The 2D soft pad's force law is one compiled function (``pad.pad_point``) behind the
pad layer of the generic route and the compiled step (``kernels``): its rows, energy and
forces equal the numpy reference (``reference_pad2d``) to round-off, and the compiled
step's rows and forces are the layer's bit for bit."""
import numpy as np
import pytest

from gripper_sim.core import kernels
from gripper_sim.core.obstacles import FlatFace
from gripper_sim.core.pad import PadLayer
from gripper_sim.geometry.shapes import circle

from reference_pad2d import PadStep

DT = 1e-3
THICKNESS = 2e-3


def _pads(seed):
    """A ring pressed into both jaws' pads while they close and lift: every term active
    (penalty, static and kinetic friction). (pad, x_n (n, 2), q (2n,), old and new
    faces, face_par, face_dyn of the compiled step's layout)."""
    rng = np.random.default_rng(seed)
    x0 = circle(0.06, 24)
    n = len(x0)
    pad = PadLayer(np.arange(n), np.full(n, 0.008), 0.04, THICKNESS, 2e5, 0.45, 0.8, n)
    faces = {}
    for side, sign in ((0, -1.0), (1, 1.0)):
        origin = np.array([sign * (0.03 + THICKNESS - 4e-4), 0.0])
        velocity = np.array([-sign * 0.05, 0.02])
        faces[side] = [FlatFace(name, o, np.array([-sign, 0.0]), half_length=0.01,
                                thickness=0.01, velocity=velocity)
                       for name, o in (('old', origin), ('new', origin + DT * velocity))]
    old = [(faces[s][0], s, s) for s in (0, 1)]
    new = [(faces[s][1], s, s) for s in (0, 1)]
    pad.begin_step(x0, old, new, DT)
    # up with the jaws (2e-5 m), plus a creep below (sticking) or above (sliding) the
    # smoothing's 1e-7 m
    creep = np.where(rng.random(n) < 0.5, 2e-8, 5e-7)
    moved = np.stack([rng.normal(scale=1e-6, size=n), 2e-5 + creep], axis=1)
    q = (x0 + moved).ravel()
    face_par = np.zeros((2, kernels.FP_SIZE))
    face_dyn = np.zeros((2, 6))
    for s in (0, 1):
        face_par[s, :3] = (*faces[s][0].normal, 0.01)
        face_par[s, kernels.FP_JAW] = s
        face_dyn[s] = (*faces[s][0].origin, *faces[s][1].origin, *faces[s][1].velocity)
    return pad, x0, q, old, new, face_par, face_dyn


@pytest.mark.parametrize('seed', [0, 1])
def test_the_pad_layer_equals_the_numpy_reference(seed):
    pad, x0, q, old, new, _, _ = _pads(seed)
    reference = PadStep(pad, x0, old, new, DT)
    assert len(pad.nodes) == sum(len(face[6]) for face in reference.faces) >= 6
    got, want = pad.evaluate(q), reference.evaluate(q)
    assert got.value == pytest.approx(want.value, rel=1e-12) and want.value > 0
    np.testing.assert_allclose(got.gradient, want.gradient, rtol=0,
                               atol=1e-12 * np.abs(want.gradient).max())
    assert np.array_equal(got.rows, want.rows) and np.array_equal(got.cols, want.cols)
    np.testing.assert_allclose(got.vals, want.vals, rtol=1e-12, atol=0)
    pad.finish_step(q)
    forces, normal, holder, side_force = reference.forces(q)
    scale = np.abs(forces).max()
    np.testing.assert_allclose(pad.forces, forces, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(pad.normal_forces, normal, rtol=0, atol=1e-12 * scale)
    assert np.array_equal(pad.holder, holder) and set(holder[holder >= 0]) == {0, 1}
    np.testing.assert_allclose(pad.side_force, side_force, rtol=1e-12)
    creep = q.reshape(-1, 2)[pad.nodes, 1] - x0[pad.nodes, 1] - 2e-5  # m, on the jaw
    assert creep.min() < 1e-4 * DT < creep.max()  # sticking and sliding nodes


def test_the_compiled_steps_pads_are_the_layers():
    pad, x0, q, _, _, face_par, face_dyn = _pads(2)
    nodes, rows, face = kernels._pad_rows(x0, pad.surface, pad.k, pad.thickness, pad.mu,
                                          face_par, face_dyn)
    assert np.array_equal(nodes, pad.nodes) and np.array_equal(face, pad.row_face)
    assert np.array_equal(rows, pad.rows)
    grad = np.zeros(q.size)
    value = kernels.pad_terms(q, x0.ravel(), DT, nodes, rows, grad)
    reference = pad.evaluate(q)
    assert value == reference.value and np.array_equal(grad, reference.gradient)
    n = len(x0)
    out = (np.empty((n, 2)), np.empty(n), np.empty(n, np.int64), np.empty(2))
    kernels._pad_forces(q.reshape(-1, 2), x0, DT, nodes, rows, face, face_par, *out)
    pad.finish_step(q)
    for got, want in zip(out, (pad.forces, pad.normal_forces, pad.holder, pad.side_force)):
        assert np.array_equal(got, want)
