"""A command line naming a subcommand is parsed by a parser holding that subcommand only
(its module alone imported): the same help page, the same errors, the same namespace as
the whole parser gives."""

from __future__ import annotations

import contextlib
import io

import pytest

from gyrostand.cli import COMMANDS, _command_in, build_parser


def _outcome(parser, argv):
    out, err = io.StringIO(), io.StringIO()
    code = None
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            ns = parser.parse_args(argv)
        except SystemExit as exc:
            code, ns = exc.code, None
    if ns is not None:
        ns = {k: v for k, v in vars(ns).items()
              if not k.startswith(("verbose_", "debug_", "quiet_"))}
        ns["func"] = getattr(ns.get("func"), "__qualname__", None)
    return code, out.getvalue(), err.getvalue(), ns


@pytest.mark.parametrize("name", COMMANDS)
def test_one_subcommand_parses_as_the_whole_parser(name):
    for argv in ([name, "--help"], [name], [name, "x.csv", "--no-such-option"],
                 ["-v", name, "a", "b"], ["--debug", name, "-q", "RUN"],
                 ["-vv", "-q", name, "--help"]):
        assert _command_in(argv) == name
        assert _outcome(build_parser(name), argv) == _outcome(build_parser(), argv), argv


def test_no_command_named_builds_the_whole_parser():
    for argv in ([], ["--help"], ["--version"], ["nope", "x"], ["--", "identify"], ["-v"],
                 ["--help", "identify"], ["-h", "run"], ["--deb", "identify"]):
        assert _command_in(argv) is None
    assert set(build_parser()._subparsers._group_actions[0].choices) == set(COMMANDS)
