"""The command line: every sub-command has --help; bad input gives one line and a non-zero exit."""

import subprocess
import sys
from pathlib import Path

import pytest

from gransim.cli import build_parser, main


def _commands():
    parser = build_parser()
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    return sorted(sub.choices)


def test_top_level_help_is_fast_and_lists_commands():
    out = subprocess.run([sys.executable, "-m", "gransim", "--help"], capture_output=True, text=True, check=True)
    for name in _commands():
        assert name in out.stdout


@pytest.mark.parametrize("command", _commands())
def test_every_command_has_help(command, capsys):
    with pytest.raises(SystemExit) as exc:
        main([command, "--help"])
    assert exc.value.code == 0
    assert "usage: gransim" in capsys.readouterr().out


def test_unknown_command_and_option_exit_nonzero(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["no-such-command"])
    assert exc.value.code != 0
    with pytest.raises(SystemExit) as exc:
        main(["validate", "--suite", "nonsense"])
    assert exc.value.code != 0
    assert "invalid choice" in capsys.readouterr().err


def test_the_process_exit_keeps_main_status_atexit_and_flushed_output():
    # `gransim` and `python -m gransim` end through gransim.cli.entry (gc.freeze before the
    # teardown): the exit status must still be main()'s, atexit handlers must run and stdout must
    # reach a pipe whole
    script = Path(sys.executable).with_name("gransim")
    assert "from gransim.cli import entry" in script.read_text()
    bad = subprocess.run([sys.executable, "-m", "gransim", "info", "no-such.h5"], capture_output=True, text=True)
    assert bad.returncode == 2 and "gransim info: error" in bad.stderr  # main() returned 2
    code = (
        "import atexit, sys\n"
        "atexit.register(lambda: print('atexit ran', flush=True))\n"
        "sys.argv = ['gransim', 'info', 'no-such.h5']\n"
        "from gransim.cli import entry\n"
        "entry()\n"
    )
    ok = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert ok.returncode == 2, ok.stderr
    assert "no such file" in ok.stderr and ok.stdout.strip() == "atexit ran"
