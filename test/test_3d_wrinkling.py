"""The wrinkling (tension-field) skin membrane: finite differences, the relaxed energy's
closed forms, and the pressurised-shell plate law it makes reachable."""
import numpy as np
import pytest
import scipy.sparse as sp

from gripper_sim.core3d.energies import Membrane
from gripper_sim.core3d.energies.wrinkling_membrane import WrinklingMembrane
from gripper_sim.core3d.meshes import geodesic_sphere

RADIUS = 0.03
YOUNG, NU, THICK = 1e7, 0.3, 1e-4


def _sphere_skin():
    sphere = geodesic_sphere(2)
    x0 = RADIUS * sphere.positions
    return (WrinklingMembrane(sphere.triangles, x0, YOUNG, NU, THICK),
            Membrane(sphere.triangles, x0, YOUNG, NU, THICK), x0)


@pytest.mark.parametrize('scale', [0.99, 1.0, 1.01])
def test_gradient_and_hessian_match_central_differences(scale):
    """Random perturbations of a shrunk, a rest and a stretched sphere mix taut,
    wrinkled and slack triangles; the Hessian is symmetric positive semi-definite."""
    skin, _, x0 = _sphere_skin()
    rng = np.random.default_rng(11)
    while True:  # no triangle within the differencing step of a region boundary
        q = (scale * x0 + rng.normal(scale=3e-4, size=x0.shape)).ravel()
        e1, e2, _, _ = skin._principal(skin._green(skin.deformation_gradients(q)))
        if min(np.min(np.abs(e2 + NU * e1)), np.min(np.abs(e1))) > 1e-4:
            break
    counts = np.bincount(skin.states(q), minlength=3)
    assert np.all(counts > 0), counts
    ev = skin.evaluate(q)
    h = 1e-7
    fd = np.array([(skin.value(q + h * e) - skin.value(q - h * e)) / (2 * h)
                   for e in np.eye(q.size)])
    assert np.max(np.abs(ev.gradient - fd)) <= 1e-6 * np.max(np.abs(ev.gradient))
    hess = sp.coo_matrix((ev.vals, (ev.rows, ev.cols)), shape=(q.size, q.size)).toarray()
    fd_h = np.array([(skin.gradient(q + h * e) - skin.gradient(q - h * e)) / (2 * h)
                     for e in np.eye(q.size)])
    assert np.max(np.abs(hess - fd_h)) <= 1e-6 * np.max(np.abs(hess))
    assert np.max(np.abs(hess - hess.T)) <= 1e-12 * np.max(np.abs(hess))
    eig = np.linalg.eigvalsh(hess)
    assert eig.min() >= -1e-12 * eig.max()


def test_relaxed_energy_of_stretch_states():
    """Equibiaxial stretch: the ordinary energy; stretch along x with a lateral
    contraction beyond Poisson's: E_s / 2 E_1^2 t A, that of free uniaxial tension (SVK
    also pays for the compression beyond Poisson's); equibiaxial shrink: zero."""
    skin, svk, x0 = _sphere_skin()
    assert skin.value((1.02 * x0).ravel()) == pytest.approx(svk.value((1.02 * x0).ravel()))
    assert skin.value((0.98 * x0).ravel()) == 0.0
    assert svk.value((0.98 * x0).ravel()) > 0
    # a flat square sheet of two triangles, stretched along x only
    flat = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=float) * 0.01
    tri = np.array([[0, 1, 2], [0, 2, 3]])
    sheet = WrinklingMembrane(tri, flat, YOUNG, NU, THICK)
    sheet_svk = Membrane(tri, flat, YOUNG, NU, THICK)
    stretch = 1.05
    q = (flat * np.array([stretch, 0.97, 1.0])).ravel()  # E_2 < -nu E_1: wrinkled
    green = 0.5 * (stretch ** 2 - 1)
    assert np.all(sheet.states(q) == 1)
    assert sheet.value(q) == pytest.approx(0.5 * YOUNG * green ** 2 * THICK * 1e-4)
    # SVK's excess is the lateral compression beyond Poisson's: (lambda*/2 + mu) (E_2 + nu E_1)^2
    lateral = 0.5 * (0.97 ** 2 - 1)
    excess = 0.5 * YOUNG / (1 - NU ** 2) * (lateral + NU * green) ** 2 * THICK * 1e-4
    assert sheet_svk.value(q) - sheet.value(q) == pytest.approx(excess)
