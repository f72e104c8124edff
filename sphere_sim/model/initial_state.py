"""Initial states: explicit values or static rest, found by Newton on the accelerations."""

import dataclasses
import math
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.integrate import solve_ivp

from sphere_sim.model.assembly import Model, assemble
from sphere_sim.model.rotations import cardan_to_quat, quat_to_matrix
from sphere_sim.model.scaling import state_scale
from sphere_sim.model.sphere_geometry import mass_properties

REST_TOLERANCE = 1e-6  # largest force imbalance left at rest, relative to the weight per tip
NEWTON_ITERATIONS = 40
NEWTON_BACKTRACKS = 30
NEWTON_FD_STEP = 1e-6  # in the scaled coordinates (um, mrad)
RELAX_TIME_S = 0.06  # several decay times of the sphere's bounce on the tips
# The relaxation's tolerance, the reference's (scipy's Radau stepped from Python) and the
# compiled one's (sphere_sim.integrate.relaxation): a tilted sphere's rest is a family held by
# the bristles, and the relaxation's path picks the member. The reference moves by 9e-7 of the
# state scale from here to 1e-8.
RADAU_RELAX_RTOL = 1e-6
REST_SCALE_Z_M = 1e-6  # Newton works on positions in um and angles in mrad
REST_SCALE_PHI_RAD = 1e-3


# A relaxation a higher layer supplies (sphere_sim.integrate.relaxation.compiled_relaxation):
# the state RELAX_TIME_S after ``x`` of the model given (its orientation already held) under the
# voltages ``u``, or None where it fails and the reference takes over.
Relaxation = Callable[[Model, NDArray[np.float64], NDArray[np.float64]],
                      NDArray[np.float64] | None]


class RestError(RuntimeError):
    """No static rest state was found."""


def explicit_state(model: Model, sphere_position_m: ArrayLike | None = None) -> NDArray[np.float64]:
    """State from the scene's explicit values (zeros where not given), shape (n_states,)."""
    init = model.scene.initial
    n = model.n_beams
    x = np.zeros(model.n_states)
    if init.beam_z_m is not None:
        x[0:2 * n:2] = init.beam_z_m
    if init.beam_phi_rad is not None:
        x[1:2 * n:2] = init.beam_phi_rad
    if model.has_sphere:
        o = model.sphere_offset
        x[o + 3:o + 7] = cardan_to_quat(*np.radians(init.sphere_angles_deg))
        position = sphere_position_m if sphere_position_m is not None else init.sphere_position_m
        if position is None:
            position = _touching_position(model, x)
        x[o:o + 3] = position
        x[o + 7:o + 10] = init.sphere_velocity_m_per_s
        x[o + 10:o + 13] = init.sphere_omega_rad_per_s
    return x


def _touching_position(model: Model, x: NDArray[np.float64]) -> NDArray[np.float64]:
    """Centre of gravity of a sphere resting on undeflected tips at the origin's vertical."""
    b, s = model.params.beam, model.params.sphere
    tip_radius = b.suspension_radius_m - b.length_m
    centre_z = math.sqrt(s.radius_m**2 - tip_radius**2)
    R = quat_to_matrix(np.ascontiguousarray(x[model.sphere_offset + 3:model.sphere_offset + 7]))
    return np.array([0.0, 0.0, centre_z]) - R[:, 2] * s.cog_offset_m


