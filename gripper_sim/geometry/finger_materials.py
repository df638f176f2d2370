"""Materials of deformable fingers (``gripper.finger.fin_ray.material``), with sources.

Small-strain Young moduli of the elastomers soft fingers are printed or cast from. Both
vary with the grade and, for printed TPU, with the printing (nozzle, raster direction):
the value below is one measured figure, the source gives its spread. ``custom`` takes
``gripper.finger.fin_ray.youngs_modulus`` and ``gripper.finger.fin_ray.density``.
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class FingerMaterial:
    """Attributes:
        youngs_modulus: Pa (small strain).
        density: kg/m^3.
        source: where the modulus (and density) come from.
        poisson_ratio: - (elastomers: nearly incompressible; an estimate, used for the
            contact modulus of the finger's surface in the damage estimate).
    """

    youngs_modulus: float
    density: float
    source: str
    poisson_ratio: float = 0.45


MATERIALS: dict[str, FingerMaterial] = {
    # material-extrusion printed TPU: 100.4 MPa (0.4 mm nozzle, 90 deg raster) to
    # 145.8 MPa (0.8 mm nozzle, 0 deg), Eng. Proc. 2025, 113(1), 19; four additively
    # manufactured TPUs measured 24 - 247 MPa quasi-static (Haid, Duncan, Hart & Foster,
    # "Characterisation of thermoplastic polyurethane (TPU) for additive manufacturing",
    # 14th Symposium of the dvs section Sportinformatik und Sporttechnologie); density of
    # TPU 95A filament 1.22 g/cm^3 (Ultimaker TPU 95A material profile)
    'tpu': FingerMaterial(100.4e6, 1220.0,
                          'printed TPU, Eng. Proc. 2025, 113(1), 19 (100.4-145.8 MPa); '
                          'Haid et al. (24-247 MPa)'),
    # Dragon Skin 30 silicone: 100 % tensile modulus 86 psi (0.593 MPa, a secant modulus
    # near the small-strain E of this rubber), specific gravity 1.08 (Smooth-On, Dragon
    # Skin series technical bulletin; the solid pad finger's default too)
    'silicone': FingerMaterial(0.593e6, 1080.0,
                               'Dragon Skin 30, 100 % modulus 0.593 MPa (Smooth-On technical '
                               'bulletin)'),
}

#: the material names ``gripper.finger.fin_ray.material`` accepts
MATERIAL_NAMES = tuple(MATERIALS) + ('custom',)

#: how a planar finger's members bend over its depth (``gripper.finger.fin_ray.section``):
#: as beams (plane stress) or as plates (plane strain across the depth)
SECTIONS = ('beam', 'plate')
