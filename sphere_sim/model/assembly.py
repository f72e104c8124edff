"""Model assembly: the parts a scene declares, packed for the compiled kernel.

``assemble(scene)`` returns a :class:`Model` whose ``rhs(t, x, u)`` is the whole continuous
model. Parts the scene leaves out are not evaluated: a beams-only scene has 4 n states and the
kernel never enters sphere, contact or friction code for it.
"""

import dataclasses
import math
from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sphere_sim.model import dynamics as dyn
from sphere_sim.model import gaps as gap_kernels
from sphere_sim.model.contact_law import contact_force, elastic_energy
from sphere_sim.model.friction import BRISTLE_READINGS, READING_PAPER, READINGS
from sphere_sim.model.packed import DERIVED, N_PARAMS, Packed
from sphere_sim.model.parameters import ParameterSet
from sphere_sim.model.rotations import quat_to_matrix
from sphere_sim.model.scaling import state_scale
from sphere_sim.model.scene import Scene, load_scene
from sphere_sim.model.sphere_geometry import mass_properties

SPHERE_STATES = dyn.SPHERE_STATES

# What Model.at_voltages returns: ``fun(t, x, out=None)`` and ``jac(t, x)``.
RhsFunction = Callable[..., NDArray[np.float64]]
JacobianFunction = Callable[[float, NDArray[np.float64]], NDArray[np.float64]]


def beam_angle_rad(beam: int) -> float:
    """delta_k: beams numbered clockwise in a top view (y up), beam 1 on the left (-x)."""
    return -(beam - 1) * 0.5 * math.pi


def pack_parameters(params: ParameterSet) -> NDArray[np.float64]:
    """The packed parameter vector ``p`` of :mod:`sphere_sim.model.dynamics`, shape (N_PARAMS,):
    each quantity of :class:`~sphere_sim.model.packed.Packed` from its path, and the sphere's
    inertia from its shape (the capacitance fit's widths are set by :func:`assemble`)."""
    p = np.zeros(N_PARAMS)
    for quantity in Packed:
        if quantity.path != DERIVED:
            p[quantity] = params.get(quantity.path)
    s = params.sphere
    mp = mass_properties(s.radius_m, s.cut_angle_rad, mass_kg=s.mass_kg)
    p[Packed.JXX:Packed.JZZ + 1] = mp.inertia_cog_kg_m2
    return p


