"""``twin search``: find the objects in as few views as it takes, choosing each next view.

The same run folder, config, ``--set``, resume, progress and Rerun recording as ``twin survey``
(``twin.commands.survey``); the views are chosen by ``search.planner`` (``--planner``) as the
mission goes (``twin.app.search``), and the run stops once every sought object's confidence
reaches ``search.confidence``, or it is declared absent, or the budget runs out.
"""

from __future__ import annotations

import argparse

from twin.app.planner_names import PLANNERS
from twin.commands.survey import add_run_arguments, run


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "search",
        help="search for the objects, choosing each next view (default: by information gain)",
        description="After each view choose the next one (a place on the map and a heading) "
        "worth most per second of robot time, fuse it as the survey does, and stop once every "
        "sought object is found with the configured confidence, declared absent, or the view "
        "or time budget is spent. result.json adds views, path_length_m, time_s and why it "
        "stopped; the Rerun recording says why each view was chosen.",
    )
    add_run_arguments(parser)
    parser.add_argument(
        "--planner",
        choices=PLANNERS,
        help="how the next view is chosen (default: the config's search.planner, information)",
    )
    parser.set_defaults(handler=_run, mission="search")


def _run(args: argparse.Namespace) -> int:
    if args.planner is not None:
        args.set = [*args.set, f"search.planner={args.planner}"]
    return run(args)