def rest_state(model: Model, sphere_angles_deg: Sequence[float] | None = None,
               relaxation: Relaxation | None = None) -> NDArray[np.float64]:
    """Static equilibrium of beams and sphere position for a fixed sphere orientation.

    The sphere is first let down onto the tips and relaxed by integrating the model with its
    orientation held (the contact stiffness makes a cold Newton start diverge), then Newton's
    method polishes the positions until the accelerations vanish. For a tilted sphere the
    orientation stays as given: the remaining torque is what friction and the kicks act on.

    ``relaxation`` integrates the held model instead of the reference, scipy's Radau stepped
    from Python (None), which takes over where it fails. The kick workloads, which relax one
    state per kick or table node, use the same method compiled
    (:func:`sphere_sim.integrate.relaxation.compiled_relaxation`, ``KICK_RELAXATION``); every
    other caller keeps the reference.

    Returns
    -------
    ndarray, shape (n_states,)
        All rates zero.

    Raises
    ------
    RestError
        When no equilibrium is found.
    """
    x = explicit_state(model)
    n = model.n_beams
    if sphere_angles_deg is not None and model.has_sphere:
        o = model.sphere_offset
        x[o + 3:o + 7] = cardan_to_quat(*np.radians(sphere_angles_deg))
        x[o:o + 3] = _touching_position(model, x)
    return polish_equilibrium(model, _relax(_dissipative_twin(model), x, relaxation),
                              np.zeros(n))


def _dissipative_twin(model: Model) -> Model:
    """The same model with damping and contact losses on: same rest states, and it settles."""
    effects = model.scene.effects
    if effects.damping and effects.contact_losses:
        return model
    scene = model.scene.replace(effects=dataclasses.replace(effects, damping=True,
                                                            contact_losses=True))
    return assemble(scene, model.params, jit=model.jit)


def polish_equilibrium(model: Model, x: NDArray[np.float64],
                       u: ArrayLike) -> NDArray[np.float64]:
    """Newton on the positions of beams and sphere (orientation held) under voltages ``u``.

    With friction bristles (the ``paper`` and ``stiction`` readings) a second Newton follows
    from the first's equilibrium with their deflections as unknowns too and the sphere's
    angular accelerations in the residual: the bristles then hold whatever torque the tilted
    sphere's weight exerts (the least-squares step picks the smallest deflections that do,
    since four tips can share a torque in many ways); a level sphere needs none. A bristle that
    would have to pass its static limit (``Model.bristle_limits_m``) is left there instead, and
    the state returned is not at rest: the friction cannot hold that tilt.

    Raises
    ------
    RestError
        When the largest force imbalance stays above ``REST_TOLERANCE`` of the weight per tip.
    """
    n = model.n_beams
    free_list = list(range(2 * n))
    if model.has_sphere:
        free_list += [model.sphere_offset + i for i in range(3)]
    free = np.array(free_list)
    scale = np.where(free % 2 == 0, REST_SCALE_Z_M, REST_SCALE_PHI_RAD)
    if model.has_sphere:
        scale[-3:] = REST_SCALE_Z_M
    accel_index = _acceleration_index(model, free)
    force_scale = _generalised_masses(model, free) / _weight_per_tip_n(model)
    x = np.array(x, dtype=float)
    x[2 * n:4 * n] = 0.0
    if model.has_sphere:
        x[model.sphere_offset + 7:model.sphere_offset + 13] = 0.0
    x = _polish(model, x, u, free, scale, accel_index, force_scale)
    if model.has_bristles:
        o, s = model.sphere_offset, model.params.sphere
        bristles = np.arange(model.bristle_offset, model.n_states)
        inertia = mass_properties(s.radius_m, s.cut_angle_rad, mass_kg=s.mass_kg).inertia_cog_kg_m2
        free = np.concatenate([free, bristles])
        scale = np.concatenate([scale, np.full(bristles.size, _bristle_scale_m(model))])
        held = np.concatenate([accel_index, o + 10 + np.arange(3)])
        weights = np.concatenate([force_scale, inertia / (s.radius_m * _weight_per_tip_n(model))])
        try:
            x = _polish(model, x, u, free, scale, held, weights,
                        limit=lambda v: _clip_to_static_limit(model, x, v, scale, free))
        except RestError:
            # Where the tips hang free of the ground plate (Table A1's own torsion spring), the
            # Newton over beams, sphere and bristles at once stalls: its least-norm step shifts
            # the sphere by micrometres against contacts nanometres deep. The sphere then
            # settles onto its bristles as after a landing, its orientation free, and is
            # polished from there: a rest near the tilt asked for (within 0.2 deg on table_a1
            # at 20 and 35 deg; validation.tilted_rests reports how near).
            settled = _relax(_dissipative_twin(model), x, voltages=u, hold_orientation=False)
            x = _polish(model, settled, u, free, scale, held, weights,
                        limit=lambda v: _clip_to_static_limit(model, settled, v, scale, free))
    return x


