"""``gyrostand report RUN [--single-file] [--format html|text|json]``: one HTML page with
PNG plots of the current model (beside it, or with ``--single-file`` embedded in it: one
file to mail), or the diagnosis as ``report.txt`` / ``report.json``; prints its path."""

from __future__ import annotations

import argparse
from typing import Any

from .common import add_format_args, workbench_command
from .workbench_args import add_subject_args, subject_of, subjects_of


def add_parser(sub: Any) -> None:
    p = sub.add_parser("report", help="write an HTML report with plots of the current model",
                       description=__doc__)
    add_subject_args(p, several=True)
    p.add_argument("--out", default=None, metavar="DIR",
                   help="folder of the report (default: report-<gyro>/ in the run folder, or "
                        "beside the CSV)")
    p.add_argument("--single-file", action="store_true",
                   help="one HTML file to mail: the figures embedded in report.html "
                        "(base64 PNG), no PNG files beside it")
    add_format_args(p, "the report", default="html", verb="write")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if len(args.run) > 1:
        from ..report.joint import write_joint_report

        print(write_joint_report(subjects_of(args), args.out, format=args.format,
                                 single_file=args.single_file))
        return 0
    args.run = args.run[0]
    from ..report import write_report  # matplotlib only when a report is asked for

    print(write_report(subject_of(args), args.out, format=args.format,
                       single_file=args.single_file,
                       fit_command=workbench_command(args, "fit"),
                       diagnose_command=workbench_command(args, "diagnose")))
    return 0