@dataclasses.dataclass(frozen=True, eq=False)
class Model:
    """An assembled continuous model: ``rhs(t, x, u)`` plus its layout and energy.

    Attributes
    ----------
    scene : Scene
    params : ParameterSet
        With the scene's perturbation applied.
    beams : tuple of int
        Beam numbers present, in state order.
    parts : tuple of str
        The parts assembled, e.g. ``('beams', 'electrostatics:closed_form', ...)``.
    beam_angles : ndarray, shape (n_beams,)
        delta_k of each beam (rad).
    beam_directions : ndarray, shape (n_beams, 2)
        Their cos and sin, which is what the compiled kernels use.
    """

    scene: Scene
    params: ParameterSet
    beams: tuple[int, ...]
    has_sphere: bool
    parts: tuple[str, ...]
    p: NDArray[np.float64]
    flags: NDArray[np.int64]
    beam_angles: NDArray[np.float64]
    beam_directions: NDArray[np.float64]
    rbf_cz: NDArray[np.float64]
    rbf_cphi: NDArray[np.float64]
    rbf_w: NDArray[np.float64]
    jit: bool = True

    @property
    def kernel_arrays(self) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.float64],
                                     NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """The packed model as the compiled integrator takes it, one record:
        ``(p, flags, beam_directions, rbf_cz, rbf_cphi, rbf_w)``."""
        return (self.p, self.flags, self.beam_directions, self.rbf_cz, self.rbf_cphi,
                self.rbf_w)

    @property
    def n_beams(self) -> int:
        return len(self.beams)

    def with_orientation_held(self) -> 'Model':
        """The same model with the sphere's orientation held (``F_ORIENTATION_HELD``): every
        other state moves as before, so a compiled integrator relaxes a tilted sphere onto its
        tips without letting it turn."""
        flags = self.flags.copy()
        flags[dyn.F_ORIENTATION_HELD] = 1
        return dataclasses.replace(self, flags=flags)

    @property
    def has_bristles(self) -> bool:
        """True when each tip carries a friction bristle (``paper`` and ``stiction`` readings)."""
        return bool(self.flags[dyn.F_STICTION])

    @property
    def n_states(self) -> int:
        return self.bristle_offset + (dyn.BRISTLE_STATES * self.n_beams if self.has_bristles
                                      else 0)

    @property
    def sphere_offset(self) -> int:
        return 4 * self.n_beams

    @property
    def bristle_offset(self) -> int:
        """Index of the first bristle state (the end of the sphere's states)."""
        return 4 * self.n_beams + (SPHERE_STATES if self.has_sphere else 0)

    def bristles(self, x: ArrayLike) -> NDArray[np.float64]:
        """Bristle deflections (m), shape (n_beams, 3) (zeros without a bristle reading)."""
        if not self.has_bristles:
            return np.zeros((self.n_beams, 3))
        o = self.bristle_offset
        return np.asarray(x)[o:o + dyn.BRISTLE_STATES * self.n_beams].reshape(self.n_beams, 3)

    def state_names(self) -> list[str]:
        names = [f'beam_{b}_{q}' for b in self.beams for q in ('z_m', 'phi_rad')]
        names += [f'beam_{b}_{q}' for b in self.beams for q in ('zdot_m_per_s', 'phidot_rad_per_s')]
        if self.has_sphere:
            names += ['sphere_x_m', 'sphere_y_m', 'sphere_z_m', 'quat_w', 'quat_x', 'quat_y',
                      'quat_z', 'sphere_vx_m_per_s', 'sphere_vy_m_per_s', 'sphere_vz_m_per_s',
                      'omega_x_rad_per_s', 'omega_y_rad_per_s', 'omega_z_rad_per_s']
        if self.has_bristles:
            names += [f'beam_{b}_bristle_{a}_m' for b in self.beams for a in 'xyz']
        return names

    def _kernel(self) -> Callable[..., None]:
        return dyn.rhs_kernel if self.jit else dyn.rhs_kernel.py_func

    def rhs(self, t: float, x: ArrayLike, u: ArrayLike,
            diag: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
        """dx/dt at time ``t`` (s), state ``x`` and beam voltages ``u`` (V, shape (n_beams,))."""
        out = np.empty(self.n_states)
        if diag is None:
            diag = np.empty(dyn.N_DIAG)
        self._kernel()(float(t), np.ascontiguousarray(x, dtype=float),
                       np.ascontiguousarray(u, dtype=float), self.p, self.flags,
                       self.beam_directions, self.rbf_cz, self.rbf_cphi, self.rbf_w, out, diag)
        return out

    def jacobian(self, t: float, x: ArrayLike, u: ArrayLike) -> NDArray[np.float64]:
        """d(dx/dt)/dx, shape (n_states, n_states), by compiled differences of the kernel."""
        jac = np.empty((self.n_states, self.n_states))
        kernel = dyn.jacobian_kernel if self.jit else dyn.jacobian_kernel.py_func
        kernel(float(t), np.ascontiguousarray(x, dtype=float), np.ascontiguousarray(u, dtype=float),
               self.p, self.flags, self.beam_directions, self.rbf_cz, self.rbf_cphi, self.rbf_w,
               state_scale(self), jac)
        return jac

    def at_voltages(self, u: ArrayLike) -> tuple[RhsFunction, JacobianFunction]:
        """``(fun, jac)`` of the model with the beam voltages ``u`` (V) held, for solvers.

        ``fun(t, x, out=None)`` returns dx/dt and ``jac(t, x)`` returns d(dx/dt)/dx, as
        :meth:`rhs` and :meth:`jacobian` do, with the voltages, the model's arrays and the
        Jacobian's difference scales bound once. A library solver calls them for every
        evaluation, and the benchmarks time it: each call then costs the compiled kernel and
        one dispatch into it, not the argument conversions of :meth:`rhs` (2.2 against 1.6 µs
        per call, of which the kernel is 0.55). ``x`` is passed on as it is: another dtype or
        layout than contiguous float64 costs a compilation of the kernel for it.
        """
        u = np.array(u, dtype=float)  # a copy: the caller may reuse its array
        kernel = self._kernel()
        jacobian_kernel = dyn.jacobian_kernel if self.jit else dyn.jacobian_kernel.py_func
        p, flags, directions = self.p, self.flags, self.beam_directions
        rbf_cz, rbf_cphi, rbf_w = self.rbf_cz, self.rbf_cphi, self.rbf_w
        n = self.n_states
        scale = state_scale(self)
        diag = np.empty(dyn.N_DIAG)

        def fun(t: float, x: NDArray[np.float64],
                out: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
            if out is None:
                out = np.empty(n)
            kernel(t, x, u, p, flags, directions, rbf_cz, rbf_cphi, rbf_w, out, diag)
            return out

        def jac(t: float, x: NDArray[np.float64]) -> NDArray[np.float64]:
            out = np.empty((n, n))
            jacobian_kernel(t, x, u, p, flags, directions, rbf_cz, rbf_cphi, rbf_w, scale, out)
            return out

        return fun, jac

    def diagnostics(self, t: float, x: ArrayLike, u: ArrayLike) -> dict[str, float]:
        """Powers (W) and smallest gaps (m) at one state, keyed by name."""
        diag = np.empty(dyn.N_DIAG)
        self.rhs(t, x, u, diag)
        return {
            'power_electrostatic_w': diag[dyn.D_POWER_ELECTROSTATIC],
            'power_damping_w': diag[dyn.D_POWER_DAMPING],
            'power_contact_loss_w': diag[dyn.D_POWER_CONTACT_LOSS],
            'power_friction_w': diag[dyn.D_POWER_FRICTION],
            'min_ground_gap_m': diag[dyn.D_MIN_GROUND_GAP],
            'min_sphere_gap_m': diag[dyn.D_MIN_SPHERE_GAP],
        }

    # --- state access -------------------------------------------------------------------
    def beam_coordinates(self, x: NDArray[np.float64],
                         ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64],
                                    NDArray[np.float64]]:
        """(z_m, phi_rad, zdot, phidot), each shape (n_beams,) (or (n_beams, n_times))."""
        n = self.n_beams
        return x[0:2 * n:2], x[1:2 * n:2], x[2 * n:4 * n:2], x[2 * n + 1:4 * n:2]

    def sphere_quaternion(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        o = self.sphere_offset
        return x[o + 3:o + 7]

    def surface_normal(self, x: ArrayLike) -> NDArray[np.float64]:
        """Inertial unit normal of the flat face, shape (3,) (or (3, n_times))."""
        x = np.asarray(x)
        if x.ndim == 2:
            return np.stack([self.surface_normal(col) for col in x.T], axis=1)
        return quat_to_matrix(np.ascontiguousarray(self.sphere_quaternion(x)))[:, 2].copy()

    def tip_positions(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Beam tip positions (m), shape (n_beams, 3), eq. (31)."""
        z, phi, _, _ = self.beam_coordinates(x)
        b = self.params.beam
        radial = -b.suspension_radius_m + b.length_m * np.cos(phi)
        return np.stack([radial * np.cos(self.beam_angles), radial * np.sin(self.beam_angles),
                         z + b.length_m * np.sin(phi)], axis=1)

    # --- energy -------------------------------------------------------------------------
    def capacitances(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Capacitance of each beam (F), shape (n_beams,)."""
        z, phi, _, _ = self.beam_coordinates(x)
        cap = dyn.capacitance_of if self.jit else dyn.capacitance_of.py_func
        return np.array([cap(zk, pk, self.p, self.flags, self.rbf_cz, self.rbf_cphi,
                             self.rbf_w)[0] for zk, pk in zip(z, phi, strict=True)])

    def mechanical_energy(self, x: NDArray[np.float64]) -> float:
        """Kinetic + gravitational + spring + contact elastic energy (J) of the parts present.

        The electrostatic co-energy is not included: with a voltage V held constant, the
        electrical work done on the mechanism is V^2/2 times the change in capacitance.
        """
        prm = self.params
        b = prm.beam
        g = prm.gravity_m_per_s2 if self.scene.effects.gravity else 0.0
        kc, ct = prm.contact.stiffness_n_per_m, prm.contact.transition_force_n
        z, phi, zd, phid = self.beam_coordinates(x)
        kinetic = (0.5 * b.mass_kg * zd**2 + b.mass_kg * b.cog_distance_m * np.cos(phi) * zd * phid
                   + 0.5 * b.inertia_suspension_kg_m2 * phid**2)
        potential = (b.mass_kg * g * (z + b.cog_distance_m * np.sin(phi))
                     + 0.5 * b.stiffness_z_n_per_m * (z - b.suspension_z_m) ** 2
                     + 0.5 * b.stiffness_phi_nm_per_rad * phi**2)
        energy = float(np.sum(kinetic + potential))
        if self.scene.effects.ground_contact:
            rear = z - b.ground_z_m - b.insulation_virtual_m
            front = rear + b.ground_length_m * np.tan(phi)
            energy += sum(elastic_energy(s, kc, ct) for s in np.concatenate([rear, front]))
        if self.has_sphere:
            s = prm.sphere
            o = self.sphere_offset
            mp = mass_properties(s.radius_m, s.cut_angle_rad, mass_kg=s.mass_kg)
            vel, omega = x[o + 7:o + 10], x[o + 10:o + 13]
            energy += 0.5 * s.mass_kg * float(vel @ vel)
            energy += 0.5 * float(omega @ (mp.inertia_cog_kg_m2 * omega))
            energy += s.mass_kg * g * x[o + 2]
            if self.scene.effects.sphere_contact:
                energy += sum(elastic_energy(gap, kc, ct) for gap in self.sphere_gaps(x))
            energy += self.bristle_energy(x)
        return energy

    def bristle_energy(self, x: NDArray[np.float64]) -> float:
        """Elastic energy held in the friction bristles (J): 1/2 k_b |b|^2 each with the
        ``paper`` reading's constant stiffness, whether in contact or relaxing; with the
        ``stiction`` reading 1/2 mu_c F_n |b_t|^2 / delta each, with F_n the contact's elastic
        normal force (0 without bristles)."""
        if not self.has_bristles:
            return 0.0
        f = self.params.friction
        if self.flags[dyn.F_FRICTION_READING] == READING_PAPER:
            b = self.bristles(x)
            return 0.5 * f.bristle_stiffness_n_per_m * float(np.sum(b * b))
        kc, ct = self.params.contact.stiffness_n_per_m, self.params.contact.transition_force_n
        rel = self._tips_from_centre(x)
        gaps = np.linalg.norm(rel, axis=1) - self.params.sphere.radius_m
        energy = 0.0
        for gap, r, b in zip(gaps, rel, self.bristles(x), strict=True):
            if gap >= 0.0:
                continue
            e = r / np.linalg.norm(r)
            tangential = b - (e @ b) * e
            f_n = contact_force(gap, 0.0, kc, ct, 0.0)
            energy += 0.5 * f.coulomb * f_n * float(tangential @ tangential) / f.presliding_m
        return energy

    def bristle_limits_m(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Largest deflection (m) each tip's bristle holds elastically at state ``x``, shape
        (n_beams,): the presliding delta of the ``stiction`` reading; with the ``paper``
        reading the edge of the elastic zone at rest, the break-away ratio of mu_b F_n / k_b
        with F_n the contact's elastic normal force (0 for a tip out of contact)."""
        f = self.params.friction
        if self.flags[dyn.F_FRICTION_READING] != READING_PAPER:
            return np.full(self.n_beams, f.presliding_m)
        kc, ct = self.params.contact.stiffness_n_per_m, self.params.contact.transition_force_n
        normal = np.array([contact_force(gap, 0.0, kc, ct, 0.0) if gap < 0.0 else 0.0
                           for gap in self.sphere_gaps(x)])
        return f.breakaway_ratio * f.static_coefficient * normal / f.bristle_stiffness_n_per_m

    def sphere_centre(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        o = self.sphere_offset
        R = quat_to_matrix(np.ascontiguousarray(x[o + 3:o + 7]))
        return x[o:o + 3] + R[:, 2] * self.params.sphere.cog_offset_m

    def sphere_gaps(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Signed tip-to-sphere-surface distances (m), shape (n_beams,), eq. (32)."""
        return (np.linalg.norm(self._tips_from_centre(x), axis=1)
                - self.params.sphere.radius_m)

    def _tips_from_centre(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Vectors from the full-sphere centre to each beam tip (m), shape (n_beams, 3)."""
        return self.tip_positions(x) - self.sphere_centre(x)

    def ground_gaps(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Rear and front beam-ground gaps (m), shape (2, n_beams), eq. (23)-(24)."""
        b = self.params.beam
        z, phi, _, _ = self.beam_coordinates(x)
        rear = z - b.ground_z_m - b.insulation_virtual_m
        return np.stack([rear, rear + b.ground_length_m * np.tan(phi)])

    def contact_gaps(self, x: ArrayLike) -> NDArray[np.float64]:
        """Gaps (m) of all point contacts, as the integrators see them: rear and front ground
        gaps, then tip-to-sphere gaps (:func:`~sphere_sim.model.gaps.contact_gaps`)."""
        n = gap_kernels.n_contacts(self.flags)
        out = np.empty(max(1, n))
        gap_kernels.contact_gaps(np.ascontiguousarray(x, dtype=float), self.p, self.flags,
                                 self.beam_directions, out)
        return out[:n]

    def electrode_gaps(self, x: ArrayLike) -> NDArray[np.float64]:
        """Smallest electrode gap (m) of each beam
        (:func:`~sphere_sim.model.gaps.electrode_gaps`)."""
        out = np.empty(max(1, self.n_beams))
        gap_kernels.electrode_gaps(np.ascontiguousarray(x, dtype=float), self.p, self.flags, out)
        return out[:self.n_beams]


def assemble(scene: Scene, params: ParameterSet | None = None, jit: bool = True) -> Model:
    """Assemble the model a scene declares.

    Parameters
    ----------
    scene : Scene
    params : ParameterSet, optional
        Replaces the parameter set the scene names. Either way the model runs on
        ``scene.parameters(params)``, the one spelling of a scene's parameter set: the scene's
        perturbation is applied on top (it sets values, so a set that already carries it is
        unchanged).
    jit : bool
        False runs the kernel as plain Python (slow; for tests that inspect which parts run).
    """
    params = scene.parameters(params)
    fx = scene.effects
    has_sphere = bool(scene.sphere)
    flags = np.zeros(dyn.N_FLAGS, dtype=np.int64)
    flags[dyn.F_N_BEAMS] = len(scene.beams)
    flags[dyn.F_SPHERE] = has_sphere
    flags[dyn.F_GRAVITY] = fx.gravity
    flags[dyn.F_ELECTROSTATICS] = fx.electrostatics
    flags[dyn.F_RBF] = fx.electrostatics and scene.capacitance == 'rbf'
    flags[dyn.F_FRINGE] = params.electrostatics.fringe
    flags[dyn.F_GROUND_CONTACT] = fx.ground_contact
    sphere_contact = has_sphere and fx.sphere_contact
    flags[dyn.F_SPHERE_CONTACT] = sphere_contact
    flags[dyn.F_CONTACT_LOSSES] = fx.contact_losses
    flags[dyn.F_DAMPING] = fx.damping
    flags[dyn.F_VISCOUS] = sphere_contact and fx.viscous
    flags[dyn.F_COULOMB] = sphere_contact and fx.coulomb
    flags[dyn.F_STRIBECK] = sphere_contact and fx.stribeck
    flags[dyn.F_FRICTION_READING] = READINGS.index(params.friction.reading)
    flags[dyn.F_STICTION] = (sphere_contact and fx.coulomb and fx.stiction
                             and flags[dyn.F_FRICTION_READING] in BRISTLE_READINGS)

    p = pack_parameters(params)
    rbf_cz = rbf_cphi = np.zeros(1)
    rbf_w = np.zeros((1, 1))
    if flags[dyn.F_RBF]:
        from sphere_sim.model.capacitance_rbf import RbfCapacitance

        b = params.beam
        fit = RbfCapacitance.fit(b.electrode_length_m, b.electrode_width_m, b.ground_z_m,
                                 params.electrostatics.fringe_angle_rad,
                                 params.electrostatics.fringe)
        rbf_cz = np.ascontiguousarray(fit.centres_z_m)
        rbf_cphi = np.ascontiguousarray(fit.centres_phi_rad)
        rbf_w = np.ascontiguousarray(fit.weights)
        p[Packed.RBF_SIGMA_Z] = fit.sigma_z_m
        p[Packed.RBF_SIGMA_PHI] = fit.sigma_phi_rad

    parts = ['beams']
    if fx.electrostatics:
        parts.append(f'electrostatics:{scene.capacitance}')
    if fx.ground_contact:
        parts.append('ground_contact')
    if has_sphere:
        parts.append('sphere')
    if sphere_contact:
        parts.append('sphere_contact')
        parts += [f'friction:{t}' for t in ('viscous', 'coulomb', 'stribeck') if getattr(fx, t)]
        if flags[dyn.F_STICTION]:
            parts.append('friction:stiction')
    angles = np.array([beam_angle_rad(b) for b in scene.beams], dtype=float).reshape(-1)
    return Model(scene=scene, params=params, beams=tuple(scene.beams), has_sphere=has_sphere,
                 parts=tuple(parts), p=p, flags=flags,
                 beam_angles=angles,
                 beam_directions=np.stack([np.cos(angles), np.sin(angles)], axis=1),
                 rbf_cz=rbf_cz, rbf_cphi=rbf_cphi, rbf_w=rbf_w, jit=jit)


def rest_model(params: ParameterSet | None = None, **effects: bool) -> Model:
    """The shipped rest scene's model with a parameter set (default: the scene's) and some
    effects switched (``damping=False``, ...)."""
    scene = load_scene('rest')
    if effects:
        scene = scene.replace(effects=dataclasses.replace(scene.effects, **effects))
    return assemble(scene, params)
