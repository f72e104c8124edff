"""The packed parameter vector ``p`` of the compiled kernels, one table for its indices and its
packing.

Each member of :class:`Packed` names one quantity once: its value is its index in ``p`` (numba
reads an IntEnum member as a compile-time constant, so ``p[Packed.COULOMB]`` costs what a
literal index does) and its ``path`` is where :func:`~sphere_sim.model.assembly.pack_parameters`
takes it from, a :class:`~sphere_sim.model.parameters.ParameterSet` path, or ``DERIVED`` for a
value the assembly computes (the sphere's inertia from its shape, the capacitance fit's widths).
"""

import enum

# The path of a quantity the assembly derives instead of reading it from the parameter set.
DERIVED = ''


class Packed(enum.IntEnum):
    """Index of each quantity in the packed parameter vector, in order, with its path."""

    path: str

    def __new__(cls, path: str) -> 'Packed':
        index = len(cls.__members__)
        member = int.__new__(cls, index)
        member._value_ = index
        member.path = path
        return member

    GRAVITY = 'gravity_m_per_s2'
    BEAM_MASS = 'beam.mass_kg'
    BEAM_INERTIA = 'beam.inertia_suspension_kg_m2'
    BEAM_COG = 'beam.cog_distance_m'
    BEAM_LENGTH = 'beam.length_m'
    SUSPENSION_RADIUS = 'beam.suspension_radius_m'
    SUSPENSION_Z = 'beam.suspension_z_m'
    STIFFNESS_Z = 'beam.stiffness_z_n_per_m'
    STIFFNESS_PHI = 'beam.stiffness_phi_nm_per_rad'
    DAMPING_Z = 'beam.damping_z_ns_per_m'
    DAMPING_PHI = 'beam.damping_phi_nms_per_rad'
    GROUND_Z = 'beam.ground_z_m'
    GROUND_LENGTH = 'beam.ground_length_m'
    INSULATION = 'beam.insulation_virtual_m'
    ELECTRODE_LENGTH = 'beam.electrode_length_m'
    ELECTRODE_WIDTH = 'beam.electrode_width_m'
    FRINGE_ANGLE = 'electrostatics.fringe_angle_rad'
    SPHERE_RADIUS = 'sphere.radius_m'
    SPHERE_MASS = 'sphere.mass_kg'
    COG_OFFSET = 'sphere.cog_offset_m'
    JXX = DERIVED
    JYY = DERIVED
    JZZ = DERIVED
    DAMPING_ROT = 'sphere.damping_rot_nms'
    DAMPING_TRANS = 'sphere.damping_trans_ns_per_m'
    CONTACT_STIFFNESS = 'contact.stiffness_n_per_m'
    TRANSITION_FORCE = 'contact.transition_force_n'
    CONTACT_LOSS = 'contact.loss_s_per_m'
    VISCOUS = 'friction.viscous_ns_per_m'
    COULOMB = 'friction.coulomb'
    COULOMB_VELOCITY = 'friction.coulomb_velocity_m_per_s'
    STRIBECK = 'friction.stribeck'
    STRIBECK_VELOCITY = 'friction.stribeck_velocity_m_per_s'
    EPSILON = 'friction.epsilon_m2_per_s2'
    VISCOUS_ONSET = 'friction.viscous_onset_m'
    RBF_SIGMA_Z = DERIVED
    RBF_SIGMA_PHI = DERIVED
    PRESLIDING = 'friction.presliding_m'
    VISCOUS_PER_NEWTON = 'friction.viscous_s_per_m'
    BRISTLE_DAMPING = 'friction.bristle_damping_s'
    STATIC_COEFFICIENT = 'friction.static_coefficient'
    BRISTLE_STIFFNESS = 'friction.bristle_stiffness_n_per_m'
    BRISTLE_SPEED = 'friction.bristle_speed_m_per_s'
    BREAKAWAY_RATIO = 'friction.breakaway_ratio'


N_PARAMS = len(Packed)
