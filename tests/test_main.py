"""The CLI root: lazy subcommands, one-line errors with exit status 2, --debug."""

import subprocess
import sys

import click
import pytest

from vdps_hil.cli import main as m
from vdps_hil.cli.common import UserError, write_json


def run(*args):
    return subprocess.run([sys.executable, "-c", "from vdps_hil.cli.main import entry; entry()", *args],
                          capture_output=True, text=True, timeout=120)


def test_help_lists_registered_commands():
    r = run("--help")
    assert r.returncode == 0
    for name in m.COMMANDS:
        assert name in r.stdout


def test_every_registered_command_imports_and_is_click():
    for name, (module, attr, _) in m.COMMANDS.items():
        cmd = m.cli.get_command(None, name)
        assert isinstance(cmd, click.Command), name


def test_unknown_command_is_one_line_exit_2():
    r = run("no-such-command")
    assert r.returncode == 2
    assert len(r.stderr.strip().splitlines()) == 1 and "error" in r.stderr


def test_unknown_option_is_one_line_exit_2():
    r = run("--no-such-option")
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1


@click.command("boom")
def _boom():
    raise UserError("bad thing")


def test_user_error_through_main_is_one_line_exit_2(monkeypatch, capsys):
    monkeypatch.setitem(m.COMMANDS, "boom", (__name__, "_boom", "test only"))
    assert m.main(["boom"]) == 2
    err = capsys.readouterr().err
    assert err == "vdps: error: bad thing\n"


def test_internal_error_one_line_and_debug_traceback(monkeypatch, capsys):
    def explode(*a, **k):
        raise RuntimeError("kaput")
    monkeypatch.setattr(m.cli, "main", explode)
    assert m.main(["x"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "kaput" in err and "--debug" in err
    with pytest.raises(RuntimeError):
        m.main(["--debug", "x"])


def test_write_json_replaces_non_finite(tmp_path):
    p = tmp_path / "o.json"
    write_json({"a": float("nan"), "b": [1.0, float("inf")], "c": {"d": 2}}, str(p))
    assert p.read_text().replace(" ", "").replace("\n", "") == '{"a":null,"b":[1.0,null],"c":{"d":2}}'


def test_write_json_unwritable_is_user_error(tmp_path):
    with pytest.raises(UserError, match="cannot write"):
        write_json({"a": 1}, str(tmp_path / "missing-dir" / "o.json"))
