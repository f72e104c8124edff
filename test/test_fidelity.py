"""The ladder of models: a rung leaves out one named mechanism, starts from the full model's
state, and is judged by its landing error against the full model (sphere_sim.twin.ladder)."""

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from sphere_sim.integrate.solve import DEFAULT_METHOD
from sphere_sim.integrate.tolerances import LIVE_METHOD
from sphere_sim.model.assembly import assemble
from sphere_sim.model.fidelity import (
    FULL,
    LADDER,
    SLIDING,
    TABLE_RUNG,
    FidelityError,
    carried_state,
    rung_named,
)
from sphere_sim.model.parameters import load_parameter_set
from sphere_sim.model.rotations import angle_between
from sphere_sim.model.scene import load_scene
from sphere_sim.twin import ladder
from sphere_sim.twin.plants import LIVE_ERROR_BOUND_RAD


def test_an_unknown_rung_is_refused_naming_the_rungs():
    with pytest.raises(FidelityError) as info:
        rung_named('fastest')
    assert "'fastest'" in str(info.value)
    assert all(name in str(info.value) for name in LADDER)


def test_a_rung_refuses_a_scene_that_already_lacks_its_mechanism():
    scene = load_scene('rest')
    bare = scene.replace(effects=dataclasses.replace(scene.effects, stiction=False))
    with pytest.raises(FidelityError, match='stiction'):
        SLIDING.scene(bare)
    assert FULL.scene(bare) is bare


def test_the_sliding_rung_leaves_out_the_bristles_and_nothing_else():
    """The same scene and parameters less the bristles: the states of beams and sphere are
    carried over unchanged, and the two models agree wherever no tip touches the sphere."""
    scene = load_scene('rest')
    full = assemble(scene)
    sliding = assemble(SLIDING.scene(scene))
    assert full.parts == (*sliding.parts, 'friction:stiction')
    assert sliding.params == full.params and not sliding.has_bristles
    rng = np.random.default_rng(3)
    x = np.concatenate([rng.normal(0.0, 1e-7, full.sphere_offset),
                        [0.0, 0.0, 1e-3, 1.0, 0.0, 0.0, 0.0],
                        rng.normal(0.0, 1e-3, 6), rng.normal(0.0, 1e-9, 12)])
    carried = carried_state(full, sliding, x)
    assert carried.shape == (sliding.n_states,)
    np.testing.assert_array_equal(carried, x[:sliding.n_states])
    # The sphere lifted 1 mm clear of the tips: no contact, so no friction of either kind.
    u = np.array([20.0, 0.0, 35.0, 80.0])
    np.testing.assert_allclose(sliding.rhs(0.0, carried, u),
                               full.rhs(0.0, x, u)[:sliding.n_states], rtol=1e-12, atol=0.0)
    with pytest.raises(FidelityError):
        carried_state(sliding, full, carried)


def _result(name, errors, ms):
    return ladder.RungResult(name, '', tuple(errors), tuple([ms * 1e-3] * len(errors)))


def test_the_live_rung_is_the_fastest_model_rung_within_both_bounds():
    p95, most = ladder.LIVE_P95_BUDGET_RAD, ladder.LIVE_MAX_BUDGET_RAD
    within = [0.0] * 19 + [0.9 * most]  # the 95th percentile interpolates below the top
    assert _result('x', within, 1.0).meets_live_budget
    assert not _result('x', [0.0] * 18 + [2 * p95, 2 * p95], 1.0).meets_live_budget
    assert not _result('x', [0.0] * 19 + [1.1 * most], 1.0).meets_live_budget
    full, sliding = _result('full', within, 100.0), _result('sliding', within, 30.0)
    table = _result(TABLE_RUNG, [0.0] * 20, 0.1)
    assert ladder.live_rung_of([full, sliding, table]) is sliding  # the table is no model
    off_budget = _result('sliding', [1.0] * 20, 30.0)
    assert ladder.live_rung_of([full, off_budget, table]) is full
    assert ladder.live_rung_of([_result('full', [1.0] * 20, 100.0), table]) is None


