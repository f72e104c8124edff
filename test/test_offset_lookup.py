"""§4.1's voltage offsets as a lookup: the half-space rule, its mirror, intensity, the table's
programmes under the device's symmetry, and the offsets file."""

import json
import math

import numpy as np
import pytest

from sphere_sim.kicks.design import KickDesign
from sphere_sim.kicks.discrete import normal_from_xy
from sphere_sim.kicks.lookup_table import TableSpec
from sphere_sim.kicks.offset_lookup import (
    OffsetError,
    OffsetLookup,
    compensating_beam,
    side_of_axis,
)
from sphere_sim.model.symmetry import KICK_AXIS_MIRROR, Symmetry, kick_axis_mirror

DIAGONAL = KickDesign()
# The axis-parallel kick's layout (bench/results/kick_optimization_axis.json): beam 3 high.
AXIS = KickDesign(direction_rad=0.0, low_beams=(1, 2, 4), high_beams=(3,))
STEP = 0.16


def linear_lookup(design, slope_v=30.0):
    """Offsets v = 5 + slope * x on the upper-right half of a 5 x 5 grid."""
    axis = STEP * np.arange(-2, 3)
    return OffsetLookup(STEP, tuple(
        (x, y, 5.0 + slope_v * x) for x in axis for y in axis
        if side_of_axis(design.direction_rad, x, y) >= -1e-9))


def pulses(programme):
    return {p.beam: p.amplitude_v for p in programme.pulses}


def test_v1_takes_the_offset_in_the_upper_right_half_and_v2_in_the_lower_left():
    """§4.1: V1, the actuator on the right-hand side of the kick, for a normal in the upper-right
    half-space; V2 in the lower-left one. For the axis kick the pair is the mirror pair 2, 4."""
    assert compensating_beam(DIAGONAL, upper_right=True) == 1
    assert compensating_beam(DIAGONAL, upper_right=False) == 2
    assert compensating_beam(AXIS, upper_right=True) == 4
    assert compensating_beam(AXIS, upper_right=False) == 2
    for design in (DIAGONAL, AXIS):
        swap = kick_axis_mirror(design.direction_rad).beam_map()
        assert swap[compensating_beam(design, True)] == compensating_beam(design, False)
    with pytest.raises(ValueError, match='mirrored'):
        compensating_beam(KickDesign(direction_rad=0.0, low_beams=(1,), high_beams=(3,)))


def test_the_lookup_is_exact_on_nodes_bilinear_between_and_mirrored_across_the_axis():
    lookup = linear_lookup(DIAGONAL)
    d = DIAGONAL.direction_rad
    for x, y, v in lookup.nodes:
        assert lookup.offset_v(d, x, y) == pytest.approx(v, abs=1e-12)
    # Bilinear reproduces a linear field inside the half.
    assert lookup.offset_v(d, 0.1, 0.05) == pytest.approx(5.0 + 30.0 * 0.1)
    # A lower-left point reads its image's offset: (x, y) -> (-y, -x) at the line y = -x.
    for x, y in ((0.1, -0.25), (-0.3, 0.05), (-0.2, -0.2)):
        assert side_of_axis(d, x, y) < 0.0
        assert lookup.offset_v(d, x, y) == pytest.approx(5.0 + 30.0 * -y)
    # Beyond the searched grid the nearest node's offset holds.
    assert lookup.offset_v(d, 0.6, 0.0) == pytest.approx(5.0 + 30.0 * 0.32)
    assert OffsetLookup().offset_v(d, 0.2, 0.1) == 0.0


def two_branch_lookup(design):
    """10 V on the released branch (x_sn < 0.1), 20 V on the pushing one, on the half of a
    5 x 5 grid: the cells between x_sn = 0 and 0.16 have corners on both."""
    axis = STEP * np.arange(-2, 3)
    nodes = [(x, y) for x in axis for y in axis
             if side_of_axis(design.direction_rad, x, y) >= -1e-9]
    return OffsetLookup(STEP, tuple((x, y, 20.0 if x > 0.1 else 10.0) for x, y in nodes),
                        tuple(x > 0.1 for x, _ in nodes))


def test_a_cell_across_the_branches_reads_the_branch_that_holds_most_of_the_weight():
    """Between a node whose compensating beam releases the sphere and one whose beam pushes it,
    a bilinear mean would put the offset in the band between the branches (13 V here at 0.3 of
    the cell); the point takes the branch nearer it instead, and that branch's mean."""
    lookup = two_branch_lookup(DIAGONAL)
    d = DIAGONAL.direction_rad
    y = 0.16  # the cells from (0, 0.16) to (0.16, 0.32) lie in the upper-right half
    assert lookup.offset_v(d, 0.3 * STEP, y) == pytest.approx(10.0)
    assert lookup.offset_v(d, 0.7 * STEP, y + 0.5 * STEP) == pytest.approx(20.0)
    assert lookup.offset_v(d, 0.5 * STEP, y) == pytest.approx(20.0)  # a tie: pushing
    # Without the branches the same nodes interpolate bilinearly across the band.
    plain = OffsetLookup(STEP, lookup.nodes)
    assert plain.offset_v(d, 0.3 * STEP, y) == pytest.approx(13.0)
    # A cell with all four corners on one branch is plain bilinear, whatever the branch.
    linear = linear_lookup(DIAGONAL)
    pushing = OffsetLookup(STEP, linear.nodes, (True,) * len(linear.nodes))
    for x, y in ((0.1, 0.05), (0.23, 0.11), (-0.05, 0.2)):
        assert pushing.offset_v(d, x, y) == pytest.approx(linear.offset_v(d, x, y), abs=1e-12)
    # The lower-left half reads its image's branch: (x, y) -> (-y, -x).
    assert lookup.offset_v(d, -y, -0.3 * STEP) == pytest.approx(10.0)
    assert lookup.offset_v(d, -y - 0.5 * STEP, -0.7 * STEP) == pytest.approx(20.0)
    with pytest.raises(ValueError, match='branches'):
        OffsetLookup(STEP, lookup.nodes, lookup.pushes[:-1])


