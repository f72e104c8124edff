"""``sphere-twin bench thresholds``: what a search of the model's pull-in threshold costs, by
where it starts.

The joint fit searches every threshold of the experiment protocol at every parameter vector it
simulates, each from a predicted cell of its lattice (docs/identification.md, "The model's
threshold"). This bench searches each threshold of a protocol recording at the recording's
truth from the starts below, on one core, and counts the pulses simulated, the wall time (the
rest states included) and the searches that ended in another cell than the first start's:

- the recorded bracket's middle, galloping from one cell, and from ``UNPREDICTED_STEP_V`` (a
  search with no prediction);
- the cell the first one found (a prediction in the right cell), and that cell moved up by
  0.013 V and by 0.5 V (predictions one cell and fifty cells off).

Its last line is ``threshold search: <a> pulses from the brackets' middles, <b> from the right
cells (<a / b>x)``; it writes ``threshold_search.md`` into ``--out``.

    sphere-twin bench thresholds            # records paper_b's protocol first (2 min), then 1 min
    sphere-twin bench thresholds --bag BAG  # a protocol recording with its truth.yaml beside it
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
from collections.abc import Sequence
from pathlib import Path

from sphere_sim.fitting.thresholds import (
    MODEL_RESOLUTION_V,
    UNPREDICTED_STEP_V,
    SearchCost,
    ThresholdObservation,
    search_cost,
)
from sphere_sim.model.parameters import ParameterSet, load_parameter_set
from sphere_twin.commands.options import DEFAULT_OUT_DIR, CommandError, output_directory

RESULTS_NAME = 'threshold_search.md'
DEFAULT_DEVICE = 'paper_b'  # recorded when no --bag is given
# The starts moved off the right cell (V): within the next cell, and fifty cells off.
OFF_CELL_V = (0.013, 0.5)


@dataclasses.dataclass(frozen=True)
class StartRow:
    """One way of starting every search: what they cost together."""

    start: str
    pulses: int
    wall_s: float
    elsewhere: int  # searches ending in another cell than the first start's


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add ``thresholds`` to the ``bench`` subcommands."""
    parser = sub.add_parser(
        'thresholds', help="what a search of the model's pull-in threshold costs, by where it "
                           'starts',
        description="Searches each threshold of a protocol recording at its truth from the "
                    "bracket's middle and from predicted cells, right and off; prints the "
                    f'pulses and wall time of each start and writes {RESULTS_NAME} into '
                    f'--out. Without --bag, records {DEFAULT_DEVICE}\'s protocol first '
                    '(2 minutes) into a scratch directory.')
    parser.add_argument('--bag', type=Path, default=None,
                        help='a protocol recording (sphere-twin synthetic record --protocol) '
                             'with its truth.yaml')
    parser.add_argument('--out', type=output_directory, default=DEFAULT_OUT_DIR,
                        help='output directory (default: the working directory; the committed '
                             'one: bench/results)')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.bag is not None:
        main(args.bag, args.out)
        return 0
    from sphere_twin.commands.synthetic import record_protocol_bag
    from sphere_twin.synthetic_device import PAPER_DEVICES

    (device,) = [d for d in PAPER_DEVICES if d.name == DEFAULT_DEVICE]
    with tempfile.TemporaryDirectory() as scratch:
        bag = Path(scratch) / DEFAULT_DEVICE
        record_protocol_bag(device, bag)
        main(bag, args.out)
    return 0


def main(bag: Path, out_dir: Path = DEFAULT_OUT_DIR) -> list[StartRow]:
    from sphere_twin.commands.identify import read_recording

    truth_file = bag / 'truth.yaml'
    if not truth_file.is_file():
        raise CommandError(f'{bag}: no truth.yaml beside the recording (the searches run at '
                           "a synthetic device's truth)")
    thresholds = read_recording(bag).thresholds
    if not thresholds:
        raise CommandError(f'{bag}: no threshold search with both sides seen (record one with '
                           'sphere-twin synthetic record --protocol)')
    rows = start_rows(load_parameter_set(truth_file), thresholds)
    write_results(rows, bag, len(thresholds), out_dir / RESULTS_NAME)
    for row in rows:
        print(f'{row.start}: {row.pulses} pulses, {row.wall_s:.1f} s; {row.elsewhere} ended '
              'in another cell')
    from_middle, right_cell = rows[0], rows[2]  # start_rows' order
    print(f"threshold search: {from_middle.pulses} pulses from the brackets' middles, "
          f'{right_cell.pulses} from the right cells '
          f'({from_middle.pulses / max(right_cell.pulses, 1):.1f}x)')
    return rows


def start_rows(params: ParameterSet,
               thresholds: Sequence[ThresholdObservation]) -> list[StartRow]:
    """Every threshold searched from each start; the first start's cells are the reference."""
    first = [search_cost(params, t, t.middle_v) for t in thresholds]
    cells_v = [cost.value_v for cost in first]
    runs: list[tuple[str, list[SearchCost]]] = [
        ("the bracket's middle, galloping from one cell", first),
        (f"the bracket's middle, galloping from {UNPREDICTED_STEP_V:g} V",
         [search_cost(params, t, t.middle_v, UNPREDICTED_STEP_V) for t in thresholds]),
        ('the right cell', [search_cost(params, t, v) for t, v in zip(thresholds, cells_v,
                                                                      strict=True)])]
    runs += [(f'{off_v:g} V above the right cell',
              [search_cost(params, t, v + off_v) for t, v in zip(thresholds, cells_v,
                                                                 strict=True)])
             for off_v in OFF_CELL_V]
    return [StartRow(start, sum(c.pulses for c in costs), sum(c.wall_s for c in costs),
                     sum(abs(c.value_v - v) > 0.5 * MODEL_RESOLUTION_V
                         for c, v in zip(costs, cells_v, strict=True)))
            for start, costs in runs]


def write_results(rows: Sequence[StartRow], bag: Path, count: int, path: Path) -> None:
    lines = ["# What a search of the model's pull-in threshold costs, by where it starts", '',
             f'Written by `sphere-twin bench thresholds` from {bag.name}\'s protocol recording: '
             f'its {count} thresholds searched at its truth on one core, each on its lattice of '
             f'{MODEL_RESOLUTION_V:g} V from its bracket\'s low end (docs/identification.md, '
             '"The model\'s threshold"). Wall times include the rest states; read the pulses '
             'and the ratios, the times follow the machine.', '',
             '| start | pulses | wall (s) | ended in another cell |', '|---|---|---|---|']
    lines += [f'| {r.start} | {r.pulses} | {r.wall_s:.1f} | {r.elsewhere} |' for r in rows]
    path.write_text('\n'.join(lines) + '\n')
