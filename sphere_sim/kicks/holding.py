"""How a sphere that landed from a kick holds, and how the kick narrows with tilt: the paper's
Fig. 1d (caught and kept) and Fig. 10 (the width "slightly decreases" with the tilt), measured
as ``sphere-twin validate`` prints them and the tests check them."""

import numpy as np
from numpy.typing import NDArray

from sphere_sim.integrate.solve import simulate
from sphere_sim.kicks.characteristics import KickBench, KickEffect
from sphere_sim.kicks.design import KickDesign
from sphere_sim.kicks.discrete import normal_from_cardan
from sphere_sim.kicks.offset_lookup import OffsetLookup
from sphere_sim.model.assembly import Model, rest_model
from sphere_sim.model.initial_state import rest_state
from sphere_sim.model.parameters import ParameterSet
from sphere_sim.model.programme import Pulse, PulseProgramme
from sphere_sim.model.rotations import angle_between

# Holding is measured on a sphere that has landed from a kick, not on a solved equilibrium
# (whose bristles start already loaded): it starts HOLD_SETTLE_S after the kick's rising edge,
# past the kick's window, and runs for HOLD_DURATION_S.
HOLD_SETTLE_S = 0.1
HOLD_DURATION_S = 2.0
# Sub-break-away pulses of the ratchet check: 1 ms on all four beams, one every 3 ms, their
# amplitudes cycling through these values (V).
RATCHET_AMPLITUDES_V = (10.0, 20.0, 30.0)
RATCHET_PULSE_S = 1e-3
RATCHET_PERIOD_S = 3e-3
RATCHET_PULSES = 100
HOLD_RTOL = 1e-6


def landed_state(tilt_deg: float, params: ParameterSet | None = None,
                 design: KickDesign | None = None) -> tuple[Model, NDArray[np.float64]]:
    """The state HOLD_SETTLE_S after ``design``'s kick (default: the paper's layout with the
    template's widths) from rest at a tilt of ``tilt_deg`` about x, and its model."""
    model = rest_model(params)
    design = KickDesign() if design is None else design
    x0 = rest_state(model, (tilt_deg, 0.0, 0.0))
    traj = simulate(model, x0, HOLD_SETTLE_S, design.programme(), rtol=HOLD_RTOL,
                    sample_period_s=HOLD_SETTLE_S)
    return model, traj.x[:, -1].copy()


def landed_creep_rate(tilt_deg: float = 20.0, duration_s: float = HOLD_DURATION_S,
                      params: ParameterSet | None = None,
                      design: KickDesign | None = None) -> float:
    """How fast a sphere that landed from a kick at a tilt of ``tilt_deg`` moves on (rad/s):
    the angle its normal turns over ``duration_s`` with no voltage, over ``duration_s``."""
    model, x = landed_state(tilt_deg, params, design)
    traj = simulate(model, x, duration_s, PulseProgramme(), rtol=HOLD_RTOL,
                    sample_period_s=duration_s / 4)
    normals = traj.surface_normal()
    return angle_between(normals[:, 0], normals[:, -1]) / duration_s


def ratchet_programme(pulses: int = RATCHET_PULSES) -> PulseProgramme:
    return PulseProgramme(tuple(
        Pulse(beam, RATCHET_AMPLITUDES_V[k % len(RATCHET_AMPLITUDES_V)], k * RATCHET_PERIOD_S,
              RATCHET_PULSE_S)
        for k in range(pulses) for beam in (1, 2, 3, 4)))


def ratchet_rad(tilt_deg: float = 35.0, pulses: int = RATCHET_PULSES,
                params: ParameterSet | None = None, design: KickDesign | None = None) -> float:
    """How far (rad) ``pulses`` sub-break-away pulses on all beams move the normal of a sphere
    that landed from a kick at ``tilt_deg``: a contact whose friction drifts under oscillating
    loads walks the sphere down pulse by pulse; one with an elastic zone does not."""
    model, x = landed_state(tilt_deg, params, design)
    duration = pulses * RATCHET_PERIOD_S + RATCHET_PERIOD_S
    traj = simulate(model, x, duration, ratchet_programme(pulses), rtol=HOLD_RTOL,
                    sample_period_s=duration)
    normals = traj.surface_normal()
    return angle_between(normals[:, 0], normals[:, -1])


def width_ratio(tilt_deg: float = 35.0, params: ParameterSet | None = None,
                design: KickDesign | None = None, offsets: OffsetLookup | None = None) -> float:
    """The full kick's rotation width from a tilt of ``tilt_deg`` (about x) over the level one
    (Fig. 10: it "slightly decreases"). With ``offsets`` both kicks carry §4.1's voltage offset
    for their resting normal, as the table's kicks do; without, only the design's voltages."""
    design = KickDesign() if design is None else design
    bench = KickBench(params)
    widths = []
    for alpha_deg in (0.0, tilt_deg):
        normal = normal_from_cardan(alpha_deg)
        programme = (design.programme(1.0) if offsets is None
                     else offsets.programme(design, normal[0], normal[1], 1.0))
        widths.append(KickEffect(bench.final_normal(normal, programme)[:2] - normal[:2]).width_rad)
    return widths[1] / widths[0]