def _polish(model: Model, x: NDArray[np.float64], u: ArrayLike, free: NDArray[np.intp],
            scale: NDArray[np.float64],
            accel_index: NDArray[np.intp], force_scale: NDArray[np.float64],
            limit: Callable[[NDArray[np.float64]], bool] | None = None) -> NDArray[np.float64]:
    """``x`` with ``free`` moved by Newton until the accelerations at ``accel_index`` vanish.

    ``limit(v)``, if given, bounds the solution in place and returns True when it had to: the
    state is then returned out of balance, without the imbalance check.
    """
    x = x.copy()

    def residual(v: NDArray[np.float64]) -> NDArray[np.float64]:
        y = x.copy()
        y[free] = v * scale
        return model.rhs(0.0, y, u)[accel_index] * force_scale

    v = _newton(residual, x[free] / scale)
    res = np.max(np.abs(residual(v)))
    if limit is not None and np.all(np.isfinite(v)) and limit(v):
        res = 0.0  # friction cannot hold this tilt: the sphere slides from the state returned
    if not np.all(np.isfinite(v)) or res > REST_TOLERANCE:
        raise RestError(f'no equilibrium found: largest force imbalance {res:.3g} of the weight '
                        'per tip')
    x[free] = v * scale
    return x


def _bristle_scale_m(model: Model) -> float:
    """A bristle's deflection at its static limit under the resting load of a tip (m)."""
    f = model.params.friction
    if f.reading == 'paper':
        return f.static_coefficient * _weight_per_tip_n(model) / f.bristle_stiffness_n_per_m
    return f.presliding_m


def _clip_to_static_limit(model: Model, x: NDArray[np.float64], v: NDArray[np.float64],
                          scale: NDArray[np.float64], free: NDArray[np.intp]) -> bool:
    """Shorten, in ``v``, any bristle deflected past its static limit (``Model.bristle_limits``:
    the presliding delta of the ``stiction`` reading, the elastic zone's edge of the ``paper``
    reading); True if one was. Such a tilt is more than friction can hold."""
    first = np.flatnonzero(free == model.bristle_offset)[0]
    bristles = (v[first:] * scale[first:]).reshape(-1, 3)
    y = x.copy()
    y[free] = v * scale
    limit = model.bristle_limits_m(y)
    length = np.linalg.norm(bristles, axis=1)
    over = length > limit
    bristles[over] *= (limit[over] / length[over])[:, None]
    v[first:] = bristles.ravel() / scale[first:]
    return bool(np.any(over))


def _newton(residual: Callable[[NDArray[np.float64]], NDArray[np.float64]], v: NDArray[np.float64],
            iterations: int = NEWTON_ITERATIONS,
            step: float = NEWTON_FD_STEP) -> NDArray[np.float64]:
    """Damped Newton with a central-difference Jacobian.

    The step is halved until the residual shrinks: a contact that engages during an update is
    invisible to the Jacobian taken before it, and a full step would overshoot into it.
    """
    r = residual(v)
    norm = np.linalg.norm(r)
    eye = np.eye(v.size)
    for _ in range(iterations):
        J = np.column_stack([(residual(v + step * e) - residual(v - step * e)) / (2 * step)
                             for e in eye])
        delta = np.linalg.lstsq(J, r, rcond=None)[0]
        for _ in range(NEWTON_BACKTRACKS):
            trial = v - delta
            r_trial = residual(trial)
            norm_trial = np.linalg.norm(r_trial)
            if np.isfinite(norm_trial) and norm_trial < norm:
                break
            delta = 0.5 * delta
        else:
            break
        v, r, norm = trial, r_trial, norm_trial
        if np.max(np.abs(r)) < 1e-3 * REST_TOLERANCE:
            break
    return v


