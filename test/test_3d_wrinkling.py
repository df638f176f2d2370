"""The wrinkling (tension-field) skin membrane: finite differences, the relaxed energy's
closed forms, and the pressurised-shell plate law it makes reachable."""
import numpy as np
import pytest
import scipy.sparse as sp

from gripper_sim.core3d.energies import Membrane
from gripper_sim.core3d.energies.wrinkling_membrane import WrinklingMembrane
from gripper_sim.core3d.meshes import geodesic_sphere

from helpers import pressed_wrinkling_shell
from reference_energies3d import (green_strains, principal_strains, wrinkling_membrane,
                                  wrinkling_states)

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
        e1, e2, _, _ = principal_strains(green_strains(skin.deformation_gradients(q)))
        if min(np.min(np.abs(e2 + NU * e1)), np.min(np.abs(e1))) > 1e-4:
            break
    counts = np.bincount(wrinkling_states(skin, q), minlength=3)
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


@pytest.mark.parametrize('scale', [0.99, 1.0, 1.01])
def test_numba_kernel_matches_the_numpy_reference(scale):
    """The skin's kernel (``evaluate_into``) gives the numpy reference's value, gradient
    and Hessian for taut, wrinkled and slack triangles."""
    skin, _, x0 = _sphere_skin()
    q = (scale * x0 + np.random.default_rng(5).normal(scale=3e-4, size=x0.shape)).ravel()
    assert np.all(np.bincount(wrinkling_states(skin, q), minlength=3) > 0)
    n = q.size
    m = skin.dofs.shape[1]
    scatter = np.repeat(skin.dofs, m, axis=1) * n + np.tile(skin.dofs, (1, m))
    grad, data = np.zeros(n), np.zeros(n * n)
    value, low_rank = skin.evaluate_into(q, grad, data, scatter, True)
    ref = wrinkling_membrane(skin, q)
    assert low_rank == []
    assert value == pytest.approx(ref.value, rel=1e-12)
    assert np.max(np.abs(grad - ref.gradient)) <= 1e-12 * np.max(np.abs(ref.gradient))
    ref_hess = sp.coo_matrix((ref.vals, (ref.rows, ref.cols)), shape=(n, n)).toarray()
    assert np.max(np.abs(data.reshape(n, n) - ref_hess)) <= 1e-12 * np.max(np.abs(ref_hess))
    grad_only, untouched = np.zeros(n), np.zeros(n * n)
    value_only, _ = skin.evaluate_into(q, grad_only, untouched, scatter, False)
    assert value_only == value and np.array_equal(grad_only, grad) and not np.any(untouched)


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
    assert np.all(wrinkling_states(sheet, q) == 1)
    assert sheet.value(q) == pytest.approx(0.5 * YOUNG * green ** 2 * THICK * 1e-4)
    # SVK's excess is the lateral compression beyond Poisson's: (lambda*/2 + mu) (E_2 + nu E_1)^2
    lateral = 0.5 * (0.97 ** 2 - 1)
    excess = 0.5 * YOUNG / (1 - NU ** 2) * (lateral + NU * green) ** 2 * THICK * 1e-4
    assert sheet_svk.value(q) - sheet.value(q) == pytest.approx(excess)


@pytest.mark.slow
def test_wrinkling_shell_on_a_plate_follows_the_cap_cut_law(capsys):
    """F ~ 2 pi p R delta (the inflated ball: the plate carries p times the flat cap cut
    off the sphere, pi a^2 = pi (2 R delta - delta^2)) for a skin stiff in tension that
    wrinkles under compression. The contact patch grows ring of nodes by ring (each
    contacting node carries p times its area; the next ring stays ~0.3 mm off the plate),
    so F(delta) is a staircase about the law: the law is checked on the least-squares
    slope F / delta over delta/R = 0.02-0.05. The same skin without wrinkling (SVK)
    carries the cap's compression, E_s t delta / (3 R), itself: several times the law
    (on a coarser mesh; on this one its Newton steps do not converge)."""
    deltas, forces, p_r = pressed_wrinkling_shell(True, (0.02, 0.03, 0.04, 0.05))
    slope = float(forces @ deltas / (deltas @ deltas))
    _, svk_force, _ = pressed_wrinkling_shell(False, (0.02,), subdivisions=8)  # finer: no convergence
    svk_ratio = svk_force[0] / (2 * np.pi * p_r * deltas[0])
    with capsys.disabled():
        print('\n  wrinkling shell on a plate, F / (2 pi p R delta) at delta/R 0.02-0.05: '
              + ', '.join(f'{v:.3f}' for v in forces / (2 * np.pi * p_r * deltas))
              + f'; least-squares slope / (2 pi p R): {slope / (2 * np.pi * p_r):.3f}'
              + f'; SVK skin at 0.02: {svk_ratio:.2f}')
    assert slope == pytest.approx(2 * np.pi * p_r, rel=0.10)
    assert svk_ratio > 2.0
