"""--help shows the common options of each task in at most 80 lines; --help-all shows every option."""

import argparse

import pytest

from sparsedepth.cli.camera import CAMERA_PRESETS
from sparsedepth.cli.parser import COMMON_OPTIONS, build_parser
from sparsedepth.complete import main


def _flags(parser):
    return [flag for action in parser._actions for flag in action.option_strings]


@pytest.fixture
def columns(monkeypatch):
    monkeypatch.setenv("COLUMNS", "80")


def test_help_is_at_most_80_lines_and_ends_naming_help_all(capsys, columns):
    assert main(["--help"]) == 0
    out = capsys.readouterr().out
    lines = out.splitlines()
    assert len(lines) <= 80
    assert "--help-all" in lines[-1]
    for _, options in COMMON_OPTIONS:  # the common options of each task, with their metavar
        for flag, _ in options:
            assert f"  {flag}" in out or f", {flag}" in out, flag
    assert main(["-h"]) == 0 and capsys.readouterr().out == out
    full = build_parser().format_help()
    assert "--alpha" not in out and "--alpha" in full  # the rest is for --help-all


def test_help_all_lists_every_flag_of_the_parser(capsys, columns):
    assert main(["--help-all"]) == 0
    out = capsys.readouterr().out
    flags = _flags(build_parser())
    assert len(flags) > 70
    missing = [flag for flag in flags if flag not in out]
    assert missing == []
    for name, preset in CAMERA_PRESETS.items():  # the camera presets' table gives the --camera help
        assert name in out and " ".join(preset.what.split()) in " ".join(out.split())


def test_every_flag_still_parses():
    parser = build_parser()
    samples = ["0.5", "1", "0,0", "1,1,0,0", "nyu", "x.png", "0:2"]
    for action in parser._actions:
        if action.nargs == 0 and action.default == argparse.SUPPRESS:
            continue  # --help, --help-all and --version print and exit: below
        flag = action.option_strings[-1]
        values = [[]] if action.nargs == 0 else [[str(c)] for c in action.choices or ()] or [[v] for v in samples]
        parsed = []
        for value in values:
            try:
                parsed.append(parser.parse_args([flag, *value]))
            except SystemExit:
                pass
        assert parsed, flag
    for flag in ("-h", "--help", "--help-all", "--version"):
        with pytest.raises(SystemExit) as stop:
            parser.parse_args([flag])
        assert stop.value.code in (0, None)

