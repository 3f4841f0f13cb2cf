"""The message on numba's first compile, and the count of what compiled."""

import logging

import numba
import numpy as np

import fourd.cli as cli
from fourd.compile_notice import FIRST_COMPILE, listen_for_compiles, stop_listening


def _kernels():
    """Fresh, uncached kernels (so they compile whatever the cache holds): an outer one that
    calls an inner one."""

    @numba.njit(cache=False)
    def inner(x):
        return x * 2.0

    @numba.njit(cache=False)
    def outer(values):
        total = 0.0
        for v in values:
            total += inner(v)
        return total

    return outer


def test_the_first_compile_is_announced_once_and_outermost_compiles_are_counted(caplog):
    logger = logging.getLogger("fourd.test_compile_notice")
    outer = _kernels()
    notice = listen_for_compiles(logger)
    try:
        with caplog.at_level(logging.INFO, logger=logger.name):
            assert outer(np.arange(4.0)) == 12.0  # compiles outer, and inner inside it
            assert outer(np.arange(4, dtype=np.int64)) == 12.0  # a second signature
            assert outer(np.arange(3.0)) == 6.0  # compiled already
    finally:
        stop_listening(notice)
    assert [r.getMessage() for r in caplog.records] == [FIRST_COMPILE]
    assert notice.count == 2 and notice.seconds > 0
    assert notice.summary().startswith("compiled 2 kernels in ")
    # no longer listening
    _kernels()(np.arange(2.0))
    assert notice.count == 2


def test_nothing_is_said_when_nothing_compiles(caplog):
    notice = listen_for_compiles(logging.getLogger("fourd.test_compile_notice"))
    stop_listening(notice)
    assert notice.summary() is None and not caplog.records


def test_the_command_line_reports_what_a_run_compiled(monkeypatch, capsys):
    outer = _kernels()

    def command(args):
        outer(np.arange(3.0))
        return 0

    parser = cli.build_parser()
    args = parser.parse_args(["info", "somewhere"])
    monkeypatch.setattr(cli, "build_parser", lambda: _Fixed(parser, args, command))
    assert cli.main(["info", "somewhere"]) == 0
    err = capsys.readouterr().err.splitlines()
    assert err[0] == FIRST_COMPILE
    assert err[-1].startswith("compiled 1 kernel in ") and err[-1].endswith("later runs load them)")


class _Fixed:
    """A parser whose result runs ``command``."""

    def __init__(self, parser, args, command):
        self.args = args
        args.func = command

    def parse_args(self, argv):
        return self.args


def test_a_message_while_a_progress_bar_is_drawn_gets_a_line_of_its_own(capsys):
    """The compile notice (or any message) logged in the middle of a stage's bar is not
    appended to the bar's line."""
    import re

    from fourd.progress import progress

    cli._configure_logging(quiet=False)
    with progress(total=3, desc="working") as bar:
        bar.update(1)
        logging.getLogger("fourd.test_compile_notice").info(FIRST_COMPILE)
        bar.update(2)
    err = capsys.readouterr().err
    assert "working" in err
    assert FIRST_COMPILE in re.split(r"[\r\n]", err)
