"""The integration tolerances, each in one place with what it is held to.

A tolerance derived from another is written as what it derives from; the rooms above import
these and never repeat a literal.
"""

import math

# rtol of simulate(): the final surface normal of the optimised kick is then within about 1e-8 rad
# of the converged value (bench/results/work_precision.md), far below what a kick resolves. The
# default of every study, kick design, table and pull-in search.
DEFAULT_RTOL = 1e-6
# The live twin's tolerance. By Radau (`fast`) the optimised kick from rest and from a 35 deg
# tilt then ends within 3.5e-6 and 5.9e-6 rad of the rtol 1e-9 run, below 1 % of the sensor
# noise of the noise study (0.1 kick widths, 9.4e-4 rad), at a third of the cost of rtol 1e-6;
# rtol 1e-3 is 1.6e-5 rad off (docs/twin.md). Across the ladder's 30 kicks it misses the live
# budget on two (docs/numerics.md, "The ladder of models").
LIVE_RTOL = 3e-4
# The live twin's method, at LIVE_RTOL. The Rosenbrock W-method against the compiled Radau
# (`fast`), over the ladder's 30 kicks against rtol 1e-9 (bench/results/fidelity.md): median
# 2.6e-5 against 4.9e-6 rad, 95th percentile 2.2e-4 against 1.7e-4, max 7.1e-4 against 1.1e-3,
# at 54 against 104 ms a kick; advanced sample by sample as the plant does, 55 against 105 ms.
# Neither meets the live budget (p95 <= 9.4e-5 rad); the W-method meets its maximum (the sensor
# noise) where Radau does not, at half the cost. Its typical kick is less exact (4e-5 against
# 2.5e-6 rad for the full kick from 5 deg, 1.1e-5 against 3e-6 from 35 deg), within a tenth of
# the sensor noise. Studies, tables and fits keep `fast` (solve.DEFAULT_METHOD).
LIVE_METHOD = 'rosenbrock'
# check_fidelity's reference beside the live twin: the cheapest tolerance at which the full model
# meets the live budget on the ladder's kick set (bench/results/fidelity.md: at 3e-6 p95 9e-6 rad
# and max 1.4e-4 rad, at 1e-6 p95 8e-6 and max 6e-5 rad: the margin of a factor of two kept).
CHECK_RTOL = 1e-6
# Identification's: a tenth of the live tolerance, where the integrator's own jumps as a
# parameter moves are worth well under one unit of misfit (misfit_scan). Written as its decimal:
# LIVE_RTOL / 10 is one bit off it, and every committed fit was made at 3e-5.
FIT_RTOL = 3e-5

assert math.isclose(FIT_RTOL, LIVE_RTOL / 10, rel_tol=1e-12)
# A synthetic device stands in for hardware, which has no integrator: its recordings are held to
# a tenth of the fit's tolerance, so that the fit's own error is what the residuals carry. Recorded
# at the live tolerance, paper_e's first protocol kick ended 2.2e-3 rad from where the fit's model
# at the truth lands it, and its sixth 7.4e-4; recorded at this one, 2.3e-4 (a kick near a
# landing's branch point, which the fit leaves out) and 4e-5. A recording takes 1.5 to 2 times
# as long.
DEVICE_RTOL = FIT_RTOL / 10
