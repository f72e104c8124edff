"""Energy: conserved without losses through repeated impacts; never above the electrical work."""

from sphere_sim import validation


def test_energy_is_conserved_through_repeated_impacts_without_losses():
    surplus, impacts = validation.lossless_drop()
    assert impacts >= 2  # the sphere lands, bounces and lands again
    assert surplus < 1e-4


def test_energy_with_voltage_is_conserved_against_electrical_work_without_losses():
    surplus, work_j = validation.lossless_pulse()
    assert work_j > 1e-9  # the pulse did work on the mechanism (positive: Q_ES pulls down)
    assert surplus < 1e-4


def test_energy_never_rises_above_electrical_work_with_losses():
    peak, final = validation.lossy_kick()
    assert peak < 1e-5
    assert final < -0.1  # and the losses are real
