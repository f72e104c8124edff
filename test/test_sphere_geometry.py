import math

import numpy as np
import pytest
from scipy import integrate

from sphere_sim.model.parameters import load_parameter_set
from sphere_sim.model.sphere_geometry import mass_properties

STEEL_KG_M3 = 7850.0


def test_table_a1_mass_and_cog_offset_follow_from_steel_geometry():
    s = load_parameter_set('table_a1').sphere
    mp = mass_properties(s.radius_m, s.cut_angle_rad, density_kg_m3=STEEL_KG_M3)
    assert mp.cog_offset_m == pytest.approx(49.7642e-6, rel=2e-6)
    assert mp.mass_kg == pytest.approx(30.973e-6, rel=1e-4)


def _quadrature(radius, cut_angle, density):
    """Mass, first moment and second moments of the cut sphere by spherical quadrature."""
    h = radius * math.cos(0.5 * cut_angle)

    def r_max(theta):
        # Radial extent along polar angle theta: the flat face cuts rays within cut_angle/2.
        if theta < 0.5 * cut_angle:
            return h / math.cos(theta)
        return radius

    def integrate_moment(fn):
        val, _ = integrate.dblquad(
            lambda rr, th: fn(rr, th) * rr**2 * math.sin(th) * 2 * math.pi,
            0, math.pi, 0, r_max, epsabs=1e-30, epsrel=1e-10)
        return density * val

    mass = integrate_moment(lambda rr, th: 1.0)
    mz = integrate_moment(lambda rr, th: rr * math.cos(th))
    # Axisymmetric: x^2 + y^2 averages to (r sin th)^2, and <x^2> = half of it.
    izz = integrate_moment(lambda rr, th: (rr * math.sin(th)) ** 2)
    ixx = integrate_moment(lambda rr, th: 0.5 * (rr * math.sin(th)) ** 2 + (rr * math.cos(th)) ** 2)
    return mass, mz, ixx, izz


@pytest.mark.parametrize('cut_angle', [0.5, math.pi / 3, math.pi / 2, 2.0])
def test_closed_form_inertia_matches_quadrature(cut_angle):
    radius = 1e-3
    mp = mass_properties(radius, cut_angle, density_kg_m3=STEEL_KG_M3)
    mass, mz, ixx, izz = _quadrature(radius, cut_angle, STEEL_KG_M3)
    assert mp.mass_kg == pytest.approx(mass, rel=1e-8)
    assert mp.cog_offset_m == pytest.approx(-mz / mass, rel=1e-7, abs=1e-15)
    np.testing.assert_allclose(mp.inertia_centre_kg_m2, [ixx, ixx, izz], rtol=1e-7)
    d = mp.cog_offset_m
    np.testing.assert_allclose(mp.inertia_cog_kg_m2, [ixx - mass * d**2, ixx - mass * d**2, izz],
                               rtol=1e-7)