def _weight_per_tip_n(model: Model) -> float:
    if model.has_sphere:
        return model.params.sphere.mass_kg * model.params.gravity_m_per_s2 / 4.0
    return model.params.beam.mass_kg * model.params.gravity_m_per_s2


def _generalised_masses(model: Model, free: NDArray[np.intp]) -> NDArray[np.float64]:
    """Mass (kg) or inertia over beam length (kg m) per free coordinate, for force units."""
    b = model.params.beam
    out = []
    for i in free:
        if i < 2 * model.n_beams:
            out.append(b.mass_kg if i % 2 == 0 else b.inertia_suspension_kg_m2 / b.length_m)
        else:
            out.append(model.params.sphere.mass_kg)
    return np.array(out)


def _relax(model: Model, x: NDArray[np.float64], relaxation: Relaxation | None = None,
           voltages: ArrayLike | None = None, hold_orientation: bool = True) -> NDArray[np.float64]:
    """Integrate with all rates damped out and the sphere's orientation held (or free), by
    ``relaxation`` or, where it fails or is None, the reference."""
    if model.has_sphere and hold_orientation:
        model = model.with_orientation_held()
    u = np.zeros(model.n_beams) if voltages is None else np.asarray(voltages, dtype=float)
    y = None if relaxation is None else relaxation(model, x, u)
    if y is None:
        y = _relax_radau(model, x, u)
    y[2 * model.n_beams:4 * model.n_beams] = 0.0
    if model.has_sphere:
        o = model.sphere_offset
        y[o + 7:o + 13] = 0.0
        if hold_orientation:
            # Held, its rates are zero, but a solver's row exchanges can leave rounding (1e-29,
            # the compiled Radau's) in its increments: the orientation given is the one returned.
            y[o + 3:o + 7] = x[o + 3:o + 7]
    return y


def _relax_radau(model: Model, x: NDArray[np.float64],
                 u: NDArray[np.float64]) -> NDArray[np.float64]:
    """The reference relaxation: scipy's Radau under the voltages ``u``, stepped from Python."""
    fun, jac = model.at_voltages(u)  # the kernels bound once (as model.rhs and .jacobian give)
    sol = solve_ivp(fun, (0.0, RELAX_TIME_S), x, method='Radau', rtol=RADAU_RELAX_RTOL,
                    atol=RADAU_RELAX_RTOL * state_scale(model), jac=jac)
    if not sol.success:
        raise RestError(f'relaxation towards rest failed: {sol.message}')
    return sol.y[:, -1].copy()


def _acceleration_index(model: Model, free: NDArray[np.intp]) -> NDArray[np.intp]:
    """Indices in dx/dt of the accelerations conjugate to the free positions."""
    n = model.n_beams
    index = []
    for i in free:
        if i < 2 * n:
            index.append(2 * n + i)
        else:
            index.append(i + 7)
    return np.array(index)


def initial_state(model: Model, relaxation: Relaxation | None = None) -> NDArray[np.float64]:
    """The scene's initial state, shape (n_states,); a rest state is relaxed with
    ``relaxation`` (:func:`rest_state`)."""
    init = model.scene.initial
    if init.mode == 'explicit':
        return explicit_state(model)
    x = rest_state(model, relaxation=relaxation)
    if model.has_sphere and init.sphere_lift_m:
        x[model.sphere_offset + 2] += init.sphere_lift_m
    if model.has_sphere:
        o = model.sphere_offset
        x[o + 7:o + 10] = init.sphere_velocity_m_per_s
        x[o + 10:o + 13] = init.sphere_omega_rad_per_s
    return x