def test_the_offset_scales_with_intensity_and_vanishes_with_the_kick():
    lookup = linear_lookup(DIAGONAL)
    x, y = 0.16, 0.0
    offset = lookup.offset_v(DIAGONAL.direction_rad, x, y)
    assert offset == pytest.approx(9.8)
    assert pulses(lookup.programme(DIAGONAL, x, y, 0.0)) == pulses(DIAGONAL.programme(0.0))
    half = pulses(lookup.programme(DIAGONAL, x, y, 0.5))
    assert half[1] == pytest.approx(DIAGONAL.low_v + 0.5 * offset)
    assert half[2] == DIAGONAL.low_v
    assert half[3] == pulses(DIAGONAL.programme(0.5))[3]
    # The mirror state's offset is the same, on V2.
    mirrored = pulses(lookup.programme(DIAGONAL, -y, -x, 1.0))
    assert (mirrored[1], mirrored[2]) == (DIAGONAL.low_v, pytest.approx(DIAGONAL.low_v + offset))


@pytest.mark.parametrize('design', [DIAGONAL, AXIS], ids=['diagonal', 'axis'])
def test_the_tables_programmes_carry_the_devices_symmetry(design):
    """The programme of action a from a normal is the action-0 programme from the normal turned
    back, turned forward; the kick axis mirror maps a state's programme to its image's."""
    spec = TableSpec(design=design, offsets=linear_lookup(design))
    rng = np.random.default_rng(3)
    mirror = kick_axis_mirror(design.direction_rad)
    for _ in range(40):
        x, y = rng.uniform(-0.35, 0.35, 2)
        normal = normal_from_xy(x, y)
        for action in range(4):
            g = Symmetry(action)
            turned = g.apply_vector(normal)
            assert spec.programme(action, 0.9, turned).segments()[1].tolist() == \
                g.apply_programme(spec.programme(0, 0.9, normal)).segments()[1].tolist()
        image = mirror.apply_programme(spec.programme(0, 0.9, normal))
        np.testing.assert_allclose(spec.programme(0, 0.9, mirror.apply_vector(normal))
                                   .segments()[1], image.segments()[1], atol=1e-9)


def test_the_table_nodes_beyond_the_axis_keep_v1():
    """Across the axis the table's band of nodes continues V1's programme with the image's
    offset, so interpolation near the axis follows one programme."""
    spec = TableSpec(offsets=linear_lookup(DIAGONAL))
    x, y = 0.0, -0.16
    assert spec.side(x, y) < 0.0
    node = pulses(spec.node_programme(x, y, 1.0))
    assert node[2] == DIAGONAL.low_v
    assert node[1] == pytest.approx(DIAGONAL.low_v + 5.0 + 30.0 * 0.16)
    assert KICK_AXIS_MIRROR.beam_map()[1] == 2


def test_offsets_load_from_their_file_only_for_their_design_and_set(tmp_path):
    states = [{'x_sn': x, 'y_sn': y, 'offset_v': v} for x, y, v in linear_lookup(DIAGONAL).nodes]
    path = tmp_path / 'voltage_offsets.json'
    path.write_text(json.dumps({'parameter_set': 'calibrated', 'design': DIAGONAL.to_dict(),
                                'grid_step': STEP, 'states': states}))
    assert OffsetLookup.load(path, DIAGONAL, 'calibrated') == linear_lookup(DIAGONAL)
    branches = two_branch_lookup(DIAGONAL)
    path.write_text(json.dumps({
        'parameter_set': 'calibrated', 'design': DIAGONAL.to_dict(), 'grid_step': STEP,
        'states': [{'x_sn': x, 'y_sn': y, 'offset_v': v, 'pushes': p}
                   for (x, y, v), p in zip(branches.nodes, branches.pushes, strict=True)]}))
    assert OffsetLookup.load(path, DIAGONAL, 'calibrated') == branches
    with pytest.raises(OffsetError, match='another kick design'):
        OffsetLookup.load(path, AXIS, 'calibrated')
    with pytest.raises(OffsetError, match='another kick design'):
        OffsetLookup.load(path, DIAGONAL, 'dry_contact')
    (tmp_path / 'junk.json').write_text('{"states": 3}')
    with pytest.raises(OffsetError, match='no voltage offsets'):
        OffsetLookup.load(tmp_path / 'junk.json', DIAGONAL, 'calibrated')


def test_a_table_spec_round_trips_its_offsets():
    spec = TableSpec(offsets=linear_lookup(DIAGONAL))
    again = TableSpec.from_dict(json.loads(json.dumps(spec.to_dict())))
    assert again == spec
    assert again.digest('p') == spec.digest('p')
    assert TableSpec().digest('p') != spec.digest('p')
    # A table saved before offsets existed reads as one without.
    data = TableSpec().to_dict()
    del data['offsets']
    assert not TableSpec.from_dict(data).offsets
    assert math.isclose(again.offsets.offset_v(DIAGONAL.direction_rad, 0.0, 0.0), 5.0)
    branches = TableSpec(offsets=two_branch_lookup(DIAGONAL))
    assert TableSpec.from_dict(json.loads(json.dumps(branches.to_dict()))) == branches
    unmeasured = TableSpec(offsets=OffsetLookup(STEP, branches.offsets.nodes))
    assert unmeasured.digest('p') != branches.digest('p')