def test_the_kick_set_spans_both_designs_three_intensities_and_three_tilts():
    kicks = ladder.kick_set()
    assert len(kicks) >= 30
    assert {k.design for k in kicks} == {'diagonal', 'axis'}
    assert {k.intensity for k in kicks} == {0.6, 0.8, 1.0}
    assert {k.tilt_deg for k in kicks} == {0.0, 20.0, 35.0}
    for k in kicks:
        assert math.degrees(math.acos(k.normal[2])) == pytest.approx(k.tilt_deg, abs=1e-9)


def test_the_table_rung_is_the_full_model_where_the_table_was_simulated():
    """At a node of the table's grid and one of its intensities, the table's landing is the full
    model's at the table's tolerance: the rungs start from the same rest, with the same
    programme (the table's own, offsets included), so any difference is the table's."""
    params = load_parameter_set('calibrated')
    table = ladder._table('diagonal', params)
    _, _, x_sn, y_sn = table.spec.nodes()[len(table.spec.nodes()) // 3]
    tilt_deg = math.degrees(math.asin(math.hypot(x_sn, y_sn)))
    azimuth_deg = math.degrees(math.atan2(y_sn, x_sn))
    intensity = float(table.intensities[-1])
    kick = ladder.LadderKick('diagonal', intensity, tilt_deg, azimuth_deg)
    looked_up, _ = ladder.landing(TABLE_RUNG, kick, params)
    simulated, _ = ladder.landing('full', kick, params, rtol=table.spec.rtol,
                                  method=DEFAULT_METHOD)  # as the table was built
    assert angle_between(kick.normal, simulated) > 1e-3  # a kick, not a rest
    assert angle_between(looked_up, simulated) < 1e-8


def test_the_full_rung_at_the_live_tolerance_lands_where_the_reference_does_off_the_edges():
    """Off the mirror lines and above the pull-in step (a full kick from 20 deg), the live
    tolerance lands within a few of its bound of a tight reference; the sliding rung kicks too,
    from the same rest and with the same programme."""
    params = load_parameter_set('calibrated')
    kick = ladder.LadderKick('diagonal', 1.0, 20.0, 20.0)
    reference = ladder.reference_landing((kick, params, 1e-8))
    live, _ = ladder.landing('full', kick, params)
    assert angle_between(reference, live) < 3.0 * LIVE_ERROR_BOUND_RAD
    sliding, _ = ladder.landing('sliding', kick, params)
    assert angle_between(kick.normal, sliding) > 1e-3


def test_bench_fidelity_quick_writes_its_table_and_ends_with_the_live_rung(tmp_path, capsys):
    """``sphere-twin bench fidelity --quick``: every row of the quick ladder, the budget, and
    the last line in the form the docs quote, into --out only."""
    import json
    import re

    from sphere_twin import cli

    assert cli.main(['bench', 'fidelity', '--quick', '--workers', '1',
                     '--out', str(tmp_path)]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert re.fullmatch(r'live rung (full \([a-z]+, rtol [0-9.e-]+\): p95 [0-9.e+-]+ rad, max '
                        r'[0-9.e+-]+ rad, [0-9.]+ ms per kick \(full model at the live '
                        r'tolerance [0-9.]+ ms\)|none: .*)', lines[-1])
    assert lines[-2].startswith(f'the twin runs: full ({LIVE_METHOD}, rtol 0.0003), ')
    assert sorted(p.name for p in tmp_path.iterdir()) == ['fidelity_quick.json',
                                                           'fidelity_quick.md']
    data = json.loads((tmp_path / 'fidelity_quick.json').read_text())
    assert [r['name'] for r in data['rungs']] == ['full', 'sliding', TABLE_RUNG]
    assert all(len(r['errors_rad']) == ladder.QUICK_KICKS for r in data['rungs'])
    assert data['live_max_budget_rad'] == pytest.approx(9.42e-4, rel=1e-3)


# --- the simulator's choice: plant and fidelity ------------------------------------------

@pytest.mark.parametrize(('plant', 'fidelity', 'expected'), [
    ('', '', ('continuous', 'full')),
    ('continuous', '', ('continuous', 'full')),
    ('discrete', '', ('discrete', 'table')),
    ('', 'table', ('discrete', 'table')),
    ('', 'sliding', ('continuous', 'sliding')),
    ('continuous', 'sliding', ('continuous', 'sliding')),
    ('discrete', 'table', ('discrete', 'table')),
])
def test_plant_and_fidelity_each_decide_alone_and_agree_together(plant, fidelity, expected):
    from sphere_sim.twin.plant_setup import plant_and_fidelity

    assert plant_and_fidelity(plant, fidelity) == expected


@pytest.mark.parametrize(('plant', 'fidelity', 'named'), [
    ('', 'fastest', LADDER), ('analogue', '', ('continuous', 'discrete')),
    ('discrete', 'sliding', ('discrete', 'table')), ('continuous', 'table', ('full', 'sliding'))])
def test_a_plant_and_fidelity_that_cannot_run_are_one_line_naming_the_choices(plant, fidelity,
                                                                              named):
    from sphere_sim.twin.plant_setup import plant_and_fidelity
    from sphere_sim.twin.plants import PlantError

    with pytest.raises(PlantError) as info:
        plant_and_fidelity(plant, fidelity)
    assert '\n' not in str(info.value)
    assert all(name in str(info.value) for name in named)


def test_the_simulator_offers_the_ladder_and_defaults_to_the_measured_live_rung():
    """The node's choices, written out to keep it light, are the ladder's; its default is the
    rung the committed ladder found fastest within the live budget."""
    import json

    from sphere_sim.twin.plant_setup import FIDELITIES, LIVE_FIDELITY, plant_and_fidelity

    assert FIDELITIES == LADDER
    committed = json.loads((Path(__file__).parents[1] / 'bench' / 'results'
                            / 'fidelity.json').read_text())
    assert committed['live_rung'].split()[0] == LIVE_FIDELITY
    assert plant_and_fidelity() == ('continuous', LIVE_FIDELITY)


def test_a_reduced_rung_plant_runs_the_rung_from_the_full_models_rest():
    """fidelity sliding builds the continuous plant on the scene without its bristles,
    started from the full model's rest: both plants report the same sphere until a kick."""
    from sphere_sim.twin.plant_setup import build_plant, plant_rung

    full, sliding = build_plant(fidelity='full'), build_plant(fidelity='sliding')
    assert (plant_rung(full), plant_rung(sliding)) == ('full', 'sliding')
    assert not sliding.model.has_bristles and full.model.has_bristles
    assert sliding.model.n_states == full.model.n_states - 12
    np.testing.assert_array_equal(sliding.model_state(),
                                  full.model_state()[:sliding.model.n_states])
    assert angle_between(sliding.snapshot().normal, full.snapshot().normal) == 0.0


def test_a_rung_that_leaves_out_what_the_scene_lacks_is_refused_naming_it(tmp_path):
    """The sliding rung on a scene that has no stiction: one line naming the mechanism."""
    from sphere_sim.twin.plant_setup import build_plant

    scene = tmp_path / 'no_stiction.yaml'
    scene.write_text((Path(__file__).parents[1] / 'sphere_sim' / 'scenes' / 'rest.yaml')
                     .read_text().replace('name: rest', 'name: no_stiction')
                     + 'effects: {friction: {stiction: false}}\n')
    with pytest.raises(FidelityError, match='stiction') as info:
        build_plant(scene_name=str(scene), fidelity='sliding')
    assert '\n' not in str(info.value) and 'no_stiction' in str(info.value)
