"""Mass properties of the flattened sphere (paper Appendix A.2).

The flat face is normal to the body z axis at height ``r cos(phi/2)`` above the full-sphere
centre, so the centre of gravity lies ``d_cog`` below that centre on the body z axis.
"""

import dataclasses
import math

import numpy as np
from numpy.typing import NDArray


@dataclasses.dataclass(frozen=True)
class MassProperties:
    """Mass properties derived from radius, cut angle and density.

    Attributes
    ----------
    volume_m3, mass_kg : float
    cog_offset_m : float
        Distance d_cog from the full-sphere centre down to the centre of gravity.
    inertia_centre_kg_m2 : ndarray, shape (3,)
        Principal inertia about the full-sphere centre, eq. (A4)-(A6).
    inertia_cog_kg_m2 : ndarray, shape (3,)
        Principal inertia about the centre of gravity, eq. (A7).
    """

    volume_m3: float
    mass_kg: float
    cog_offset_m: float
    inertia_centre_kg_m2: NDArray[np.float64]
    inertia_cog_kg_m2: NDArray[np.float64]


def cap_height_m(radius_m: float, cut_angle_rad: float) -> float:
    return radius_m * (1.0 - math.cos(0.5 * cut_angle_rad))


def cut_sphere_volume_m3(radius_m: float, cut_angle_rad: float) -> float:
    h = cap_height_m(radius_m, cut_angle_rad)
    return 4.0 / 3.0 * math.pi * radius_m**3 - math.pi * h**2 * (3.0 * radius_m - h) / 3.0


def cog_offset_m(radius_m: float, cut_angle_rad: float) -> float:
    """d_cog: the removed cap's first moment divided by the remaining volume."""
    h = cap_height_m(radius_m, cut_angle_rad)
    cap_volume = math.pi * h**2 * (3.0 * radius_m - h) / 3.0
    if cap_volume == 0.0:
        return 0.0
    cap_centroid = 3.0 * (2.0 * radius_m - h) ** 2 / (4.0 * (3.0 * radius_m - h))
    return cap_volume * cap_centroid / cut_sphere_volume_m3(radius_m, cut_angle_rad)


def mass_properties(radius_m: float, cut_angle_rad: float, density_kg_m3: float | None = None,
                    mass_kg: float | None = None) -> MassProperties:
    """Mass properties of the cut sphere; give either the density or the mass.

    Returns
    -------
    MassProperties
    """
    if (density_kg_m3 is None) == (mass_kg is None):
        raise ValueError('give exactly one of density_kg_m3 and mass_kg')
    volume = cut_sphere_volume_m3(radius_m, cut_angle_rad)
    # Exactly one of the two is given (checked above): mass_kg is a float where it is used.
    density = (density_kg_m3 if density_kg_m3 is not None
               else mass_kg / volume)  # type: ignore[operator]
    mass = density * volume
    c2 = math.cos(0.5 * cut_angle_rad)
    c4 = math.cos(0.25 * cut_angle_rad)
    r5 = radius_m**5
    theta_xx = (r5 * math.pi / 60.0 * (c2 + 1.0) ** 2
                * (16.0 - 9.0 * c2**3 + 18.0 * c2**2 - 17.0 * c2))
    theta_zz = 8.0 / 15.0 * r5 * math.pi * c4**6 * (10.0 + 6.0 * c4**4 - 15.0 * c4**2)
    centre = density * np.array([theta_xx, theta_xx, theta_zz])
    d_cog = cog_offset_m(radius_m, cut_angle_rad)
    cog = centre - mass * d_cog**2 * np.array([1.0, 1.0, 0.0])
    return MassProperties(volume, mass, d_cog, centre, cog)
